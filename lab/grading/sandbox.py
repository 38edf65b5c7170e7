"""The child process that runs a student's code, and the wire format it answers in.

The grader never imports a submission. For every graded test it starts this file as a fresh Python
process (``python -I sandbox.py ...``) which

1. becomes the throwaway uid it is given, when the grader runs it as root (inside the bubblewrap
   sandbox of :mod:`lab.grading.isolation`, which gives it a filesystem holding only the system,
   Python and the copy of the submission, and no network; or, in the ``uid`` mode where namespaces
   are forbidden, on the grader's filesystem with the grader's folders private);
2. lowers its own resource limits (address space, CPU time, file size, open files, processes),
   before any student code runs;
3. imports the submitted module from its private folder (``lab`` itself cannot be imported: the
   assignments are to be written, not borrowed; in the sandbox it is not even there);
4. notes what the student's code tried that the sandbox forbids (files outside the submission,
   network connections, new processes, ``import lab``) with an audit hook, and sends the notes with
   each answer for the feedback (they never change a score: the sandbox, not the hook, stops them);
5. answers *calls*: the grading process sends ``{"call": name, "args": [...]}`` and gets back the
   function's return value, or a description of the exception it raised.

Requests and answers travel over two pipes that the grader opened for this process only (their file
descriptors are passed on the command line), never over stdout: whatever the student's code prints,
including text that looks like JSON results, is captured as plain text for the feedback and never
parsed. Nothing the child sends is a score: it can only send the values the student's functions
return, and the grading process judges those. A child that lies on the channel lies about its own
return values, which is what it is being graded on.

Wire format: each message is a 4-byte big-endian length and a UTF-8 JSON document. NumPy arrays are
``{"__ndarray__": base64, "dtype": "<f8", "shape": [...]}``; only boolean, integer, float and complex
arrays are accepted when decoding, never objects, and decoding never calls ``pickle``.

This module imports only the standard library and NumPy, so the child starts in ~0.1 s.
"""

from __future__ import annotations

import base64
import json
import math
import os
import struct
import sys

__all__ = [
    "encode",
    "decode",
    "read_message",
    "write_message",
    "install_seccomp",
    "MAX_MESSAGE_BYTES",
    "WireError",
]

MAX_MESSAGE_BYTES = 4 << 20  # one frame: far above any answer a graded test needs (a few KB)
_MAX_DEPTH = 32
_MAX_CONTAINERS = 200_000  # lists and dicts in one frame: what decoding may build stays bounded
_MAX_INT_DIGITS = 20  # an int64 has 19 digits; 400 digits is not a number a graded test can use
_ARRAY_KINDS = "biufc"  # bool, int, uint, float, complex: no objects, strings or structured dtypes
_HEADER = struct.Struct(">I")


class WireError(ValueError):
    """A message could not be encoded or decoded (wrong type, too large, malformed)."""


# ---------------------------------------------------------------------------------------------- codec
def _to_wire(x, depth: int = 0):
    import numpy as np

    if depth > _MAX_DEPTH:
        raise WireError(f"the value is nested more than {_MAX_DEPTH} levels deep")
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, int):
        if abs(x) >= 10**_MAX_INT_DIGITS:
            raise WireError(f"cannot send an integer of more than {_MAX_INT_DIGITS} digits")
        return x
    if isinstance(x, float):
        return x
    if isinstance(x, np.generic):
        if x.dtype.kind not in _ARRAY_KINDS:
            raise WireError(f"cannot send a NumPy scalar of dtype {x.dtype}")
        return _to_wire(np.asarray(x).reshape(()), depth + 1) if x.dtype.kind == "c" else x.item()
    if isinstance(x, np.ndarray):
        if x.dtype.kind not in _ARRAY_KINDS or x.dtype.fields is not None:
            raise WireError(
                f"cannot send a NumPy array of dtype {x.dtype} (only bool, integer, float or complex arrays)"
            )
        a = np.asarray(x, order="C")  # keeps 0-d arrays 0-d (ascontiguousarray would not)
        return {
            "__ndarray__": base64.b64encode(a.tobytes()).decode("ascii"),
            "dtype": a.dtype.str,
            "shape": list(a.shape),
        }
    if isinstance(x, complex):
        return _to_wire(np.asarray(x), depth + 1)
    if isinstance(x, (list, tuple)):
        return [_to_wire(v, depth + 1) for v in x]
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            if not isinstance(k, str) or k.startswith("__nd"):
                raise WireError(f"cannot send a dict with the key {k!r} (keys must be plain strings)")
            out[k] = _to_wire(v, depth + 1)
        return out
    raise WireError(
        f"cannot send a value of type {type(x).__name__} (return numbers, lists, tuples or NumPy arrays)"
    )


def _from_wire_hook(d: dict):
    if "__ndarray__" not in d:
        return d
    import numpy as np

    if set(d) != {"__ndarray__", "dtype", "shape"}:
        raise WireError("malformed array message")
    dt = np.dtype(str(d["dtype"]))
    if dt.kind not in _ARRAY_KINDS or dt.fields is not None or dt.hasobject:
        raise WireError(f"refusing an array of dtype {dt}")
    shape = d["shape"]
    if not (isinstance(shape, list) and len(shape) <= 32 and all(type(s) is int and s >= 0 for s in shape)):
        raise WireError("malformed array shape")
    raw = base64.b64decode(d["__ndarray__"], validate=True)
    if math.prod(shape) * dt.itemsize != len(raw):
        raise WireError("array data does not match its shape and dtype")
    return np.frombuffer(raw, dtype=dt).reshape(shape).copy()


def encode(obj) -> bytes:
    """Serialise ``obj`` (None, bool, int, float, str, lists, tuples, str-keyed dicts, NumPy arrays)."""
    try:
        data = json.dumps(_to_wire(obj), allow_nan=True, separators=(",", ":")).encode("utf-8")
    except (TypeError, ValueError, RecursionError) as e:
        raise WireError(str(e)) from None
    if len(data) > MAX_MESSAGE_BYTES:
        raise WireError(
            f"the value is too large to send ({len(data) >> 20} MB > {MAX_MESSAGE_BYTES >> 20} MB)"
        )
    return data


def decode(data: bytes):
    """Inverse of :func:`encode`. Safe on untrusted bytes: raises :class:`WireError`, never runs code,
    and builds at most a bounded number of lists and dicts and no integer too long for a graded test."""
    if data.count(b"[") + data.count(b"{") > _MAX_CONTAINERS:
        raise WireError(f"malformed message: more than {_MAX_CONTAINERS} lists and dicts")
    try:
        return json.loads(data.decode("utf-8"), object_hook=_from_wire_hook, parse_int=_parse_int)
    except WireError:
        raise
    except (ValueError, TypeError, RecursionError, OverflowError, MemoryError) as e:
        raise WireError(f"malformed message: {type(e).__name__}: {str(e)[:200]}") from None


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > _MAX_INT_DIGITS:
        raise WireError(f"an integer of {len(text.lstrip('-'))} digits (at most {_MAX_INT_DIGITS})")
    return int(text)


def write_message(fd: int, obj) -> None:
    """Blocking write of one framed message (used by the child; the grader writes with a deadline)."""
    data = encode(obj)
    view = memoryview(_HEADER.pack(len(data)) + data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exactly(fd: int, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        b = os.read(fd, min(n - got, 1 << 20))
        if not b:
            raise EOFError("the channel was closed")
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def read_message(fd: int):
    """Blocking read of one framed message (used by the child)."""
    (n,) = _HEADER.unpack(_read_exactly(fd, _HEADER.size))
    if n > MAX_MESSAGE_BYTES:
        raise WireError("message too large")
    return decode(_read_exactly(fd, n))


# ---------------------------------------------------------------------------------------------- child
def _drop_to(uid: int) -> None:
    """Become ``uid`` (and gid ``uid``, no supplementary groups) for good; fail loudly otherwise."""
    os.setgroups([])
    os.setgid(uid)
    os.setuid(uid)
    if os.getuid() != uid or os.geteuid() != uid or os.getgid() != uid or os.getgroups():
        raise SystemExit(f"sandbox: could not become uid {uid}")
    try:
        os.setuid(0)
    except PermissionError:
        return
    raise SystemExit("sandbox: root could be regained after dropping it")


def _apply_limits(memory_mb: int, cpu_s: int) -> None:
    import resource
    import signal

    def lower(which, value):
        soft, hard = resource.getrlimit(which)
        if hard != resource.RLIM_INFINITY:
            value = min(value, hard)
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError):
            pass

    lower(resource.RLIMIT_AS, memory_mb << 20)  # MemoryError instead of swapping the machine
    lower(resource.RLIMIT_CPU, cpu_s)  # backstop; the grader's wall-clock timeout comes first
    lower(resource.RLIMIT_FSIZE, 0)  # no writing into files (the results file included)
    lower(resource.RLIMIT_CORE, 0)
    lower(resource.RLIMIT_NOFILE, 128)  # open files (the pipes to the grader are already open)
    if hasattr(resource, "RLIMIT_NPROC"):
        lower(resource.RLIMIT_NPROC, 0)  # no new processes or threads (not enforced for root)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write then fails with OSError(EFBIG) instead


def install_seccomp() -> None:
    """Install the grader's seccomp filter (:mod:`lab.grading.seccomp`) when it is handed over in
    ``$LAB_SECCOMP_FD`` (the uid mode; bubblewrap installs it itself before this process starts):
    ``no_new_privs``, then ``prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER)``. Fails loudly: a child that
    cannot confine itself must not run the student's code."""
    fd = os.environ.pop("LAB_SECCOMP_FD", None)
    if fd is None:
        return
    import ctypes

    data = b""
    while chunk := os.read(int(fd), 1 << 16):
        data += chunk
    os.close(int(fd))

    class SockFprog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_char_p)]

    buf = ctypes.create_string_buffer(data, len(data))
    prog = SockFprog(len(data) // 8, ctypes.cast(buf, ctypes.c_char_p))
    libc = ctypes.CDLL(None, use_errno=True)
    ul = ctypes.c_ulong
    set_nnp = libc.prctl(38, ul(1), ul(0), ul(0), ul(0))  # PR_SET_NO_NEW_PRIVS
    if set_nnp != 0 or libc.prctl(22, ul(2), ctypes.byref(prog), ul(0), ul(0)) != 0:  # PR_SET_SECCOMP
        raise SystemExit(f"sandbox: could not install the seccomp filter ({os.strerror(ctypes.get_errno())})")


class _NoLab:
    """Meta-path finder that refuses ``import lab``: the assignment is to write it, not import it."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname == "lab" or fullname.startswith("lab."):
            raise ImportError(
                f"importing {fullname!r} is not allowed in a submission: write the function yourself "
                "(NumPy, SciPy and the standard library are available)"
            )
        return None


_MAX_NOTES = 8
_notes: list[str] = []


def _note(text: str) -> None:
    if text not in _notes and len(_notes) < _MAX_NOTES:
        _notes.append(text)


def _watch(allowed: tuple[str, ...]):
    """An audit hook noting what the sandbox forbids (it observes; the sandbox refuses)."""
    procs = {
        "os.fork",
        "os.forkpty",
        "os.posix_spawn",
        "os.exec",
        "os.spawn",
        "os.system",
        "subprocess.Popen",
    }

    def hook(event: str, args: tuple) -> None:
        if event == "open":
            path = args[0]
            if isinstance(path, (str, bytes)):
                p = os.path.normpath(os.path.join(os.getcwd(), os.fsdecode(path)))
                if "/__pycache__/" in p:  # the import system looking for a cached module: not the student
                    return
                if not any(p == a or p.startswith(a + "/") for a in allowed):
                    _note(f"open {p}: outside the submission")
                elif p.startswith("/tmp/") and not os.path.exists(os.path.dirname(p)):
                    _note(f"open {p}: not in the sandbox (its /tmp is its own)")
        elif event in ("socket.connect", "socket.sendto", "socket.sendmsg"):
            _note(f"a network connection to {args[1]!r}: no network while grading")
        elif event in procs:
            _note(f"starting a process ({event}): not allowed while grading")
        elif event == "import" and args[0].split(".")[0] == "lab":
            _note("import lab: the course library is not available to a submission")

    return hook


def _describe(exc: BaseException, module_file: str) -> dict:
    """Type, message and the innermost frame of the submission's own file where it was raised."""
    import linecache
    import traceback

    frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename == module_file]
    where = [
        {
            "line": f.lineno,
            "function": f.name,
            "code": (f.line or linecache.getline(f.filename, f.lineno)).strip(),
        }
        for f in frames[-4:]
    ]
    msg = str(exc)
    if len(msg) > 600:
        msg = msg[:600] + " ..."
    return {
        "type": type(exc).__name__,
        "message": msg,
        "where": where,
        "memory": isinstance(exc, MemoryError),
    }


def _serve(req_fd: int, resp_fd: int, module_path: str) -> int:
    import importlib.util

    sys.meta_path.insert(0, _NoLab())
    name = os.path.splitext(os.path.basename(module_path))[0]
    allowed = {os.path.dirname(module_path), "/tmp", "/dev/null", "/dev/urandom", "/proc/self", "/sys"}
    allowed |= {"/proc/cpuinfo", "/proc/meminfo", "/usr", "/etc/ld.so.cache", "/proc/" + str(os.getpid())}
    allowed |= {os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix) if p}
    allowed |= {p for p in (sys.prefix, sys.base_prefix, sys.exec_prefix) if p}
    try:
        import numpy  # noqa: F401  (before the student's code, so its import time is not theirs)

        sys.addaudithook(_watch(tuple(sorted(allowed))))
        spec = importlib.util.spec_from_file_location(name, module_path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    except BaseException as e:  # noqa: BLE001 - SystemExit and KeyboardInterrupt at import too
        write_message(resp_fd, {"ready": False, "error": _describe(e, module_path), "notes": _notes})
        return 0
    functions = sorted(k for k, v in vars(module).items() if callable(v) and not k.startswith("_"))
    write_message(resp_fd, {"ready": True, "functions": functions, "notes": _notes})
    while True:
        try:
            req = read_message(req_fd)
        except EOFError:
            return 0
        if req.get("op") == "bye":
            return 0
        fn = getattr(module, req["call"], None)
        try:
            if not callable(fn):
                raise AttributeError(f"{name}.py does not define a function {req['call']}")
            value = fn(*req.get("args", []), **req.get("kwargs", {}))
        except BaseException as e:  # noqa: BLE001 - report everything, including sys.exit()
            answer = {"ok": False, "error": _describe(e, module_path)}
        else:
            try:
                answer = {"ok": True, "value": value}
                encode(answer)
            except WireError as e:
                answer = {
                    "ok": False,
                    "error": {"type": "UnsendableResult", "message": str(e), "where": [], "memory": False},
                }
        answer["notes"] = _notes
        write_message(resp_fd, answer)


def main(argv: list[str]) -> int:
    """``sandbox.py REQ_FD RESP_FD MODULE_PATH MEMORY_MB CPU_S [UID]`` (UID: become it first)."""
    req_fd, resp_fd = int(argv[0]), int(argv[1])
    module_path, memory_mb, cpu_s = argv[2], int(argv[3]), int(argv[4])
    if len(argv) > 5 and int(argv[5]) >= 0:
        _drop_to(int(argv[5]))
    _apply_limits(memory_mb, cpu_s)
    install_seccomp()
    sys.dont_write_bytecode = True
    return _serve(req_fd, resp_fd, module_path)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
