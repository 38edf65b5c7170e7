"""Where a student's code runs: a bubblewrap sandbox that sees only its own copy of the submission.

The grader runs each graded test's student code in a child process (:mod:`lab.grading.sandbox`). This
module puts that child inside `bubblewrap <https://github.com/containers/bubblewrap>`_ (``bwrap``, the
Debian package ``bubblewrap``; the sandbox Flatpak is built on), chosen because it is maintained,
small, packaged everywhere, needs no daemon, and gives in one command everything the grader needs:

* **a filesystem of its own**: an empty root with read-only binds of the system (``/usr``), the Python
  installation and its packages (the ``lab`` package, the assignments, the graded tests and the
  repository are masked if they lie inside those), the submission's private copy at
  ``/submission``, the child's entry point at ``/grader/sandbox.py``, a fresh ``/proc`` and ``/dev``
  and a private ``/tmp`` (a 16 MB tmpfs) with an empty, read-only ``/dev/shm``. Nothing else
  exists: not the reference solutions, not the graded tests, not a classmate's folder, not the
  grader's results file;
* **no network** (a network namespace with only a loopback interface), its own PID, IPC and UTS
  namespaces, a new session (no terminal injection), no capabilities and ``no_new_privs``;
* **a smaller kernel surface**: a seccomp filter (:mod:`lab.grading.seccomp`, in every mode) refuses
  new namespaces, io_uring, ``bpf``, shared memory, new files and what else grading never needs, and
  ``bwrap-userns`` passes ``--disable-userns``;
* **an end**: with ``--die-with-parent`` and its own PID namespace, every process the test started
  dies with it; the grader kills the namespace's first process and waits until it is gone (and, as
  root, until no process of the test's uid is left) before it records the result.

Two ways of running it, chosen by who runs the grader:

* ``bwrap-uid`` (the grader is root where namespaces are allowed, as in CI): bwrap runs privileged (no user
  namespace needed) with every capability dropped except ``setuid``/``setgid``; the child's first act,
  before it imports anything of the student's, is to become a throwaway uid and gid (random, above
  2**30, no supplementary groups), different for every child. So the student's code is not root,
  cannot read or signal the grader, and the process limit applies to it.
* ``bwrap-userns`` (the grader is an ordinary user): bwrap makes a user namespace; the child keeps the
  grader's uid outside it (there is no other uid to drop to without root) but sees nothing of the
  grader's files and cannot reach its process (another PID namespace; the grader is not dumpable).

The grader itself is made non-dumpable (``prctl(PR_SET_DUMPABLE, 0)``): no process of its uid can
read or write its memory through ``/proc/<pid>/mem`` or ptrace it.

A third way, for a root grader where bubblewrap cannot make namespaces (a default Docker container, as
on Gradescope: no ``CAP_SYS_ADMIN``), needs no namespace at all:

* ``uid``: the child starts as root, and its first act, before it imports anything of the student's,
  is to become a throwaway uid and gid of its own (as in ``bwrap-uid``); it then lowers its limits on
  processes (none), memory, CPU time, file size (no writes) and open files. It works in a private
  folder owned by that uid (mode 0700). The grader makes its own folders private (mode 0700: the
  course library, the assignments with their reference solutions and graded tests, a class's
  submissions and the results' folder: :func:`make_private`), so another uid reads none of them; the
  grader is non-dumpable, and every process of the child's uid is killed before a result is recorded.
  What it cannot stop, :attr:`Sandbox.cannot_stop` says (and ``--check-sandbox`` prints it as a
  WARNING): the network (cut it where the grader runs: ``docker run --network none``) and the list of
  the machine's processes in ``/proc`` (their command lines, not their memory or files).

:func:`find_sandbox` picks the strongest mode that works here (``bwrap-uid``, ``bwrap-userns``, then
``uid``; ``$LAB_GRADE_SANDBOX`` = ``bwrap`` or ``uid`` restricts the choice) and says which. When none
works it says why, and ``lab grade`` refuses to grade for scores unless ``--insecure`` (practice only;
every result then says so). ``lab grade --check-sandbox`` runs
:func:`lab.grading.sandbox_check.check_sandbox`: a real sandboxed child that tries what a cheating
submission would, and reports each attempt.
"""

from __future__ import annotations

import ctypes
import functools
import os
import secrets
import shutil
import signal
import site
import stat
import subprocess
import sys
import sysconfig
import time
from dataclasses import dataclass
from pathlib import Path

from lab.errors import LabError
from lab.grading import seccomp

__all__ = [
    "Sandbox",
    "SandboxUnavailable",
    "find_sandbox",
    "make_undumpable",
    "secret_folders",
    "make_private",
    "make_grader_private",
    "MODES",
    "SUBMISSION_DIR",
    "ENTRY",
    "TMP_BYTES",
    "SHM_BYTES",
]

SUBMISSION_DIR = "/submission"  # where the child sees its copy of the submission
ENTRY = "/grader/sandbox.py"  # where the child sees its entry point
TMP_BYTES, SHM_BYTES = 16 << 20, 4096  # the sizes of the sandbox's private /tmp and /dev/shm
_UID_LOW, _UID_HIGH = 1 << 30, (1 << 31) - 2  # throwaway uids: far above any real account
_PR_SET_DUMPABLE, _PR_GET_DUMPABLE = 4, 3
_handed_out: set[int] = set()
MODES = ("bwrap-uid", "bwrap-userns", "uid")  # strongest first: find_sandbox takes the first that works
_NETWORK = (
    "the network: the student's code can open connections (uid mode has no network namespace); cut it "
    "where the grader runs (docker run --network none; on a course server, a firewall rule for the "
    "throwaway uids 1073741824-2147483645: iptables -m owner --uid-owner)"
)
_PROCESSES = (
    "the process list: the student's code sees the machine's processes in /proc and their command "
    "lines (not their memory, files or environment); give the grader a command line with no secrets"
)
_SHARED_TMP = (
    "the machine's /tmp and /dev/shm filling up: they are shared (no mount namespace) and the grader "
    "cannot cap their size; the seccomp filter refuses the student's code every new file, folder, link "
    "and extended attribute, so it cannot fill them itself, but cap them where the grader runs "
    "(docker run --tmpfs /tmp:size=64m --shm-size=1m)"
)
_CANNOT_STOP = {"uid": (_NETWORK, _PROCESSES, _SHARED_TMP)}


class SandboxUnavailable(LabError):
    """No sandbox works on this machine; the message says why and what to do."""


@dataclass(frozen=True)
class Sandbox:
    """How children are isolated.

    Attributes
    ----------
    kind : str
        ``"bwrap-uid"`` (root: throwaway uid per child), ``"bwrap-userns"`` (a user namespace),
        ``"uid"`` (root without namespaces: throwaway uid per child, private grader folders) or
        ``"none"`` (``--insecure``: no isolation beyond resource limits).
    bwrap : str or None
        Path of the bwrap executable.
    """

    kind: str
    bwrap: str | None = None

    @property
    def secure(self) -> bool:
        return self.kind != "none"

    @property
    def bubblewrap(self) -> bool:
        """True when the child runs inside bwrap (its own filesystem, network and PID namespace)."""
        return self.kind.startswith("bwrap")

    @property
    def cannot_stop(self) -> tuple[str, ...]:
        """What this mode does not stop, in words, with the platform setting that does."""
        return _CANNOT_STOP.get(self.kind, ())

    def describe(self) -> str:
        return {
            "bwrap-uid": "bubblewrap: own filesystem, no network, own PID namespace, throwaway uid per test",
            "bwrap-userns": "bubblewrap: own filesystem, no network, own PID namespace, a user namespace",
            "uid": "uid mode (no namespaces): throwaway uid per test, private grader folders, rlimits; "
            "the network is NOT cut",
            "none": "NO SANDBOX (--insecure): the student code can read the grader files; practice only",
        }[self.kind]

    def new_uid(self) -> int | None:
        """A fresh throwaway uid (root only: one of 2**30, drawn at random, never one handed out before
        by this process); None when the child keeps the grader's uid."""
        if self.kind not in ("bwrap-uid", "uid"):
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
        (an assignment's) are masked if they lie inside what the child is given. In ``uid`` mode the
        command is bare too: the child itself becomes ``uid`` first (see :mod:`lab.grading.sandbox`)."""
        if not self.bubblewrap:
            return [sys.executable, *python_args]
        return [*_bwrap_args(self, scratch, entry, hide), "--", sys.executable, *python_args]


def secret_folders() -> list[Path]:
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
    # size-capped: a tmpfs is memory no limit of the child counts (and the seccomp filter refuses new
    # files anyway); /dev/shm, where POSIX shared memory lives, is empty and read-only
    args.extend(["--proc", "/proc", "--dev", "/dev", "--size", str(SHM_BYTES), "--tmpfs", "/dev/shm"])
    args.extend(["--remount-ro", "/dev/shm", "--perms", "1777", "--size", str(TMP_BYTES), "--tmpfs", "/tmp"])
    made: set[str] = {"/", "/proc", "/dev", "/dev/shm", "/tmp"}

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
    for s in sorted({*map(str, secret_folders()), *hide}):  # masked over the binds: never readable
        if any(s == r or s.startswith(r.rstrip("/") + "/") for r in roots):
            args.extend(["--tmpfs", s])
    parents(ENTRY)
    args.extend(["--ro-bind", entry, ENTRY])
    args.extend(["--unshare-ipc", "--unshare-pid", "--unshare-net", "--unshare-uts", "--unshare-cgroup-try"])
    if sb.kind == "bwrap-userns":
        args.extend(["--unshare-user", "--disable-userns", "--cap-drop", "ALL"])
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


def make_private(paths) -> list[str]:
    """Take every permission of group and others off the folders in ``paths`` (``chmod go-rwx``), so that
    a throwaway uid (``uid`` mode, where the child sees the grader's filesystem) can neither list nor
    read nor enter them. Only folders this process owns are changed, never a shared sticky one such as
    ``/tmp`` nor one holding the Python installation the child needs (a repository with its venv);
    returns the folders that are private now (changed or already so)."""
    done: list[str] = []
    pythons = [r.rstrip("/") + "/" for r in _python_roots()]
    for p in dict.fromkeys(os.path.realpath(q) for q in paths):
        try:
            st = os.stat(p)
        except OSError:
            continue
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid() or st.st_mode & stat.S_ISVTX:
            continue
        real = os.path.realpath(p).rstrip("/") + "/"
        if any(r.startswith(real) for r in pythons):
            continue
        if st.st_mode & 0o077:
            try:
                os.chmod(p, stat.S_IMODE(st.st_mode) & 0o700)
            except OSError:
                continue
        done.append(str(p))
    return done


def make_grader_private(extra=()) -> list[str]:
    """:func:`make_private` on the grader's own folders (the course library, the repository, the
    assignments; the repository's tests, which hold edits of the reference solutions, for when the
    repository itself must stay readable because the venv is inside it) and on ``extra`` (an
    assignment's folder, a class's submissions, the results)."""
    from lab.paths import repo_root

    return make_private([*secret_folders(), repo_root() / "tests", *extra])


def private_workdir(uid: int | None, prefix: str) -> Path:
    """A fresh folder for one child: in ``uid`` mode owned by the child's uid and closed to everyone
    else (0700), otherwise readable (0755: bwrap binds it read-only for the child's uid)."""
    import tempfile

    d = Path(tempfile.mkdtemp(prefix=prefix))
    if uid is None:
        os.chmod(d, 0o755)
    else:
        os.chown(d, uid, uid)
        os.chmod(d, 0o700)
    return d


# ---------------------------------------------------------------------------------- detection
def run_confined(sb: Sandbox, cmd: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    """Run a sandbox command (``sb.command``) under the seccomp filter every graded child runs under
    (:func:`lab.grading.seccomp.attach`), its output captured as text, within 60 s."""
    fd = seccomp.attach(cmd, env, sb.bubblewrap)
    try:
        return subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            timeout=60,
            stdin=subprocess.DEVNULL,
            cwd=cwd,
            env=env,
            pass_fds=(fd,),
        )
    finally:
        os.close(fd)


def _probe(sb: Sandbox) -> str | None:
    """Run one trivial child in ``sb``; None if it works, else why not."""
    entry = Path(__file__).with_name("sandbox.py")
    uid = sb.new_uid()
    d = private_workdir(uid if sb.kind == "uid" else None, "lab-probe-")
    try:
        code = "import os, sys; "
        if sb.kind == "uid":  # the child installs the seccomp filter itself, as a graded child does
            code += "import importlib.util as u; s = u.spec_from_file_location('entry', sys.argv[1]); "
            code += "e = u.module_from_spec(s); s.loader.exec_module(e); "
        if uid is not None:
            code += f"os.setgroups([]); os.setgid({uid}); os.setuid({uid}); "
        if sb.kind == "uid":
            code += "e.install_seccomp(); "
            # no filesystem of its own: the Python installation and NumPy must be readable by any uid
            code += "import numpy; "
        else:  # NumPy found (not imported: that would take longer than the rest) proves it is there
            code += "import importlib.util as u; assert u.find_spec('numpy'), 'no numpy in the sandbox'; "
        code += "sys.stdout.write(str(os.getuid()))"
        what = sb.bwrap if sb.bubblewrap else "the uid mode"
        cmd, env = sb.command(["-I", "-c", code, str(entry)], d, entry, uid), dict(os.environ)
        try:
            r = run_confined(sb, cmd, d, env)
        except (OSError, subprocess.TimeoutExpired) as e:
            return f"{what} could not run: {e}"
        if r.returncode != 0:
            last = (r.stderr.strip().splitlines() or [f"exit status {r.returncode}"])[-1]
            if sb.kind == "uid" and ("Permission denied" in last or not _others_can_enter(sys.base_prefix)):
                hint = "or its packages are not readable by other users: use one installed for all users"
                last += f" (the Python at {sys.base_prefix} {hint}, e.g. /usr/bin/python3)"
            return f"{what} failed here: {last}"
        if uid is not None and r.stdout.strip() != str(uid):
            return f"the child did not become uid {uid}"
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return None


def _others_can_enter(path: str) -> bool:
    """Whether other users can reach ``path`` (a pyenv Python under ``/root`` cannot)."""
    p = Path(path).resolve()
    try:
        return all(d.stat().st_mode & stat.S_IXOTH for d in (p, *p.parents))
    except OSError:
        return False


def find_sandbox() -> Sandbox:
    """The strongest isolation mode that works on this machine (probed once per process and choice);
    raises SandboxUnavailable saying why each one does not work.

    ``$LAB_GRADE_SANDBOX`` restricts the choice: ``bwrap`` (only bubblewrap), ``uid`` (only the uid
    mode), or ``auto`` (the default: :data:`MODES` in order)."""
    return _find(os.environ.get("LAB_GRADE_SANDBOX", "auto").strip() or "auto")


@functools.lru_cache(maxsize=4)
def _find(choice: str) -> Sandbox:
    if choice not in ("auto", "bwrap", "uid", *MODES):
        raise SandboxUnavailable(f"LAB_GRADE_SANDBOX={choice!r}: use auto, bwrap or uid")
    if sys.platform != "linux":
        raise SandboxUnavailable(
            f"the grading sandbox needs Linux (bubblewrap, or root for the uid mode); this is {sys.platform}"
        )
    root = os.geteuid() == 0
    bwrap = shutil.which("bwrap")
    why: list[str] = []
    kinds = [k for k in MODES if choice in ("auto", k) or (choice == "bwrap" and k.startswith("bwrap"))]
    if any(k.startswith("bwrap") for k in kinds) and bwrap is None:
        why.append("bubblewrap (bwrap) is not installed: apt-get install bubblewrap")
    for kind in kinds:
        if kind.startswith("bwrap") and bwrap is None:
            continue
        if kind in ("bwrap-uid", "uid") and not root:
            if kind == "uid":
                why.append("the uid mode needs the grader to run as root (as on Gradescope)")
            continue
        sb = Sandbox(kind, bwrap if kind.startswith("bwrap") else None)
        problem = _probe(sb)
        if problem is None:
            return sb
        why.append(f"{kind}: {problem}" + (" (namespaces forbidden here?)" if sb.bubblewrap else ""))
    raise SandboxUnavailable("; ".join(why) + "; check with lab grade --check-sandbox")
