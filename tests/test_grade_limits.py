"""Bounded resources, a smaller kernel surface and clean output (issue 48): one test per class of attack,
each a submission written against the released stereo template that tries it.

Each is graded the documented way (``lab grade ... --json``) in a separate grader process, in each
isolation mode, and must score no more than the untouched template (0) while the grader stays well:
its peak resident memory (``VmHWM``) under 500 MB, ``results.json`` under 1 MB, no control character
in what it prints, exit code 0. Where the attack is about the kernel, the same submission graded
without the sandbox (``Sandbox("none")``) shows that the calls it tries do work on this machine, so
it is the seccomp filter that stops them.
"""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.grading import get_assignment, grade_submission, seccomp
from lab.grading.isolation import Sandbox
from lab.grading.limits import RESULTS_MAX_BYTES, clean, fit_results
from lab.grading.release import release
from lab.grading.sandbox import MAX_MESSAGE_BYTES, WireError, decode

STEREO = get_assignment("stereo")
GRADER_RSS_MB = 500
CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff]")

# the grader as `lab grade` runs it, in a process of its own: its peak memory is its alone. These
# attacks test the sandbox's limits, so the assignment's import rules (tests/test_grade_rules.py), which
# would refuse their `import os` before they reach those limits, are narrowed to refusing `lab`.
GRADER = """
import sys
import lab.grading.runner
lab.grading.runner.child_rules = lambda a: {"assignment": a.name, "imports": None, "oracles": ["lab"]}
from lab.cli import main
rc = main(["grade", sys.argv[1], sys.argv[2], "--json", sys.argv[3]])
hwm = next(line for line in open("/proc/self/status") if line.startswith("VmHWM:"))
sys.stderr.write("\\nLAB-HWM-KB " + hwm.split()[1] + "\\n")
sys.exit(rc)
"""


@pytest.fixture(autouse=True)
def no_import_rules(monkeypatch):
    """As in ``GRADER``: the import rules narrowed to ``lab``, so the attacks reach the limits."""
    narrowed = {"imports": None, "oracles": ["lab"]}
    monkeypatch.setattr("lab.grading.runner.child_rules", lambda a: {"assignment": a.name, **narrowed})


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """The released stereo.py (solutions stripped), as students receive it."""
    out = tmp_path_factory.mktemp("release")
    release([STEREO], out)
    return (out / "stereo" / "stereo.py").read_text()


def _submission(tmp_path, template, attack: str):
    d = tmp_path / "student"
    d.mkdir()
    (d / "stereo.py").write_text(template + "\n\n# ---- the attack\n" + attack)
    return d


def _grade(tmp_path, sub) -> tuple[dict, str]:
    """Grade ``sub`` with ``lab grade`` in a fresh process; check what every attack must leave intact
    and return results.json and the terminal output."""
    results = tmp_path / "results.json"
    r = subprocess.run(
        [sys.executable, "-c", GRADER, "stereo", str(sub), str(results)],
        capture_output=True,
        timeout=600,
        cwd=tmp_path,
    )
    out = r.stdout.decode("utf-8")  # strict: a lone surrogate could not have been printed
    assert r.returncode == 0, r.stderr.decode(errors="replace")[-2000:]
    hwm_mb = int(r.stderr.decode().rsplit("LAB-HWM-KB ", 1)[1].split()[0]) / 1024
    assert hwm_mb < GRADER_RSS_MB, f"the grader's peak memory was {hwm_mb:.0f} MB"
    assert results.stat().st_size < RESULTS_MAX_BYTES
    assert CONTROL.search(out) is None, repr(CONTROL.search(out))
    data = json.loads(results.read_text())
    assert data["score"] <= 0, out  # the untouched template scores 0
    assert all("GRADER ERROR" not in t["output"] for t in data["tests"]), out
    return data, out


def _printed(data) -> str:
    return "\n".join(t["output"] for t in data["tests"])


# ---- a smaller kernel surface: what a user namespace would open up, and the calls themselves
KERNEL = (
    """
import ctypes, os
_libc = ctypes.CDLL(None, use_errno=True)
def _try(name, fn):
    try:
        r = fn()
        if isinstance(r, int) and r < 0:
            raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()))
        print("ALLOWED", name)
        return r
    except Exception as e:
        print("refused", name, type(e).__name__)
_try("unshare-user", lambda: _libc.unshare(0x10000000))
_try("unshare-ipc", lambda: _libc.unshare(0x08000000))
_seg = _try("shmget", lambda: _libc.shmget(0, 1 << 20, 0o1600))
if _seg is not None:
    _libc.shmctl(_seg, 0, None)  # IPC_RMID: leave nothing behind where it was allowed
_try("io_uring_setup", lambda: _libc.syscall(NR_IO_URING, 1, ctypes.create_string_buffer(120)))
_try("userfaultfd", lambda: _libc.syscall(NR_USERFAULTFD, 0))
_try("memfd_create", lambda: os.memfd_create("x"))
_try("bpf", lambda: _libc.syscall(NR_BPF, 0, None, 0))
""".replace("NR_IO_URING", str(seccomp.number("io_uring_setup")))
    .replace("NR_USERFAULTFD", str(seccomp.number("userfaultfd")))
    .replace("NR_BPF", str(seccomp.number("bpf")))
)
KERNEL_CALLS = (
    "unshare-user",
    "unshare-ipc",
    "shmget",
    "io_uring_setup",
    "userfaultfd",
    "memfd_create",
    "bpf",
)


def test_the_kernel_surface_is_refused(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template, KERNEL)
    data, _ = _grade(tmp_path, sub)
    printed = _printed(data)
    for name in KERNEL_CALLS:
        assert f"refused {name}" in printed, printed
    assert "ALLOWED" not in printed, printed
    # the same calls work on this machine without the sandbox: the filter is what refuses them
    bare = grade_submission(STEREO, sub, sandbox=Sandbox("none"))
    allowed = _printed_report(bare)
    for name in ("unshare-ipc", "shmget", "memfd_create"):
        assert f"ALLOWED {name}" in allowed, allowed


def _printed_report(report) -> str:
    return "\n".join(r.output for r in report.tests)


# ---- memory outside the memory limit: shared memory, tmpfs files, folders, links, attributes
MEMORY = """
import ctypes, mmap, os
_libc = ctypes.CDLL(None, use_errno=True)
_got = {"shm": 0, "posix": 0, "memfd": 0, "entries": 0, "xattrs": 0}
for _ in range(4):  # System V: 64 MB segments, touched
    seg = _libc.shmget(0, 64 << 20, 0o1600)
    if seg < 0:
        break
    _got["shm"] += 64 << 20
    _libc.shmctl(seg, 0, None)
for base in ("/dev/shm", "/tmp"):  # POSIX shared memory and tmpfs: files, folders, links
    for i in range(200):
        for make in (lambda p: open(p, "w").close(), os.mkdir, lambda p: os.symlink("/" * 100, p)):
            try:
                make(f"{base}/lab-fill-{os.getpid()}-{i}-{make.__name__}")
                _got["entries"] += 1
            except OSError:
                pass
try:
    _fd = os.memfd_create("fill"); os.ftruncate(_fd, 64 << 20); _got["memfd"] += 64 << 20
except OSError:
    pass
for target in (".", "/tmp"):
    try:
        os.setxattr(target, "user.fill", b"x" * 60000); _got["xattrs"] += 1
    except OSError:
        pass
print("GOT", sorted(_got.items()))
"""


def test_shared_memory_and_tmpfs_cannot_be_filled(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template, MEMORY)
    data, _ = _grade(tmp_path, sub)
    printed = _printed(data)
    nothing = str(sorted({"shm": 0, "posix": 0, "memfd": 0, "entries": 0, "xattrs": 0}.items()))
    assert f"GOT {nothing}" in printed, printed


# ---- an answer far larger than any test needs: the grader reads its header and stops
HUGE = """
import os, struct, sys
def triangulate(*args, **kwargs):  # a raw frame claiming 250 MB, then the data
    fd = int(sys.argv[2])
    os.write(fd, struct.pack(">I", 250 << 20))
    chunk = b"A" * (1 << 20)
    for _ in range(250):
        os.write(fd, chunk)
def project(*args, **kwargs):  # 4 MB of empty lists: small on the wire, large once decoded
    body = b'{"ok":true,"value":[' + b"[]," * 1_300_000 + b'[]],"notes":[]}'
    os.write(int(sys.argv[2]), struct.pack(">I", len(body)) + body)
    import time; time.sleep(30)
def depth_std(Z, *args, **kwargs):  # an honest 8 MB array: the child refuses to send it
    import numpy as np
    return np.zeros(1_000_000)
"""


def test_a_huge_answer_does_not_grow_the_grader(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template, HUGE)
    data, _ = _grade(tmp_path, sub)
    printed = _printed(data)
    assert "answer too large" in printed and "more than 200000 lists" in printed, printed
    assert "too large to send" in printed, printed


# ---- output: ANSI escapes, carriage returns and a lone surrogate, in messages and in prints
FAKE_TABLE = "\\x1b[2J\\x1b[H\\r  PASS 6/6 everything\\x1b[8m"
OUTPUT = f"""
import json, os, struct, sys
print("{FAKE_TABLE}")
def triangulate(*args, **kwargs):
    raise ValueError("{FAKE_TABLE}\\ud800 " + "x" * 5000)
def project(*args, **kwargs):  # a raw answer: escapes and a lone surrogate in every field
    body = json.dumps({{"ok": False, "error": {{"type": "\\x1b[32mPASS", "message": "\\ud800" * 3000,
        "where": [{{"line": 1, "function": "\\x1b]0;owned\\x07", "code": "\\r" * 900}}]}}, "notes": []}})
    os.write(int(sys.argv[2]), struct.pack(">I", len(body)) + body.encode())
    import time; time.sleep(30)
def depth_std(Z, *args, **kwargs):  # a long answer a graded test may quote
    return ["\\x1b[1m" * 100] * 2000
"""


def test_control_characters_and_surrogates_are_escaped(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template, OUTPUT)
    data, out = _grade(tmp_path, sub)
    text = json.dumps(data, ensure_ascii=False)
    assert CONTROL.search(text) is None  # json.loads would have turned "\u001b" back into ESC
    assert "\\x1b[2J" in _printed(data) and "\\ud800" in _printed(data)  # shown, escaped, not hidden


# ---- numbers and frames the grader cannot use: the student's failed test, never a grader error
MALFORMED = """
import os, struct, sys
def _raw(body):
    os.write(int(sys.argv[2]), struct.pack(">I", len(body)) + body)
    import time; time.sleep(30)
def triangulate(*args, **kwargs):
    _raw(b'{"ok":true,"value":' + b"9" * 400 + b"}")
def project(*args, **kwargs):
    _raw(b'{"ok":false,"error":{"type":["x"],"message":7,"where":[1,"x",{"line":"a"}]},"notes":[]}')
def depth_std(Z, *args, **kwargs):
    return 10 ** 400
"""


def test_an_oversized_integer_or_a_malformed_frame_fails_the_students_test(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template, MALFORMED)
    data, _ = _grade(tmp_path, sub)
    printed = _printed(data)
    assert "an integer of 400 digits" in printed, printed
    assert "cannot send an integer of more than 20 digits" in printed, printed
    assert "project raised Exception" in printed, printed  # the malformed error, reduced to what it can say


# ---- the pieces, against hand-made values
def test_clean_escapes_controls_and_surrogates_and_keeps_text():
    assert clean("a\x1b[31mb\r\n\tc\ud800é中\u202e") == "a\\x1b[31mb\\x0d\n\tc\\ud800é中\\u202e"
    cut = clean("x" * 100, 10)
    assert cut == "x" * 10 + " ... [100 characters, cut to 10]"
    assert clean("\x1b" * 10, 12) == "\\x1b\\x1b\\x1b" + " ... [10 characters, cut to 12]"


def test_results_fit_under_their_limit():
    data = {"output": "", "tests": [{"output": "\x1b" * 400_000, "extra_data": {}} for _ in range(20)]}
    data["tests"] = [dict(t, output=clean(t["output"], 8000)) for t in data["tests"]]
    assert len(fit_results(data).encode()) < RESULTS_MAX_BYTES
    small = {"output": "ok", "tests": [{"output": "fine", "extra_data": {}}]}
    assert json.loads(fit_results(small)) == small  # nothing cut when it fits


def test_decode_refuses_long_integers_and_container_bombs_but_not_arrays():
    with pytest.raises(WireError, match="400 digits"):
        decode(b"[" + b"1" * 400 + b"]")
    with pytest.raises(WireError, match="lists and dicts"):
        decode(b"[" + b"[]," * 300_000 + b"[]]")
    assert decode(b"[-9223372036854775808, 1.5]") == [-(2**63), 1.5]
    from lab.grading.sandbox import encode

    a = np.arange(100_000, dtype=float)  # 800 kB: well under the frame limit
    assert len(encode(a)) < MAX_MESSAGE_BYTES and np.array_equal(decode(encode(a)), a)


# ---- the seccomp filter, read by a small classic-BPF interpreter, against the kernel's own headers
def _run_bpf(prog: bytes, nr: int, arch: int, args=(0, 0, 0, 0, 0, 0)) -> int:
    """What the filter returns for one system call (the cBPF subset it uses: ld abs, jeq, jge, jset, ret)."""
    import struct

    insns = [struct.unpack("=HBBI", prog[i : i + 8]) for i in range(0, len(prog), 8)]
    data = struct.pack("<iIQ6Q", nr, arch, 0, *args)
    pc, acc = 0, 0
    while True:
        code, jt, jf, k = insns[pc]
        if code == 0x20:
            acc = struct.unpack_from("<I", data, k)[0]
        elif code in (0x15, 0x35, 0x45):
            hit = {0x15: acc == k, 0x35: acc >= k, 0x45: bool(acc & k)}[code]
            pc += jt if hit else jf
        elif code == 0x06:
            return k
        else:
            raise AssertionError(f"unknown instruction {code:#x}")
        pc += 1


def _header_numbers(path: str, prefix: str) -> dict[str, int]:
    import os

    if not os.path.exists(path):
        pytest.skip(f"no {path} on this machine (linux-libc-dev)")
    found = {}
    for line in open(path):
        parts = line.split()
        if len(parts) >= 3 and parts[0] == "#define" and parts[1].startswith(prefix) and parts[2].isdigit():
            found[parts[1][len(prefix) :]] = int(parts[2])
    return found


@pytest.mark.parametrize(
    "machine, arch, header",
    [
        ("x86_64", 0xC000003E, "/usr/include/x86_64-linux-gnu/asm/unistd_64.h"),
        ("aarch64", 0xC00000B7, "/usr/include/asm-generic/unistd.h"),
    ],
)
def test_the_filter_refuses_by_the_kernels_numbers(monkeypatch, machine, arch, header):
    import platform

    monkeypatch.setattr(platform, "machine", lambda: machine)
    seccomp.program.cache_clear()
    try:
        prog = seccomp.program()
    finally:
        seccomp.program.cache_clear()
    numbers = _header_numbers(header, "__NR_")
    allow, errno = 0x7FFF0000, 0x00050000
    checked = 0
    for name in seccomp.REFUSED_NAMES:
        if name not in numbers or " " in name:
            continue  # newer than the headers here, or one of the flag checks below
        got = _run_bpf(prog, numbers[name], arch)
        assert got & 0xFFFF0000 == errno and got & 0xFFFF in (1, 30, 38), (name, hex(got))
        checked += 1
    assert checked > 60
    for name in ("read", "write", "mmap", "munmap", "futex", "exit_group", "getpid"):
        if name in numbers:
            assert _run_bpf(prog, numbers[name], arch) == allow, name
    clone, openat = numbers["clone"], numbers["openat"]
    assert _run_bpf(prog, clone, arch, (0x3D0F00, 0, 0, 0, 0, 0)) == allow  # a thread's flags
    assert _run_bpf(prog, clone, arch, (0x10000000 | 17, 0, 0, 0, 0, 0)) == errno | 1  # CLONE_NEWUSER
    assert _run_bpf(prog, openat, arch, (0, 0, 0o2000000, 0, 0, 0)) == allow  # O_RDONLY | O_CLOEXEC
    assert _run_bpf(prog, openat, arch, (0, 0, 0o101, 0, 0, 0)) == errno | 30  # O_WRONLY | O_CREAT
    assert _run_bpf(prog, numbers["clone3"], arch) == errno | 38  # ENOSYS: the C library falls back
    assert _run_bpf(prog, numbers["read"], 0x40000003) == 0x80000000  # i386's entry: killed
    if machine == "x86_64":
        assert _run_bpf(prog, 0x40000000 | numbers["read"], arch) == 0x80000000  # the x32 ABI: killed


def test_check_sandbox_reports_the_new_limits(capsys, grading_mode):
    from lab.cli import main

    assert main(["grade", "--check-sandbox"]) == 0
    out = capsys.readouterr().out
    for line in (
        "ok  seccomp filter on (Seccomp: 2)",
        "ok  no user namespaces",
        "ok  memory limit covers shared memory",
        "ok  /tmp size: ",
        "ok  make a user namespace (unshare CLONE_NEWUSER): stopped",
        "ok  io_uring (io_uring_setup): stopped",
    ):
        assert line in out, out
    if grading_mode == "bwrap":
        assert "ok  /tmp size: private, 16 MB cap" in out
