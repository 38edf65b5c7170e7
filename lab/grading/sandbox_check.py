"""``lab grade --check-sandbox``: a real sandboxed child tries, from inside, what a cheating submission
would, and each attempt is reported.

The child runs in the machine's isolation mode (:func:`lab.grading.isolation.find_sandbox`) under the
same seccomp filter as a graded child (:mod:`lab.grading.seccomp`). It tries to read the grader's
files, write the results file, see and signal the grader, open a connection, become root, and, for the
kernel surface and the memory limit, to make a user namespace, System V and POSIX shared memory, a
``memfd``, an io_uring, a ``userfaultfd``, and files, folders and extended attributes in ``/tmp``.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
from pathlib import Path

from lab.grading import seccomp
from lab.grading.isolation import (
    SHM_BYTES,
    TMP_BYTES,
    Sandbox,
    SandboxUnavailable,
    end_all,
    find_sandbox,
    make_grader_private,
    make_undumpable,
    private_workdir,
    run_confined,
    secret_folders,
)

__all__ = ["check_sandbox"]

_CHECKS = r"""
import ctypes, json, os, socket, sys
uid = int(sys.argv[1])
secrets, grader_pid, results, token = json.loads(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
numbers = json.loads(sys.argv[7])
if os.environ.get("LAB_SECCOMP_FD"):  # the uid mode: the child installs the filter, as a graded child does
    import importlib.util
    spec = importlib.util.spec_from_file_location("lab_sandbox_entry", sys.argv[6])
    entry = importlib.util.module_from_spec(spec); spec.loader.exec_module(entry)
if uid >= 0:
    os.setgroups([]); os.setgid(uid); os.setuid(uid)
if os.environ.get("LAB_SECCOMP_FD"):
    entry.install_seccomp()
out = {}
def attempt(name, fn):
    try:
        fn()
        out[name] = "NOT stopped"
    except Exception as e:
        out[name] = f"stopped ({type(e).__name__}: {e})"
for s in secrets:
    attempt(f"read {s}", lambda s=s: os.listdir(s) if os.path.isdir(s) else open(s).read())
def write_results():
    with open(results, "a") as f:
        f.write(token)
attempt(f"write {results}", write_results)
attempt(f"see the grader (pid {grader_pid}) in /proc", lambda: open(f"/proc/{grader_pid}/status").read())
attempt(f"signal the grader (pid {grader_pid})", lambda: os.kill(grader_pid, 0))
def net():
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM); s.settimeout(2)
    s.connect(("1.1.1.1", 53))
attempt("open a network connection (1.1.1.1:53)", net)
attempt("become root (setuid 0)", lambda: os.setuid(0))
attempt("write outside /tmp (/usr)", lambda: open("/usr/lab-sandbox-check", "w").close())
libc = ctypes.CDLL(None, use_errno=True)
def call(fn, *args):
    if fn(*args) < 0:
        e = ctypes.get_errno(); raise OSError(e, os.strerror(e))
made = []
def create(path, fn):
    fn(path); made.append(path)
tag = f"lab-check-{token}"
attempt("make a user namespace (unshare CLONE_NEWUSER)", lambda: call(libc.unshare, 0x10000000))
attempt("System V shared memory (shmget)", lambda: call(libc.shmget, 0, 1 << 20, 0o1600))
def new_file(p):
    open(p, "w").close()
attempt("POSIX shared memory (a file in /dev/shm)", lambda: create(f"/dev/shm/{tag}", new_file))
attempt("memory outside the limit (memfd_create)", lambda: os.close(os.memfd_create("lab-check")))
params = ctypes.create_string_buffer(120)
attempt("io_uring (io_uring_setup)", lambda: call(libc.syscall, numbers["io_uring_setup"], 1, params))
attempt("userfaultfd", lambda: call(libc.syscall, numbers["userfaultfd"], 0))
attempt("a file in /tmp", lambda: create(f"/tmp/{tag}", new_file))
attempt("a folder in /tmp (mkdir)", lambda: create(f"/tmp/{tag}.d", os.mkdir))
attempt("a link in /tmp (symlink)", lambda: create(f"/tmp/{tag}.l", lambda p: os.symlink("/", p)))
attempt("an extended attribute (setxattr)", lambda: os.setxattr(".", "user.lab", b"1"))
for p in made:  # what was not stopped is not left behind
    try:
        os.rmdir(p) if os.path.isdir(p) and not os.path.islink(p) else os.unlink(p)
    except OSError:
        pass
st = os.statvfs("/tmp")
out["tmp_bytes"] = st.f_blocks * st.f_frsize
out["seccomp"] = next((ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("Seccomp:")), "?")
out["uid"] = os.getuid()
sys.stdout.write(json.dumps(out))
"""
_SHM = ("shmget", "/dev/shm", "memfd_create")


def check_sandbox(results_path: str | Path | None = None) -> tuple[bool, list[str]]:
    """Start a real sandboxed child and try, from inside, what a cheating submission would.

    Returns ``(ok, lines)``: ``ok`` is True when a sandbox works and stops every attempt it can;
    what the mode cannot stop is a ``WARNING`` line (with the platform setting that stops it), not a
    failure. The write to the results file is judged by the real file: a write that lands in the
    sandbox's private ``/tmp`` is stopped, from whatever folder this runs.
    """
    lines = []
    undumpable = make_undumpable()
    lines.append(f"{'ok ' if undumpable else 'BAD'} the grader is not dumpable (prctl PR_SET_DUMPABLE 0)")
    try:
        sb = find_sandbox()
    except SandboxUnavailable as e:
        return False, [*lines, f"BAD no sandbox: {e}"]
    lines.append(f"ok  sandbox: {sb.kind}: {sb.describe()}" + (f" ({sb.bwrap})" if sb.bwrap else ""))
    if sb.kind == "uid":  # as lab grade would (not the results' folder: a check changes no folder of yours)
        for p in make_grader_private():
            lines.append(f"ok  made private (chmod go-rwx): {p}")
    results = Path(results_path or Path.cwd() / "results.json").resolve()
    try:
        found, landed = _run_checks(sb, results)
    except ValueError as e:
        return False, [*lines, f"BAD the check did not run: {e}"]
    ok, judged = _judge(sb, found, landed, results)
    return undumpable and ok, lines + judged


def _targets() -> list[str]:
    """The grader's files the check tries to read."""
    from lab.grading.assignments import assignments_dir
    from lab.paths import repo_root

    repo = repo_root().resolve()  # not a target: it holds the venv's folder when the venv is inside it
    targets = [str(p) for p in secret_folders() if p != repo]
    a_dir = assignments_dir()
    for name in ("ekf/ekf.py", "ekf/hidden_tests.py"):
        if (a_dir / name).exists():
            targets.append(str((a_dir / name).resolve()))
    return targets


def _run_checks(sb: Sandbox, results: Path) -> tuple[dict, bool]:
    """Run the checking child; what it found, and whether its write reached the real results file."""
    entry = Path(__file__).with_name("sandbox.py")
    token = secrets.token_hex(8)
    created = _canary(results)
    uid = sb.new_uid()
    d = private_workdir(uid if sb.kind == "uid" else None, "lab-check-")
    numbers = {n: seccomp.number(n) for n in ("io_uring_setup", "userfaultfd")}
    env = dict(os.environ)
    try:
        args = ["-I", "-c", _CHECKS, str(-1 if uid is None else uid), json.dumps(targets := _targets())]
        args += [str(os.getpid()), str(results), token, str(entry), json.dumps(numbers)]
        r = run_confined(sb, sb.command(args, d, entry, uid), d, env)
        if uid is not None and sb.kind == "uid":
            end_all(None, uid)
        try:
            landed = token in results.read_text(errors="replace")
        except OSError:
            landed = False
    finally:
        shutil.rmtree(d, ignore_errors=True)
        if created:
            with contextlib.suppress(OSError):
                results.unlink()
    try:
        found = json.loads(r.stdout)
    except ValueError:
        raise ValueError(r.stderr.strip()[-300:]) from None
    found["uid_expected"], found["targets"] = uid, targets
    return found, landed


def _judge(sb: Sandbox, found: dict, landed: bool, results: Path) -> tuple[bool, list[str]]:
    """The report's lines for what the child found; False when something that should be stopped is not."""
    ok, lines = True, []
    uid, child_uid = found.pop("uid_expected"), found.pop("uid")
    found.pop("targets")
    tmp_bytes, mode = found.pop("tmp_bytes"), found.pop("seccomp")
    if uid is not None:
        ok &= child_uid == uid
        mark = "ok " if child_uid == uid else "BAD"
        lines.append(f"{mark} the student's code runs as uid {child_uid}, not root")
    else:
        lines.append(f"ok  the student's code runs as uid {child_uid} in a user namespace")
    known = {"network": "the network", "/proc": "the process list"}
    for what, res in found.items():
        if what == f"write {results}":
            res = "NOT stopped" if landed else "stopped (the real file is unchanged)"
        good = res.startswith("stopped")
        cannot = any(k in what and any(c.startswith(v) for c in sb.cannot_stop) for k, v in known.items())
        if not good and cannot:
            lines.append(f"WARN {what}: {res} (this mode cannot stop it; see the WARNING below)")
            continue
        ok &= good
        lines.append(f"{'ok ' if good else 'BAD'} {what}: {res}")
    lines += _limit_lines(sb, found, mode, tmp_bytes)
    ok &= all(not ln.startswith("BAD") for ln in lines)
    lines += [f"WARNING {sb.kind} mode cannot stop {c}" for c in sb.cannot_stop]
    return ok, lines


def _limit_lines(sb: Sandbox, found: dict, mode: str, tmp_bytes: int) -> list[str]:
    """The summary lines of the limits: seccomp, user namespaces, memory with shared memory, /tmp."""
    stopped = {what: res.startswith("stopped") for what, res in found.items()}
    refused = len(seccomp.REFUSED_NAMES)
    userns = stopped.get("make a user namespace (unshare CLONE_NEWUSER)", False)
    shm = all(v for w, v in stopped.items() if any(s in w for s in _SHM))
    fill = all(v for w, v in stopped.items() if "/tmp" in w and w.startswith("a "))
    mark = {True: "ok ", False: "BAD"}
    out = [
        f"{mark[mode == '2']} seccomp filter on (Seccomp: {mode}): {refused} kinds of system call refused",
        f"{mark[userns]} no user namespaces: the student's code cannot make one",
        f"{mark[shm]} memory limit covers shared memory: System V, POSIX (/dev/shm) and memfd are refused; "
        "the per-child limit (RLIMIT_AS) counts the rest",
    ]
    if sb.bubblewrap:
        capped = tmp_bytes <= TMP_BYTES
        out.append(
            f"{mark[capped and fill]} /tmp size: private, {tmp_bytes >> 20} MB cap "
            f"(asked {TMP_BYTES >> 20} MB), no new files, folders or links; "
            f"/dev/shm read-only ({SHM_BYTES} bytes)"
        )
    else:
        out.append(
            f"{mark[fill]} /tmp size: the machine's own /tmp ({tmp_bytes >> 20} MB), but no new files, "
            "folders or links (seccomp); see the WARNING below"
        )
    return out


def _canary(results: Path) -> bool:
    """Make the results file (empty, 0600) if it is not there, so that the check's write to it is judged
    by the real file whatever folder it is in; True if this made it (the check removes it again)."""
    try:
        fd = os.open(results, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    except OSError:
        return False
    os.close(fd)
    return True
