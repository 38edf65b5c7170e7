"""The child process that runs a student's code, and the wire format it answers in.

The grader never imports a submission. For every graded test it starts this file as a fresh Python
process (``python -I sandbox.py ...``) which

1. becomes the throwaway uid it is given, when the grader runs it as root (inside the bubblewrap
   sandbox of :mod:`lab.grading.isolation`, which gives it a filesystem holding only the system,
   Python and the copy of the submission, and no network; or, in the ``uid`` mode where namespaces
   are forbidden, on the grader's filesystem with the grader's folders private);
2. lowers its own resource limits (address space, CPU time, file size, open files, processes),
   before any student code runs;
3. puts the assignment's import rules in place (:func:`_rules`: only the modules ``assignment.toml``
   lists; never ``lab`` nor the graded tests' oracles, which are not even there in the sandbox) and
   imports the submitted module from its private folder;
4. notes what the student's code tried that the sandbox forbids (files outside the submission,
   network connections, new processes, refused imports) with an audit hook, each note written the
   moment it happens to a record pipe the grader reads (:mod:`lab.grading.records`): the student's
   code cannot take it back (the notes never change a score: the sandbox, not the hook, stops them);
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
import builtins
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


# ------------------------------------------------------------------------------- records and rules
# importlib's own frames: an import's true author is the first frame outside them
_IMPORTLIB = frozenset(
    {"importlib", "importlib.util", "importlib._bootstrap", "importlib._bootstrap_external"}
    | {"_frozen_importlib", "_frozen_importlib_external"}
)


def _recorder(fd: int):
    """``note(text)`` and ``mark(k)`` on the grader's record pipe ``fd``.

    A note of a refused attempt is written the moment the attempt is made, before the student's code
    goes on, so nothing in this process can take it back; ``mark(k)`` precedes the ``k``-th message on
    the answer channel, so the grader sees a record channel the student's code closed or replaced (its
    marks go missing). Everything used is bound here: replacing ``os.write`` or this module's functions
    later changes nothing."""
    write, text_of = os.write, str

    def note(text: str) -> None:
        line = "N" + " ".join(text_of(text).split())[:300] + "\n"
        try:
            write(fd, line.encode("utf-8", "backslashreplace"))
        except (OSError, ValueError):
            pass  # closed or replaced by the student's code: the grader notices the missing marks

    def mark(k: int) -> None:
        try:
            write(fd, b"M%d\n" % k)
        except OSError:
            pass

    return note, mark


def _rules(rules: dict, module_name: str, student: list, note):
    """``check(fullname, frame)``: raise ImportError (after a note) when the import is refused.

    Allowed: the assignment's ``imports`` and the submission's own module. Refused whoever imports it:
    ``lab``, the graded tests' oracles and (when the assignment lists its imports) every module outside
    the standard library that it does not list. Refused when the student's code imports it: a
    standard-library module the assignment does not list; a library's own import of one (NumPy's) is
    let through. The author is the first frame outside importlib, whose globals must be those of a
    module loaded from the Python installation (or this file), not the submission's module."""
    assignment, imports = rules.get("assignment", "?"), rules.get("imports")
    oracles = frozenset(rules.get("oracles") or ())  # lab among them (lab.grading.rules.oracles)
    allowed = None if imports is None else frozenset(imports) | {module_name}
    import inspect  # loaded already (NumPy uses it)

    stdlib, modules, here = sys.stdlib_module_names, sys.modules, inspect.currentframe
    own = os.path.abspath(__file__)
    roots = tuple(
        {own}
        | {
            os.path.join(p, "")
            for q in (sys.prefix, sys.base_prefix, sys.exec_prefix)
            if q
            for p in (q, os.path.realpath(q))
        }
    )
    rule = "its graded tests use it to check your answers"
    if allowed is not None:
        rule = f"assignment {assignment!r} allows only {', '.join(sorted(imports))}"

    def by_student(frame, skip: bool) -> bool:
        while skip and frame is not None and frame.f_globals.get("__name__") in _IMPORTLIB:
            frame = frame.f_back
        if frame is None:
            return True
        g = frame.f_globals
        mod = modules.get(g.get("__name__"))
        if mod is None or mod in student or getattr(mod, "__dict__", None) is not g:
            return True
        f = getattr(mod, "__file__", None)
        return not (isinstance(f, str) and f.startswith(roots))

    def refused(top: str, frame, skip: bool) -> bool:
        if top == module_name or (allowed is not None and top in allowed):
            return False
        if top in oracles or (allowed is not None and top not in stdlib):
            return True
        return allowed is not None and frame is not None and by_student(frame, skip)

    def check(fullname: str, frame=None, skip: bool = True) -> None:
        top = fullname.partition(".")[0]
        if not refused(top, frame, skip):
            return
        if top == "lab":
            note("import lab: the course library is not available to a submission")
            also = f" ({rule})" if allowed is not None else ""
            raise ImportError(
                f"importing 'lab' is not allowed in a submission: write the function yourself{also}",
                name=fullname,
            )
        note(f"import {top}: {rule}")
        raise ImportError(f"importing {top!r} is not allowed in a submission: {rule}", name=fullname)

    class Finder:
        """First on ``sys.meta_path``: any import of a module not loaded yet."""

        def find_spec(self, fullname, path=None, target=None):
            check(fullname, here().f_back)

    real_import = builtins.__import__

    def guarded_import(name, globals=None, locals=None, fromlist=(), level=0):
        """Import statements and ``__import__``, also of modules already loaded (``import os``)."""
        if level == 0 and name:
            check(name, here().f_back, False)  # the statement's own frame: importlib's are trusted here
        return real_import(name, globals, locals, fromlist, level)

    return check, Finder(), guarded_import


def _watch(allowed: tuple[str, ...], check, note):
    """The audit hook: notes what the sandbox forbids (it observes; the sandbox refuses), and refuses
    itself what the import rules forbid (``check``): importing such a module even with the finder
    removed, and opening the files of a package in site-packages the rules refuse (loading it by path,
    reading its source). An audit hook cannot be removed."""
    procs = {
        "os.fork",
        "os.forkpty",
        "os.posix_spawn",
        "os.exec",
        "os.spawn",
        "os.system",
        "subprocess.Popen",
    }
    sites = tuple(os.path.join(os.path.realpath(p), "") for p in sys.path if p.endswith("-packages"))
    normpath, join, getcwd, exists, dirname = (
        os.path.normpath,
        os.path.join,
        os.getcwd,
        os.path.exists,
        os.path.dirname,
    )
    realpath, fsdecode = os.path.realpath, os.fsdecode

    def package_file(p: str) -> None:
        real = realpath(p)
        for s in sites:
            if real.startswith(s):
                parts = real[len(s) :].split("/")
                entry = parts[1] if parts[0] == "__pycache__" and len(parts) > 1 else parts[0]
                try:
                    check(entry.replace("-", ".").split(".")[0])
                except ImportError as e:
                    raise PermissionError(f"reading {p} refused: {e}") from None

    def hook(event: str, args: tuple) -> None:
        if event == "open":
            path = args[0]
            if isinstance(path, (str, bytes)):
                p = normpath(join(getcwd(), fsdecode(path)))
                package_file(p)
                if "/__pycache__/" in p:  # the import system looking for a cached module: not the student
                    return
                if not any(p == a or p.startswith(a + "/") for a in allowed):
                    note(f"open {p}: outside the submission")
                elif p.startswith("/tmp/") and not exists(dirname(p)):
                    note(f"open {p}: not in the sandbox (its /tmp is its own)")
        elif event == "import":
            check(args[0])
        elif event in ("socket.connect", "socket.sendto", "socket.sendmsg"):
            note(f"a network connection to {args[1]!r}: no network while grading")
        elif event in procs:
            note(f"starting a process ({event}): not allowed while grading")

    return hook


def _describe(exc: BaseException, module_file: str) -> dict:
    """Type, message and the innermost frames of the submission's own file where it was raised (only
    its lines are looked up: no other file is opened for it)."""
    import linecache
    import traceback

    summary = traceback.StackSummary.extract(traceback.walk_tb(exc.__traceback__), lookup_lines=False)
    frames = [f for f in summary if f.filename == module_file]
    where = [
        {"line": f.lineno, "function": f.name, "code": linecache.getline(f.filename, f.lineno).strip()}
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


def _guard(config: dict, module_path: str, name: str, note) -> list:
    """Put the import rules and the audit hook in place, before the student's code runs; returns the
    list the student's module goes in (its imports are the student's own)."""
    import traceback  # noqa: F401  (loaded now, for _describe: the rules are for the student's imports)

    student: list = []
    check, finder, guarded_import = _rules(config, name, student, note)
    allowed = {os.path.dirname(module_path), "/tmp", "/dev/null", "/dev/urandom", "/proc/self", "/sys"}
    allowed |= {"/proc/cpuinfo", "/proc/meminfo", "/usr", "/etc/ld.so.cache", "/proc/" + str(os.getpid())}
    allowed |= {os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix) if p}
    allowed |= {p for p in (sys.prefix, sys.base_prefix, sys.exec_prefix) if p}
    allowed.add(os.path.abspath(__file__))  # this file: the traceback of an exception may read it
    sys.addaudithook(_watch(tuple(sorted(allowed)), check, note))
    sys.meta_path.insert(0, finder)
    builtins.__import__ = guarded_import
    return student


def _serve(req_fd: int, resp_fd: int, module_path: str) -> int:
    import importlib.util

    name = os.path.splitext(os.path.basename(module_path))[0]
    config = json.loads(os.environ.pop("LAB_GRADE_RULES", "") or "{}")  # lab.grading.rules.child_rules
    note, mark = _recorder(int(config.get("records_fd", -1)))
    try:
        import numpy  # noqa: F401  (before the student's code, so its import time is not theirs)

        student = _guard(config, module_path, name, note)
        spec = importlib.util.spec_from_file_location(name, module_path)
        module = importlib.util.module_from_spec(spec)
        student.append(module)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    except BaseException as e:  # noqa: BLE001 - SystemExit and KeyboardInterrupt at import too
        mark(0)
        write_message(resp_fd, {"ready": False, "error": _describe(e, module_path)})
        return 0
    functions = sorted(k for k, v in vars(module).items() if callable(v) and not k.startswith("_"))
    mark(0)
    write_message(resp_fd, {"ready": True, "functions": functions})
    sent = 0
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
        sent += 1
        mark(sent)
        write_message(resp_fd, answer)


def main(argv: list[str]) -> int:
    """``sandbox.py REQ_FD RESP_FD MODULE_PATH MEMORY_MB CPU_S [UID]`` (UID: become it first); the
    environment variable ``LAB_GRADE_RULES`` holds the assignment's import rules and the record pipe's
    file descriptor (JSON: :func:`lab.grading.rules.child_rules`, plus ``records_fd``)."""
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
