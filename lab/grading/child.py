"""The child that runs a student's code for one graded test, and the proxy the test calls it through.

A :class:`ChildProcess` is a running ``sandbox.py`` inside the sandbox (:mod:`lab.grading.isolation`)
with its private request and answer pipes; :func:`start_child` starts one and waits for the module's
import; :class:`Submission` is the student's module as a graded test sees it (calls go out as values
and come back as values); the :class:`SubmissionProblem` family says how the student's code failed.
"""

from __future__ import annotations

import functools
import json
import os
import select
import shutil
import signal
import struct
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from lab.grading import seccomp
from lab.grading.isolation import (
    ENTRY,
    SUBMISSION_DIR,
    Sandbox,
    end_all,
    pid_namespace_members,
    private_workdir,
    processes_of_uid,
)
from lab.grading.limits import error_info, function_names
from lab.grading.records import Records
from lab.grading.sandbox import MAX_MESSAGE_BYTES, WireError, decode, encode
from lab.grading.suite import Fail

__all__ = [
    "ChildLimits",
    "ChildProcess",
    "ImportFailed",
    "StudentCrash",
    "StudentError",
    "StudentTimeout",
    "Submission",
    "SubmissionProblem",
    "start_child",
]

_SANDBOX = Path(__file__).with_name("sandbox.py")
_HEADER = struct.Struct(">I")
_OUTPUT_KEEP = 4000  # characters of the child's stdout/stderr kept for feedback


# ------------------------------------------------------------------------------------------ outcomes


def _signal_name(number: int) -> str | None:
    """The name of signal ``number`` (``"SIGKILL"``), or None when it is not a signal of this platform."""
    try:
        return signal.Signals(number).name
    except ValueError:
        return None


class SubmissionProblem(Exception):
    """The student's code did not produce a value: raised, timed out, crashed or failed to import."""


class StudentError(SubmissionProblem):
    """A student function raised; ``info`` holds the type, message and the lines of their file."""

    def __init__(self, function: str, module: str, info: dict):
        self.function, self.module, self.info = function, module, error_info(info)
        self.type = self.info["type"]
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


def _child_env(sandbox: Sandbox, home: str, rules: dict | None, records_fd: int) -> dict:
    """The child's whole environment: nothing of the grader's but a ``PATH``; one thread per numeric
    library; the import rules and the record pipe's descriptor (``LAB_GRADE_RULES``)."""
    return {
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
        "LAB_GRADE_RULES": json.dumps({**(rules or {}), "records_fd": records_fd}),
    }


class ChildProcess:
    """A running ``sandbox.py`` (in the sandbox) with its private request and answer pipes."""

    def __init__(
        self,
        source: bytes,
        module: str,
        memory_mb: int,
        cpu_s: int,
        sandbox: Sandbox,
        hide: tuple[str, ...],
        rules: dict | None = None,
    ):
        self.sandbox = sandbox
        self.uid = sandbox.new_uid()
        own = sandbox.kind == "uid"  # no filesystem of its own: a private folder owned by its uid
        # bwrap: the child's throwaway uid reads the folder (read-only, in the sandbox)
        self.dir = private_workdir(self.uid if own else None, "lab-grade-")
        self.module_file = self.dir / module  # under the assignment's name, whatever the upload was called
        self.module_file.write_bytes(source)
        os.chmod(self.module_file, 0o644)
        if own:
            os.chown(self.module_file, self.uid, self.uid)
        self.notes: list[str] = []
        req_r, self.req_w = os.pipe()
        self.resp_r, resp_w = os.pipe()
        info_r, info_w = os.pipe() if sandbox.bubblewrap else (-1, -1)
        rec_r, rec_w = os.pipe()  # the record of refused attempts (lab.grading.records)
        self.records = Records(rec_r, self.notes)
        home = "/tmp" if sandbox.bubblewrap else str(self.dir)
        env = _child_env(sandbox, home, rules, rec_w)
        args = [
            "-I",  # isolated: no PYTHON* variables, no user site, no script folder on sys.path
            "-u",  # unbuffered: what the student printed before a crash or a timeout is not lost
            ENTRY if sandbox.bubblewrap else str(_SANDBOX),  # uid mode: read as root, before the drop
            str(req_r),
            str(resp_w),
            f"{SUBMISSION_DIR}/{module}" if sandbox.bubblewrap else str(self.module_file),
            str(memory_mb),
            str(cpu_s),
            str(-1 if self.uid is None else self.uid),
        ]
        cmd = sandbox.command(args, self.dir, _SANDBOX, self.uid, hide)
        if sandbox.bubblewrap:
            cmd[1:1] = ["--info-fd", str(info_w)]  # bwrap says there the pid of the namespace's first process
        fds = (req_r, resp_w, rec_w) + ((info_w,) if sandbox.bubblewrap else ())
        if sandbox.secure:  # the seccomp filter, installed before any of the student's code runs
            fds += (seccomp.attach(cmd, env, sandbox.bubblewrap),)
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
        self._messages = 0  # received so far (the record pipe has one mark per message)
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
                    self.records.after_message(self._messages)
                    self._messages += 1
                    return decode(data)
            left = deadline - time.monotonic()
            if left <= 0:
                raise _Timeout
            r, _, _ = select.select([self.resp_r, *self.records.waiting()], [], [], left)
            if self.records.fd in r:  # read as it comes: a child noting much never blocks on it
                self.records.pump()
            if self.resp_r not in r:
                continue
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
        bwrap_signal = 128 < code < 128 + 65 and _signal_name(code - 128) is not None
        if self.sandbox.bubblewrap and bwrap_signal:
            code = 128 - code  # bwrap reports a child killed by signal N as exit status 128 + N
        if code < 0:
            sig = _signal_name(-code) or str(-code)
            why = {
                "SIGSEGV": " (segmentation fault: e.g. unbounded recursion)",
                "SIGXCPU": " (CPU time limit)",
                "SIGKILL": " (killed: e.g. out of memory)",
                "SIGABRT": " (aborted: e.g. out of memory in a C library)",
            }.get(sig, "")
            return f"the process died with {sig}{why}"
        return f"the process exited with status {code} (sys.exit or os._exit in the submission?)"

    def close(self) -> None:
        """End every process of the child (its PID namespace; as root every process of its uid), wait
        until none is left, and clean up; idempotent (fd numbers are reused)."""
        if self._closed:
            return
        self._closed = True
        init = self._namespace_init()
        extra = 0
        if init is not None:
            # the namespace's first process and the child it runs; anything more was left running
            extra = len(pid_namespace_members(init)) - 2
        elif self.sandbox.kind == "uid" and self.uid is not None:
            extra = len([p for p in processes_of_uid(self.uid) if p != self.proc.pid])
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
        self.records.finish()  # what reached the record pipe, to the end
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

    def __init__(self, child: ChildProcess, module: str, functions: list[str], timeout_s: float):
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
        if not isinstance(answer, dict) or not isinstance(answer.get("ok"), bool):
            raise StudentCrash(f"{name} sent an answer the grader cannot read")
        if answer["ok"]:
            return answer.get("value")
        err = answer.get("error") if isinstance(answer.get("error"), dict) else {}
        raise StudentError(name, self._module, err)


# ------------------------------------------------------------------------------------------ starting
@dataclass
class ChildLimits:
    source: bytes  # the submitted module, read once
    module: str
    memory_mb: int
    import_timeout_s: float
    sandbox: Sandbox
    hide: tuple[str, ...] = ()  # folders the child must not see (the assignment's, the oracles')
    rules: dict | None = None  # the import rules (lab.grading.rules.child_rules)


def start_child(limits: ChildLimits, cpu_s: float, import_deadline: float) -> tuple[ChildProcess, list[str]]:
    """A child with the module imported; raises ImportFailed (and closes the child) otherwise.

    ``cpu_s`` is the child's CPU-time backstop (``RLIMIT_CPU``), above every wall-clock limit it has."""
    child = ChildProcess(
        limits.source,
        limits.module,
        limits.memory_mb,
        int(cpu_s) + 2,
        limits.sandbox,
        limits.hide,
        limits.rules,
    )
    try:
        hello = child.receive(import_deadline)
        if not (isinstance(hello, dict) and hello.get("ready")):
            info = error_info(hello.get("error") if isinstance(hello, dict) else None)
            t, m = info["type"], info["message"]
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
    return child, function_names(hello.get("functions"))
