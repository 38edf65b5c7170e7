"""Grade one submission: every graded test in its own child process, scored here.

Isolation (see :mod:`lab.grading.isolation` for the sandbox, :mod:`lab.grading.sandbox` for the
child's side):

* **The student's code runs in a sandbox, as another user.** Each test starts a fresh child inside
  bubblewrap: a filesystem holding only the system, Python and a private copy of the submission (no
  assignments, graded tests, reference solutions, other students' folders or grader files), no
  network, its own PID namespace, and (when the grader is root) a throwaway uid of its own. The
  grading process is not dumpable, so no process can read or write its memory.
* **The submission is read once, as a regular file.** Its bytes are read when grading starts (a
  classmate changing the file later changes nothing); a symbolic link, a device or a folder where the
  module is expected is refused with a message.
* **The scoring process never imports the submission.** The child imports its copy under a memory
  limit (``RLIMIT_AS``), a CPU-time backstop, no file writes (``RLIMIT_FSIZE = 0``) and no new
  processes. The test itself (the oracle, the tolerances, the points) runs here and reaches the
  student's functions only through :class:`Submission`, whose calls come back as *values*.
* **The channel is private.** Calls and answers go over two pipes opened for that child alone; the
  child's stdout and stderr are captured as text for the feedback and never parsed, so printing fake
  results does nothing. A malformed answer is a failed call.
* **Nothing the child sends is a score.** At worst a hostile child sends wrong values for its own
  functions, which is what it is graded on.
* **Nothing outlives its test.** Before a test's result is recorded, every process it started is gone
  (the sandbox's PID namespace is killed and, as root, every process of its uid), so nothing can
  rewrite results after the grader.
* **Limits cost points, not the grading run.** An exception, a timeout, running out of memory, a
  crash, wrong shapes or NaNs fail that test with a message; the next test starts a new child. A
  module that fails to import fails every test with the same message, found once by a first import
  probe. A total time budget bounds the whole run.

Without a working sandbox :func:`grade_submission` refuses (``SandboxUnavailable``) unless asked to
grade insecurely, and then every result says so.
"""

from __future__ import annotations

import functools
import json
import os
import select
import shutil
import signal
import stat
import struct
import subprocess
import tempfile
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from lab.grading.assignments import Assignment
from lab.grading.isolation import (
    ENTRY,
    SUBMISSION_DIR,
    Sandbox,
    SandboxUnavailable,
    end_all,
    find_sandbox,
    make_undumpable,
    pid_namespace_members,
)
from lab.grading.report import INSECURE, GradeReport, TestResult
from lab.grading.sandbox import MAX_MESSAGE_BYTES, WireError, decode, encode
from lab.grading.suite import Fail, GradedTest

__all__ = [
    "Submission",
    "SubmissionProblem",
    "StudentError",
    "StudentTimeout",
    "StudentCrash",
    "ImportFailed",
    "grade_submission",
    "find_module",
    "read_module",
    "Refused",
]

_SANDBOX = Path(__file__).with_name("sandbox.py")
_HEADER = struct.Struct(">I")
_OUTPUT_KEEP = 4000  # characters of the child's stdout/stderr kept for feedback
_OUTPUT_SHOW = 1500
_MAX_MODULE_BYTES = 2 << 20  # a submitted module larger than 2 MB is refused


# ------------------------------------------------------------------------------------------ outcomes
class SubmissionProblem(Exception):
    """The student's code did not produce a value: raised, timed out, crashed or failed to import."""


class StudentError(SubmissionProblem):
    """A student function raised; ``info`` holds the type, message and the lines of their file."""

    def __init__(self, function: str, module: str, info: dict):
        self.function, self.module, self.info = function, module, info
        self.type = str(info.get("type", "Exception"))
        super().__init__(self._message())

    def _message(self) -> str:
        t, m = self.type, str(self.info.get("message", ""))
        if t == "NotImplementedError":
            head = f"{self.function} is not implemented yet (it raises NotImplementedError)"
        elif t == "UnsendableResult":
            head = f"{self.function} returned a value the grader cannot use: {m}"
        elif self.info.get("memory"):
            head = f"{self.function} ran out of memory (MemoryError{': ' + m if m else ''})"
        else:
            head = f"{self.function} raised {t}" + (f": {m}" if m else "")
        return head + _where(self.info, self.module)


class StudentTimeout(SubmissionProblem):
    """The student's code did not answer within the test's time limit (the child was killed)."""


class StudentCrash(SubmissionProblem):
    """The child process died while running the student's code."""


class ImportFailed(SubmissionProblem):
    """The module could not be imported (or its import did not finish in time); ``notes`` holds what
    the sandbox refused while it was imported."""

    def __init__(self, message: str, notes: list[str] | None = None):
        super().__init__(message)
        self.notes = list(notes or [])


def _where(info: dict, module: str) -> str:
    lines = [
        f"\n  at {module} line {w['line']}, in {w['function']}: {w['code']}" for w in info.get("where", [])
    ]
    return "".join(lines)


# ------------------------------------------------------------------------------------------ child
class _Timeout(Exception):
    pass


class _Child:
    """A running ``sandbox.py`` (in the sandbox) with its private request and answer pipes."""

    def __init__(
        self, source: bytes, module: str, memory_mb: int, cpu_s: int, sandbox: Sandbox, hide: tuple[str, ...]
    ):
        self.dir = Path(tempfile.mkdtemp(prefix="lab-grade-"))
        os.chmod(self.dir, 0o755)  # the child's throwaway uid reads it (read-only, in the sandbox)
        self.module_file = self.dir / module  # under the assignment's name, whatever the upload was called
        self.module_file.write_bytes(source)
        os.chmod(self.module_file, 0o644)
        self.sandbox = sandbox
        self.uid = sandbox.new_uid()
        self.notes: list[str] = []
        req_r, self.req_w = os.pipe()
        self.resp_r, resp_w = os.pipe()
        info_r, info_w = os.pipe() if sandbox.secure else (-1, -1)
        home = "/tmp" if sandbox.secure else str(self.dir)
        env = {
            "PATH": "/usr/bin:/bin" if sandbox.secure else os.environ.get("PATH", "/usr/bin:/bin"),
            "HOME": home,
            "TMPDIR": home,
            "MPLCONFIGDIR": home,
            "MPLBACKEND": "Agg",
            "OPENBLAS_NUM_THREADS": "1",
            "OMP_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1",
            "PYTHONHASHSEED": "0",
            "LC_ALL": "C.UTF-8",
        }
        args = [
            "-I",  # isolated: no PYTHON* variables, no user site, no script folder on sys.path
            "-u",  # unbuffered: what the student printed before a crash or a timeout is not lost
            ENTRY if sandbox.secure else str(_SANDBOX),
            str(req_r),
            str(resp_w),
            f"{SUBMISSION_DIR}/{module}" if sandbox.secure else str(self.module_file),
            str(memory_mb),
            str(cpu_s),
            str(-1 if self.uid is None else self.uid),
        ]
        cmd = sandbox.command(args, self.dir, _SANDBOX, self.uid, hide)
        if sandbox.secure:
            cmd[1:1] = ["--info-fd", str(info_w)]  # bwrap says there the pid of the namespace's first process
        fds = (req_r, resp_w) + ((info_w,) if sandbox.secure else ())
        try:
            self.proc = subprocess.Popen(
                cmd,
                cwd=self.dir,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                pass_fds=fds,
                start_new_session=True,  # its own process group: a timeout kills everything it started
            )
        finally:
            for fd in fds:
                os.close(fd)
        self.info_r = info_r
        self.init_pid: int | None = None
        os.set_blocking(self.req_w, False)
        self._buf = bytearray()
        self._out = bytearray()
        self._out_total = 0
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        self.memory_mb = memory_mb
        self._closed = False

    def _namespace_init(self) -> int | None:
        """The pid of the sandbox's first process, from bwrap's ``--info-fd`` (read once)."""
        if self.init_pid is None and self.info_r >= 0:
            os.set_blocking(self.info_r, False)
            try:
                data = os.read(self.info_r, 4096)
                self.init_pid = int(json.loads(data)["child-pid"])
            except (OSError, ValueError, KeyError, TypeError):
                pass
        return self.init_pid

    def _drain(self) -> None:
        """Keep the first few KB of what the child prints (never parsed); discard the rest."""
        f = self.proc.stdout
        while True:
            chunk = f.read1(65536) if hasattr(f, "read1") else f.read(65536)
            if not chunk:
                return
            self._out_total += len(chunk)
            room = _OUTPUT_KEEP - len(self._out)
            if room > 0:
                self._out += chunk[:room]

    def printed(self) -> str:
        text = self._out.decode("utf-8", errors="replace")
        if self._out_total > len(self._out):
            text += f"\n... ({self._out_total - len(self._out)} more bytes not shown)"
        return text

    def send(self, obj, deadline: float) -> None:
        data = encode(obj)
        view = memoryview(_HEADER.pack(len(data)) + data)
        while view:
            left = deadline - time.monotonic()
            if left <= 0:
                raise _Timeout
            _, w, _ = select.select([], [self.req_w], [], left)
            if not w:
                raise _Timeout
            try:
                n = os.write(self.req_w, view)
            except BlockingIOError:
                continue
            except BrokenPipeError:
                raise StudentCrash(self.death()) from None
            view = view[n:]

    def receive(self, deadline: float):
        while True:
            if len(self._buf) >= _HEADER.size:
                (n,) = _HEADER.unpack_from(self._buf)
                if n > MAX_MESSAGE_BYTES:
                    raise WireError("answer too large")
                if len(self._buf) >= _HEADER.size + n:
                    data = bytes(self._buf[_HEADER.size : _HEADER.size + n])
                    del self._buf[: _HEADER.size + n]
                    return decode(data)
            left = deadline - time.monotonic()
            if left <= 0:
                raise _Timeout
            r, _, _ = select.select([self.resp_r], [], [], left)
            if not r:
                raise _Timeout
            chunk = os.read(self.resp_r, 1 << 20)
            if not chunk:
                raise StudentCrash(self.death())
            self._buf += chunk

    def death(self) -> str:
        """Why the child is gone, in words."""
        try:
            code = self.proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            return "the process closed the grader's channel"
        if self.sandbox.secure and 128 < code < 128 + 65 and code - 128 in signal.Signals._value2member_map_:
            code = 128 - code  # bwrap reports a child killed by signal N as exit status 128 + N
        if code < 0:
            sig = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ else str(-code)
            why = {
                "SIGSEGV": " (segmentation fault: e.g. unbounded recursion)",
                "SIGXCPU": " (CPU time limit)",
                "SIGKILL": " (killed: e.g. out of memory)",
                "SIGABRT": " (aborted: e.g. out of memory in a C library)",
            }.get(sig, "")
            return f"the process died with {sig}{why}"
        return f"the process exited with status {code} (sys.exit or os._exit in the submission?)"

    def take_notes(self, answer) -> None:
        """Keep what the child's audit hook noticed (feedback only; it never changes a score)."""
        notes = answer.get("notes") if isinstance(answer, dict) else None
        if isinstance(notes, list):
            for n in notes[:8]:
                if isinstance(n, str) and n not in self.notes:
                    self.notes.append(n[:300])

    def close(self) -> None:
        """End every process of the child (its PID namespace; as root every process of its uid), wait
        until none is left, and clean up; idempotent (fd numbers are reused)."""
        if self._closed:
            return
        self._closed = True
        init = self._namespace_init()
        if init is not None:
            # the namespace's first process and the child it runs; anything more was left running
            extra = len(pid_namespace_members(init)) - 2
            if extra > 0:
                self.notes.append(
                    f"{extra} process(es) your code started were still running; the sandbox ended them"
                )
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        if self.sandbox.secure:
            end_all(init, self.uid)
        try:
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            pass
        for fd in (self.req_w, self.resp_r, self.info_r):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._reader.join(timeout=1.0)
        if self.proc.stdout:
            self.proc.stdout.close()
        shutil.rmtree(self.dir, ignore_errors=True)


# ------------------------------------------------------------------------------------- the proxy
class Submission:
    """The student's module as the graded tests see it: ``sub.f(*args)`` runs ``f`` in the child.

    Arguments are sent by value (numbers, lists, tuples, str-keyed dicts, NumPy arrays); the return
    value comes back the same way (tuples as lists). The time the student's code takes is charged to
    the test's limit; exceeding it kills the child and raises :class:`StudentTimeout`.
    """

    def __init__(self, child: _Child, module: str, functions: list[str], timeout_s: float):
        self._child = child
        self._module = module
        self._functions = set(functions)
        self._timeout_s = timeout_s
        self._left_s = timeout_s
        self._dead: str | None = None

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return functools.partial(self.call, name)

    def defines(self, name: str) -> bool:
        return name in self._functions

    def call(self, name: str, *args, **kwargs):
        if self._dead:
            raise StudentCrash(self._dead)
        if name not in self._functions:
            raise Fail(
                f"{self._module} does not define the function {name}() (it is one of the functions to write)"
            )
        t0 = time.monotonic()
        deadline = t0 + max(self._left_s, 0.0)
        try:
            self._child.send({"op": "call", "call": name, "args": list(args), "kwargs": kwargs}, deadline)
            answer = self._child.receive(deadline)
        except _Timeout:
            self._dead = f"{name} did not return within this test's limit of {self._timeout_s:g} s"
            self._child.close()
            raise StudentTimeout(
                self._dead + " (an infinite loop? a loop that never ends its search?)"
            ) from None
        except StudentCrash as e:
            self._dead = f"while running {name}: {e}"
            raise StudentCrash(self._dead) from None
        except WireError as e:
            self._dead = f"{name} sent an answer the grader cannot read ({e})"
            self._child.close()
            raise StudentCrash(self._dead) from None
        finally:
            self._left_s -= time.monotonic() - t0
        self._child.take_notes(answer)
        if not isinstance(answer, dict) or "ok" not in answer:
            raise StudentCrash(f"{name} sent an answer the grader cannot read")
        if answer["ok"]:
            return answer.get("value")
        err = answer.get("error") if isinstance(answer.get("error"), dict) else {}
        raise StudentError(name, self._module, err)


# ------------------------------------------------------------------------------------------ grading
@dataclass
class _Limits:
    source: bytes  # the submitted module, read once
    module: str
    memory_mb: int
    import_timeout_s: float
    sandbox: Sandbox
    hide: tuple[str, ...] = ()  # folders the child must not see (the assignment's)


def _start(limits: _Limits, cpu_s: float, import_deadline: float) -> tuple[_Child, list[str]]:
    """A child with the module imported; raises ImportFailed (and closes the child) otherwise.

    ``cpu_s`` is the child's CPU-time backstop (``RLIMIT_CPU``), above every wall-clock limit it has."""
    child = _Child(
        limits.source, limits.module, limits.memory_mb, int(cpu_s) + 2, limits.sandbox, limits.hide
    )
    try:
        hello = child.receive(import_deadline)
        child.take_notes(hello)
        if not (isinstance(hello, dict) and hello.get("ready")):
            info = hello.get("error", {}) if isinstance(hello, dict) else {}
            t, m = info.get("type", "Exception"), info.get("message", "")
            raise ImportFailed(f"importing {limits.module} failed: {t}: {m}" + _where(info, limits.module))
    except _Timeout:
        child.close()
        raise ImportFailed(
            f"importing {limits.module} did not finish within {limits.import_timeout_s:g} s "
            "(code at module level runs on import: an infinite loop or a long computation there?)",
            child.notes,
        ) from None
    except (StudentCrash, WireError) as e:
        child.close()
        raise ImportFailed(f"importing {limits.module} failed: {e}", child.notes) from None
    except ImportFailed as e:
        child.close()
        raise ImportFailed(str(e), child.notes) from None
    return child, list(hello.get("functions", []))


def _run_one(test: GradedTest, limits: _Limits, timeout_s: float) -> TestResult:
    t0 = time.monotonic()
    child = None
    printed = ""
    notes: list[str] = []
    try:
        child, functions = _start(limits, limits.import_timeout_s + timeout_s, t0 + limits.import_timeout_s)
        sub = Submission(child, limits.module, functions, timeout_s)
        note = test.func(sub)
        score, status, output = test.points, "passed", (str(note) if note else "")
    except Fail as e:
        score, status, output = 0.0, "failed", str(e)
    except SubmissionProblem as e:
        score, status, output = 0.0, "failed", str(e)
    except Exception as e:  # noqa: BLE001 - a bug in the graded test, or a value it did not foresee
        tb = traceback.format_exception_only(type(e), e)[-1].strip()
        score, status = 0.0, "failed"
        output = (
            f"GRADER ERROR: the test could not check what {test.target} returned ({tb}). "
            "Tell the instructor; this is probably not your fault."
        )
    finally:
        if child is not None:
            child.close()  # ends the child and drains its output pipe to the end first:
            printed = child.printed()  # what it printed just before answering is not lost
            notes = child.notes
    if printed.strip():
        shown = printed if len(printed) <= _OUTPUT_SHOW else printed[:_OUTPUT_SHOW] + "\n..."
        output = (output + "\n\n" if output else "") + "Your code printed:\n" + shown
    if notes:
        output = (
            (output + "\n\n" if output else "")
            + "The grader's sandbox refused:\n"
            + "\n".join(f"  - {n}" for n in notes)
        )
    if not limits.sandbox.secure:
        output = INSECURE + ("\n" + output if output else "")
    return TestResult(test, score, status, output, time.monotonic() - t0, tuple(notes))


class Refused(Exception):
    """The submission is not a module the grader will run (a link, a device, a folder, too large)."""


def _kind(mode: int) -> str:
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISREG(mode):
        return "a file"
    return "a device, pipe or socket"


def find_module(assignment: Assignment, submission: str | Path) -> Path | None:
    """The module file of a submission: the path itself if it is not a folder, else
    ``SUBMISSION/<module>`` (also one folder down, as Gradescope sometimes nests uploads). None when it
    is not there. Links are not followed: :func:`read_module` refuses what is not a regular file."""
    p = Path(submission)
    if not os.path.lexists(p):
        return None
    if not p.is_dir() or p.is_symlink():
        return p
    direct = p / assignment.module
    if os.path.lexists(direct):
        return direct
    nested = sorted(q for q in p.glob(f"*/{assignment.module}") if os.path.lexists(q))
    return nested[0] if len(nested) == 1 else None


def read_module(assignment: Assignment, path: Path) -> bytes:
    """The bytes of the submitted module, read once; :class:`Refused` unless it is a regular file
    reached without following a symbolic link."""
    name = assignment.module
    for q in (path, path.parent):
        try:
            st = os.lstat(q)
        except OSError as e:
            raise Refused(f"refused {path}: cannot read it ({e.strerror})") from None
        if q == path and not stat.S_ISREG(st.st_mode):
            raise Refused(
                f"refused {path}: it is {_kind(st.st_mode)}, not a file; submit {name} itself "
                "(links are not followed)"
            )
        if q != path and stat.S_ISLNK(st.st_mode):
            raise Refused(f"refused {path}: its folder {q.name} is a symbolic link (links are not followed)")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise Refused(f"refused {path}: cannot open it without following a link ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise Refused(f"refused {path}: it is {_kind(st.st_mode)}, not a file; submit {name} itself")
        if st.st_size > _MAX_MODULE_BYTES:
            raise Refused(
                f"refused {path}: {st.st_size >> 10} KB is more than a module of {name} needs (2 MB)"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read(_MAX_MODULE_BYTES + 1)
    finally:
        os.close(fd)


def choose_sandbox(insecure: bool = False) -> Sandbox:
    """The machine's sandbox; without one, :class:`SandboxUnavailable` unless ``insecure`` (then none)."""
    try:
        return find_sandbox()
    except SandboxUnavailable as e:
        if insecure:
            return Sandbox("none")
        raise SandboxUnavailable(
            f"refusing to grade without a sandbox: {e}; --insecure grades anyway, for practice only "
            "(every result then says so)"
        ) from None


def grade_submission(
    assignment: Assignment,
    submission: str | Path,
    *,
    jobs: int | None = None,
    timeout_scale: float = 1.0,
    insecure: bool = False,
    sandbox: Sandbox | None = None,
) -> GradeReport:
    """Run every graded test of ``assignment`` against ``submission`` (a folder or the module file).

    Parameters
    ----------
    assignment : Assignment
    submission : path
        A folder holding ``assignment.module`` (Gradescope's ``/autograder/submission``), or the file.
    jobs : int, optional
        Tests run at once (each in its own child); default ``min(4, cpu count)``.
    timeout_scale : float
        Multiplies every per-test time limit (a slow grading machine).
    insecure : bool
        Without a working sandbox, grade anyway (practice only: every result says so).
    sandbox : Sandbox, optional
        The isolation to use (default: :func:`~lab.grading.isolation.find_sandbox`).

    Returns
    -------
    GradeReport
        Never raises for anything the submission does.

    Raises
    ------
    SandboxUnavailable
        No sandbox works on this machine and ``insecure`` is False.
    """
    t0 = time.monotonic()
    sb = sandbox or choose_sandbox(insecure)
    make_undumpable()
    suite = assignment.load_suite()
    jobs = jobs or max(1, min(4, os.cpu_count() or 1))

    def nothing_runs(msg: str, notes: list[str] = ()) -> GradeReport:
        text = msg if sb.secure else f"{INSECURE}\n{msg}"
        if notes:
            text += "\n\nThe grader's sandbox refused:\n" + "\n".join(f"  - {n}" for n in notes)
        results = [TestResult(t, 0.0, "failed", text, 0.0, tuple(notes)) for t in suite.tests]
        return GradeReport(assignment, str(submission), results, time.monotonic() - t0, msg, sb.kind)

    module_path = find_module(assignment, submission)
    if module_path is None:
        return nothing_runs(
            f"no {assignment.module} found in {submission}: submit the file {assignment.module}"
        )
    try:
        source = read_module(assignment, module_path)
    except Refused as e:
        return nothing_runs(str(e))
    limits = _Limits(
        source,
        assignment.module,
        assignment.memory_mb,
        assignment.import_timeout_s * timeout_scale,
        sb,
        (str(Path(assignment.folder).resolve()),),
    )

    # One import probe: a module that cannot be imported fails every test with the same message,
    # without paying its import timeout once per test.
    try:
        child, _ = _start(limits, limits.import_timeout_s, t0 + limits.import_timeout_s)
        child.close()
    except ImportFailed as e:
        return nothing_runs(str(e), e.notes)

    budget_end = t0 + assignment.budget_s

    def run(test: GradedTest) -> TestResult:
        left = budget_end - time.monotonic()
        if left < 1.0:
            return TestResult(
                test,
                0.0,
                "failed",
                f"not run: grading stopped after its time budget of {assignment.budget_s:g} s "
                "(earlier tests timed out)",
                0.0,
            )
        timeout = min((test.timeout_s or assignment.timeout_s) * timeout_scale, left)
        return _run_one(test, limits, timeout)

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        results = list(pool.map(run, suite.tests))
    _point_at_dependencies(results)
    return GradeReport(assignment, str(submission), results, time.monotonic() - t0, None, sb.kind)


def _point_at_dependencies(results: list[TestResult]) -> None:
    """A failed test whose function uses another failing function says so (fix that one first)."""
    failing: dict[str, list[str]] = {}
    for r in results:
        if r.status != "passed":
            failing.setdefault(r.test.target, []).append(r.test.id)
    for r in results:
        if r.status == "passed" or r.output.startswith(f"{r.test.target} is not implemented"):
            continue
        culprits = [f for f in r.test.uses if f in failing and f != r.test.target]
        if culprits:
            one = len(culprits) == 1
            r.output += f"\nNote: {r.test.target} uses {', '.join(culprits)}, which " + (
                "fails its own tests; fix it first." if one else "fail their own tests; fix those first."
            )
