"""Where a student's code runs: a bubblewrap sandbox that sees only its own copy of the submission.

The grader runs each graded test's student code in a child process (:mod:`lab.grading.sandbox`). This
module puts that child inside `bubblewrap <https://github.com/containers/bubblewrap>`_ (``bwrap``, the
Debian package ``bubblewrap``; the sandbox Flatpak is built on), chosen because it is maintained,
small, packaged everywhere, needs no daemon, and gives in one command everything the grader needs:

* **a filesystem of its own**: an empty root with read-only binds of the system (``/usr``), the Python
  installation and its packages (the ``lab`` package, the assignments, the graded tests and the
  repository are masked if they lie inside those), the submission's private copy at
  ``/submission``, the child's entry point at ``/grader/sandbox.py``, a fresh ``/proc`` and ``/dev``
  and a private ``/tmp``. Nothing else exists: not the reference solutions, not the graded tests,
  not a classmate's folder, not the grader's results file;
* **no network** (a network namespace with only a loopback interface), its own PID, IPC and UTS
  namespaces, a new session (no terminal injection), no capabilities and ``no_new_privs``;
* **an end**: with ``--die-with-parent`` and its own PID namespace, every process the test started
  dies with it; the grader kills the namespace's first process and waits until it is gone (and, as
  root, until no process of the test's uid is left) before it records the result.

Two ways of running it, chosen by who runs the grader:

* ``bwrap-uid`` (the grader is root, as on Gradescope and in CI): bwrap runs privileged (no user
  namespace needed) with every capability dropped except ``setuid``/``setgid``; the child's first act,
  before it imports anything of the student's, is to become a throwaway uid and gid (random, above
  2**30, no supplementary groups), different for every child. So the student's code is not root,
  cannot read or signal the grader, and the process limit applies to it.
* ``bwrap-userns`` (the grader is an ordinary user): bwrap makes a user namespace; the child keeps the
  grader's uid outside it (there is no other uid to drop to without root) but sees nothing of the
  grader's files and cannot reach its process (another PID namespace; the grader is not dumpable).

The grader itself is made non-dumpable (``prctl(PR_SET_DUMPABLE, 0)``): no process of its uid can
read or write its memory through ``/proc/<pid>/mem`` or ptrace it.

When bwrap is missing or does not work here (a container that forbids namespaces), :func:`find_sandbox`
says why, and ``lab grade`` refuses to grade for scores unless ``--insecure`` (practice only; every
result then says so). ``lab grade --check-sandbox`` runs :func:`check_sandbox`: a real sandboxed child
that tries what a cheating submission would, and reports each attempt.
"""

from __future__ import annotations

import ctypes
import functools
import json
import os
import secrets
import shutil
import signal
import site
import subprocess
import sys
import sysconfig
import time
from dataclasses import dataclass
from pathlib import Path

from lab.errors import LabError

__all__ = [
    "Sandbox",
    "SandboxUnavailable",
    "find_sandbox",
    "check_sandbox",
    "make_undumpable",
    "SUBMISSION_DIR",
    "ENTRY",
]

SUBMISSION_DIR = "/submission"  # where the child sees its copy of the submission
ENTRY = "/grader/sandbox.py"  # where the child sees its entry point
_UID_LOW, _UID_HIGH = 1 << 30, (1 << 31) - 2  # throwaway uids: far above any real account
_PR_SET_DUMPABLE, _PR_GET_DUMPABLE = 4, 3
_handed_out: set[int] = set()


class SandboxUnavailable(LabError):
    """No sandbox works on this machine; the message says why and what to do."""


@dataclass(frozen=True)
class Sandbox:
    """How children are isolated.

    Attributes
    ----------
    kind : str
        ``"bwrap-uid"`` (root: throwaway uid per child), ``"bwrap-userns"`` (a user namespace) or
        ``"none"`` (``--insecure``: no isolation beyond resource limits).
    bwrap : str or None
        Path of the bwrap executable.
    """

    kind: str
    bwrap: str | None = None

    @property
    def secure(self) -> bool:
        return self.kind != "none"

    def describe(self) -> str:
        return {
            "bwrap-uid": "bubblewrap: own filesystem, no network, own PID namespace, throwaway uid per test",
            "bwrap-userns": "bubblewrap: own filesystem, no network, own PID namespace, a user namespace",
            "none": "NO SANDBOX (--insecure): the student code can read the grader files; practice only",
        }[self.kind]

    def new_uid(self) -> int | None:
        """A fresh throwaway uid (root only: one of 2**30, drawn at random, never one handed out before
        by this process); None when the child keeps the grader's uid."""
        if self.kind != "bwrap-uid":
            return None
        while True:
            uid = _UID_LOW + secrets.randbelow(_UID_HIGH - _UID_LOW)
            if uid not in _handed_out:
                _handed_out.add(uid)
                return uid

    def command(
        self, python_args: list[str], scratch: Path, entry: Path, uid: int | None, hide: tuple[str, ...] = ()
    ) -> list[str]:
        """The full command line running ``python python_args`` in the sandbox (or bare, if none):
        ``scratch`` is seen as ``/submission``, ``entry`` as ``/grader/sandbox.py``; folders in ``hide``
        (an assignment's) are masked if they lie inside what the child is given."""
        if self.kind == "none":
            return [sys.executable, *python_args]
        return [*_bwrap_args(self, scratch, entry, hide), "--", sys.executable, *python_args]


def _secrets() -> list[Path]:
    """Folders the child must never see even when they lie inside what it is given."""
    from lab.grading.assignments import assignments_dir
    from lab.paths import repo_root

    lab_pkg = Path(__file__).resolve().parent.parent
    return [p.resolve() for p in (lab_pkg, repo_root(), assignments_dir()) if p.exists()]


@functools.lru_cache(maxsize=1)
def _python_roots() -> tuple[str, ...]:
    """The folders the child's Python needs: its installation, the venv, the packages' folders."""
    cands = {sys.base_prefix, sys.base_exec_prefix, sys.prefix, sys.exec_prefix}
    for key in ("stdlib", "platstdlib", "purelib", "platlib"):
        cands.add(sysconfig.get_paths()[key])
    cands.update(site.getsitepackages())
    cands.add(str(Path(sys.executable).parent))
    cands.add(str(Path(os.path.realpath(sys.executable)).parent))
    roots = sorted({os.path.realpath(c) for c in cands if c and os.path.isdir(c)} | {"/usr"})
    kept: list[str] = []
    for r in roots:  # drop folders inside another kept one
        if not any(r == k or r.startswith(k.rstrip("/") + "/") for k in kept):
            kept.append(r)
    # the venv's own path may be a symlink to its real path: bind it under both names
    for c in (sys.prefix, str(Path(sys.executable).parent)):
        if os.path.realpath(c) != c and os.path.isdir(c):
            kept.append(c)
    return tuple(kept)


def _bwrap_args(sb: Sandbox, scratch: Path, entry: Path, hide: tuple[str, ...] = ()) -> list[str]:
    return [*_bwrap_fixed(sb, str(entry), hide), "--ro-bind", str(scratch), SUBMISSION_DIR]


@functools.lru_cache(maxsize=16)
def _bwrap_fixed(sb: Sandbox, entry: str, hide: tuple[str, ...]) -> tuple[str, ...]:
    """Everything of the bwrap command but the submission's folder (the same for every child)."""
    args = [sb.bwrap]
    # first the private mounts, so that a Python installation under /tmp is bound over them, not hidden
    args.extend(["--proc", "/proc", "--dev", "/dev", "--perms", "1777", "--tmpfs", "/tmp"])
    made: set[str] = {"/", "/proc", "/dev", "/tmp"}

    def parents(target: str) -> None:
        # bwrap makes missing folders 0700 (root-only) when it runs as root: make them readable
        parts = Path(target).parts[1:-1]
        for i in range(len(parts)):
            d = "/" + "/".join(parts[: i + 1])
            if d not in made:
                made.add(d)
                args.extend(["--perms", "0755", "--dir", d])

    for top in ("bin", "lib", "lib32", "lib64", "libx32", "sbin"):
        p = "/" + top
        if os.path.islink(p):
            args.extend(["--symlink", os.readlink(p), p])
        elif os.path.isdir(p):
            args.extend(["--ro-bind", p, p])
        made.add(p)
    roots = _python_roots()
    for r in roots:
        if r in made:
            continue
        parents(r)
        args.extend(["--ro-bind", r, r])
        made.add(r)
    if os.path.exists("/etc/ld.so.cache"):
        parents("/etc/ld.so.cache")
        args.extend(["--ro-bind", "/etc/ld.so.cache", "/etc/ld.so.cache"])
    for s in sorted({*map(str, _secrets()), *hide}):  # masked over the binds: never readable
        if any(s == r or s.startswith(r.rstrip("/") + "/") for r in roots):
            args.extend(["--tmpfs", s])
    parents(ENTRY)
    args.extend(["--ro-bind", entry, ENTRY])
    args.extend(["--unshare-ipc", "--unshare-pid", "--unshare-net", "--unshare-uts", "--unshare-cgroup-try"])
    if sb.kind == "bwrap-userns":
        args.extend(["--unshare-user", "--cap-drop", "ALL"])
    else:  # root: keep only what the child needs to become its throwaway uid, then it has nothing
        args.extend(["--cap-drop", "ALL", "--cap-add", "CAP_SETUID", "--cap-add", "CAP_SETGID"])
    args.extend(["--die-with-parent", "--new-session", "--chdir", SUBMISSION_DIR])
    return tuple(args)


# ---------------------------------------------------------------------------------- processes
def processes_of_uid(uid: int) -> list[int]:
    """Pids of every process whose real uid is ``uid`` (read from /proc)."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/status", "rb") as f:
                for line in f:
                    if line.startswith(b"Uid:"):
                        if int(line.split()[1]) == uid:
                            found.append(int(name))
                        break
        except (OSError, ValueError, IndexError):
            continue
    return found


def pid_namespace_members(pid: int) -> list[int]:
    """Pids (as the grader sees them) of the processes in the PID namespace of which ``pid`` is first."""
    try:
        ns = os.readlink(f"/proc/{pid}/ns/pid")
    except OSError:
        return []
    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                if os.readlink(f"/proc/{name}/ns/pid") == ns:
                    found.append(int(name))
            except OSError:
                continue
    return found


def _alive(pid: int) -> bool:
    """True while ``pid`` exists and has not finished exiting (a zombie has finished)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rsplit(b")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in (b"Z", b"X")


def end_all(init_pid: int | None, uid: int | None, timeout_s: float = 10.0) -> None:
    """Kill the sandbox's PID namespace (its first process) and, as root, every process of ``uid``;
    return once none is left.

    The kernel kills every process of a PID namespace before its first process has finished exiting,
    so once that one is gone (or a zombie) the namespace is empty; the sweep of ``uid`` after it is
    a second, independent check."""
    deadline = time.monotonic() + timeout_s
    while init_pid is not None and _alive(init_pid):
        try:
            os.kill(init_pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        if time.monotonic() > deadline:
            raise RuntimeError(f"the sandbox's first process {init_pid} did not end after SIGKILL")
        time.sleep(0.001)
    while uid is not None:
        pids = [p for p in processes_of_uid(uid) if _alive(p)]
        if not pids:
            return
        for p in pids:
            try:
                os.kill(p, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        if time.monotonic() > deadline:
            raise RuntimeError(f"processes {pids} of uid {uid} did not end after SIGKILL")
        time.sleep(0.001)


# ------------------------------------------------------------------------------------ the grader
def make_undumpable() -> bool:
    """``prctl(PR_SET_DUMPABLE, 0)`` on the grading process: no process of its uid can read or write its
    memory (``/proc/<pid>/mem``, ptrace). True if it is now non-dumpable."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_DUMPABLE, 0, 0, 0, 0)
        return libc.prctl(_PR_GET_DUMPABLE, 0, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


# ---------------------------------------------------------------------------------- detection
def _probe(sb: Sandbox) -> str | None:
    """Run one trivial child in ``sb``; None if it works, else why not."""
    import tempfile

    entry = Path(__file__).with_name("sandbox.py")
    with tempfile.TemporaryDirectory(prefix="lab-probe-") as d:
        os.chmod(d, 0o755)
        uid = sb.new_uid()
        code = "import os, sys; "
        if uid is not None:
            code += f"os.setgroups([]); os.setgid({uid}); os.setuid({uid}); "
        # NumPy found (not imported: that would take longer than the rest) proves the packages are there
        code += "import importlib.util as u; assert u.find_spec('numpy'), 'no numpy in the sandbox'; "
        code += "sys.stdout.write(str(os.getuid()))"
        try:
            r = subprocess.run(
                sb.command(["-I", "-c", code], Path(d), entry, uid),
                capture_output=True,
                text=True,
                timeout=60,
                stdin=subprocess.DEVNULL,
            )
        except (OSError, subprocess.TimeoutExpired) as e:
            return f"{sb.bwrap} could not run: {e}"
        if r.returncode != 0:
            last = (r.stderr.strip().splitlines() or [f"exit status {r.returncode}"])[-1]
            return f"{sb.bwrap} failed here: {last}"
        if uid is not None and r.stdout.strip() != str(uid):
            return f"the sandboxed child did not become uid {uid}"
    return None


@functools.lru_cache(maxsize=1)
def find_sandbox() -> Sandbox:
    """The sandbox this machine supports (probed once per process); raises SandboxUnavailable."""
    if sys.platform != "linux":
        raise SandboxUnavailable(f"the grading sandbox needs Linux (bubblewrap); this is {sys.platform}")
    bwrap = shutil.which("bwrap")
    if bwrap is None:
        raise SandboxUnavailable(
            "bubblewrap (bwrap) is not installed: apt-get install bubblewrap "
            "(then check with lab grade --check-sandbox)"
        )
    sb = Sandbox("bwrap-uid" if os.geteuid() == 0 else "bwrap-userns", bwrap)
    why = _probe(sb)
    if why:
        raise SandboxUnavailable(f"{why} (namespaces forbidden here?); check with lab grade --check-sandbox")
    return sb


# ------------------------------------------------------------------------------- check-sandbox
_CHECKS = r"""
import json, os, socket, sys
uid = int(sys.argv[1])
if uid >= 0:
    os.setgroups([]); os.setgid(uid); os.setuid(uid)
secrets, grader_pid, results = json.loads(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
out = {}
def attempt(name, fn):
    try:
        fn()
        out[name] = "NOT stopped"
    except Exception as e:
        out[name] = f"stopped ({type(e).__name__}: {e})"
for s in secrets:
    attempt(f"read {s}", lambda s=s: os.listdir(s) if os.path.isdir(s) else open(s).read())
attempt(f"write {results}", lambda: open(results, "a").close())
attempt(f"see the grader (pid {grader_pid}) in /proc", lambda: open(f"/proc/{grader_pid}/status").read())
attempt(f"signal the grader (pid {grader_pid})", lambda: os.kill(grader_pid, 0))
def net():
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM); s.settimeout(2)
    s.connect(("1.1.1.1", 53))
attempt("open a network connection (1.1.1.1:53)", net)
attempt("become root (setuid 0)", lambda: os.setuid(0))
attempt("write outside /tmp (/usr)", lambda: open("/usr/lab-sandbox-check", "w").close())
out["uid"] = os.getuid()
sys.stdout.write(json.dumps(out))
"""


def check_sandbox(results_path: str | Path | None = None) -> tuple[bool, list[str]]:
    """Start a real sandboxed child and try, from inside, what a cheating submission would.

    Returns ``(ok, lines)``: ``ok`` is True when a sandbox works and stops every attempt.
    """
    import tempfile

    lines = []
    undumpable = make_undumpable()
    lines.append(f"{'ok ' if undumpable else 'BAD'} the grader is not dumpable (prctl PR_SET_DUMPABLE 0)")
    try:
        sb = find_sandbox()
    except SandboxUnavailable as e:
        return False, [*lines, f"BAD no sandbox: {e}"]
    lines.append(f"ok  sandbox: {sb.describe()} ({sb.bwrap})")
    from lab.grading.assignments import assignments_dir
    from lab.paths import repo_root

    repo = repo_root().resolve()  # not a target: it holds the venv's folder when the venv is inside it
    targets = [str(p) for p in _secrets() if p != repo]
    a_dir = assignments_dir()
    for name in ("ekf/ekf.py", "ekf/hidden_tests.py"):
        if (a_dir / name).exists():
            targets.append(str((a_dir / name).resolve()))
    results = str(Path(results_path or Path.cwd() / "results.json").resolve())
    entry = Path(__file__).with_name("sandbox.py")
    ok = undumpable
    with tempfile.TemporaryDirectory(prefix="lab-check-") as d:
        os.chmod(d, 0o755)
        uid = sb.new_uid()
        cmd = sb.command(
            [
                "-I",
                "-c",
                _CHECKS,
                str(-1 if uid is None else uid),
                json.dumps(targets),
                str(os.getpid()),
                results,
            ],
            Path(d),
            entry,
            uid,
        )
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        try:
            found = json.loads(r.stdout)
        except ValueError:
            return False, [*lines, f"BAD the check did not run: {r.stderr.strip()[-300:]}"]
    child_uid = found.pop("uid")
    if uid is not None:
        good = child_uid == uid
        ok &= good
        lines.append(f"{'ok ' if good else 'BAD'} the student's code runs as uid {child_uid}, not root")
    else:
        lines.append(f"ok  the student's code runs as uid {child_uid} in a user namespace")
    for what, res in found.items():
        good = res.startswith("stopped")
        ok &= good
        lines.append(f"{'ok ' if good else 'BAD'} {what}: {res}")
    return ok, lines
