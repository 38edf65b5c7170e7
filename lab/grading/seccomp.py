"""The system calls a graded child may not make: a seccomp filter, written here as a classic-BPF program.

Grading calls a student's functions on numbers; it never needs the kernel's larger surfaces. The
filter (:func:`program`) is installed in every sandboxed child before any of the student's code runs
(bubblewrap loads it with ``--seccomp FD``; in the ``uid`` mode the child installs it itself, from the
file descriptor named by ``$LAB_SECCOMP_FD``, see :mod:`lab.grading.sandbox`). It refuses:

* **new namespaces**: ``unshare``, ``setns``, and ``clone`` with a namespace flag (a user namespace
  would give the child every capability inside it, and with them io_uring, nf_tables and mounts);
  ``clone3`` fails with ``ENOSYS`` (its flags are in memory a filter cannot read), so the C library
  falls back to ``clone``, whose flags it can;
* **kernel surfaces grading never needs**: io_uring, ``userfaultfd``, ``bpf``, ``perf_event_open``,
  the key rings, ``ptrace``, ``process_vm_*``, ``kcmp``, ``pidfd_getfd``, mounting, ``chroot``,
  ``kexec``, kernel modules, ``personality``, swap, reboot, clocks, ``syslog``, file handles;
* **memory outside the memory limit**: System V shared memory, message queues and semaphores, POSIX
  message queues and ``memfd_create``. ``RLIMIT_AS`` counts a process's mappings, not what a
  ``tmpfs`` or the IPC namespace holds;
* **new files, folders, links and extended attributes anywhere** (``open`` with ``O_CREAT`` or
  ``O_TMPFILE``, ``mkdir``, ``symlink``, ``link``, ``mknod``, ``setxattr``...; they fail with
  ``EROFS``): ``RLIMIT_FSIZE = 0`` already kept data out of files, but names, folders, links and
  extended attributes cost kernel memory too (a child filled its ``/tmp`` with 1.2 GB of them). A
  POSIX shared-memory segment is such a file (in ``/dev/shm``), so it is refused as well.

Refused calls fail with ``EPERM`` (``EROFS`` for a new file, ``ENOSYS`` for ``clone3`` and ``openat2``),
so the student's code sees an ordinary ``OSError``. The filter checks the architecture first: on
x86-64 and AArch64 it knows the numbers; a call made through another architecture's entry (32-bit
``int 0x80``, the x32 ABI) kills the process. On another machine :func:`program` raises.
"""

from __future__ import annotations

import functools
import os
import platform
import struct

__all__ = ["program", "program_fd", "attach", "number", "supported", "ENV_FD", "REFUSED_NAMES"]

ENV_FD = "LAB_SECCOMP_FD"  # the uid mode's child reads its filter from this file descriptor

# syscall name: (x86-64 number, AArch64 number); None where the architecture has no such call
_NUMBERS: dict[str, tuple[int | None, int | None]] = {
    "unshare": (272, 97),
    "setns": (308, 268),
    "io_uring_setup": (425, 425),
    "io_uring_enter": (426, 426),
    "io_uring_register": (427, 427),
    "userfaultfd": (323, 282),
    "bpf": (321, 280),
    "perf_event_open": (298, 241),
    "keyctl": (250, 219),
    "add_key": (248, 217),
    "request_key": (249, 218),
    "ptrace": (101, 117),
    "process_vm_readv": (310, 270),
    "process_vm_writev": (311, 271),
    "process_madvise": (440, 440),
    "kcmp": (312, 272),
    "pidfd_getfd": (438, 438),
    "mount": (165, 40),
    "umount2": (166, 39),
    "pivot_root": (155, 41),
    "chroot": (161, 51),
    "fsopen": (430, 430),
    "fsconfig": (431, 431),
    "fsmount": (432, 432),
    "fspick": (433, 433),
    "move_mount": (429, 429),
    "open_tree": (428, 428),
    "mount_setattr": (442, 442),
    "open_tree_attr": (467, 467),
    "kexec_load": (246, 104),
    "kexec_file_load": (320, 294),
    "init_module": (175, 105),
    "finit_module": (313, 273),
    "delete_module": (176, 106),
    "personality": (135, 92),
    "swapon": (167, 224),
    "swapoff": (168, 225),
    "reboot": (169, 142),
    "acct": (163, 89),
    "quotactl": (179, 60),
    "quotactl_fd": (443, 443),
    "syslog": (103, 116),
    "settimeofday": (164, 170),
    "clock_settime": (227, 112),
    "adjtimex": (159, 171),
    "clock_adjtime": (305, 266),
    "vhangup": (153, 58),
    "iopl": (172, None),
    "ioperm": (173, None),
    "modify_ldt": (154, None),
    "uselib": (134, None),
    "name_to_handle_at": (303, 264),
    "open_by_handle_at": (304, 265),
    "fanotify_init": (300, 262),
    "lookup_dcookie": (212, 18),
    # memory the memory limit does not count
    "shmget": (29, 194),
    "shmat": (30, 196),
    "shmctl": (31, 195),
    "shmdt": (67, 197),
    "msgget": (68, 186),
    "msgsnd": (69, 189),
    "msgrcv": (70, 188),
    "msgctl": (71, 187),
    "semget": (64, 190),
    "semop": (65, 193),
    "semctl": (66, 191),
    "semtimedop": (220, 192),
    "mq_open": (240, 180),
    "memfd_create": (319, 279),
    "memfd_secret": (447, 447),
}
# new names in a filesystem: EROFS, as on a read-only one
_CREATE: dict[str, tuple[int | None, int | None]] = {
    "mkdir": (83, None),
    "mkdirat": (258, 34),
    "symlink": (88, None),
    "symlinkat": (266, 36),
    "link": (86, None),
    "linkat": (265, 37),
    "mknod": (133, None),
    "mknodat": (259, 33),
    "creat": (85, None),
    "setxattr": (188, 5),
    "lsetxattr": (189, 6),
    "fsetxattr": (190, 7),
    "setxattrat": (463, 463),
}
_NOSYS: dict[str, tuple[int | None, int | None]] = {"clone3": (435, 435), "openat2": (437, 437)}
# calls allowed unless a flag in one argument is set: (x86-64, AArch64), argument index, flags
_CLONE = ((56, 220), 0, 0x02000000 | 0x04000000 | 0x08000000 | 0x10000000 | 0x20000000 | 0x40000000 | 0x20000)
_O_CREATE = 0o100 | 0o20000000  # O_CREAT, __O_TMPFILE (the same bits on both architectures)
_OPEN = ((2, None), 1, _O_CREATE)
_OPENAT = ((257, 56), 2, _O_CREATE)

REFUSED_NAMES = tuple(sorted({*_NUMBERS, *_CREATE, *_NOSYS, "clone (namespace flags)", "open (O_CREAT)"}))

_ARCH = {"x86_64": (0, 0xC000003E), "aarch64": (1, 0xC00000B7), "arm64": (1, 0xC00000B7)}
_X32_BIT = 0x40000000
_EPERM, _EROFS, _ENOSYS = 1, 30, 38
_RET_ALLOW, _RET_ERRNO, _RET_KILL_PROCESS = 0x7FFF0000, 0x00050000, 0x80000000
_LD_W_ABS, _JEQ_K, _JGE_K, _JSET_K, _RET_K = 0x20, 0x15, 0x35, 0x45, 0x06
_OFF_NR, _OFF_ARCH, _OFF_ARGS = 0, 4, 16  # struct seccomp_data; an argument's low 32 bits (little-endian)
_INSN = struct.Struct("=HBBI")  # struct sock_filter: code, jt, jf, k


def supported() -> bool:
    """True on the architectures whose system-call numbers the filter knows (x86-64, AArch64)."""
    return platform.machine().lower() in _ARCH


@functools.lru_cache(maxsize=1)
def program() -> bytes:
    """The filter for this machine's architecture as ``struct sock_filter`` records (what bubblewrap's
    ``--seccomp`` and ``prctl(PR_SET_SECCOMP)`` take)."""
    machine = platform.machine().lower()
    if machine not in _ARCH:
        raise OSError(f"no seccomp filter for the {machine} architecture (only x86_64 and aarch64)")
    col, audit_arch = _ARCH[machine]
    ins: list[tuple[int, int, int, int]] = [
        (_LD_W_ABS, 0, 0, _OFF_ARCH),
        (_JEQ_K, 1, 0, audit_arch),
        (_RET_K, 0, 0, _RET_KILL_PROCESS),
        (_LD_W_ABS, 0, 0, _OFF_NR),
    ]
    if col == 0:  # x86-64: the x32 ABI's numbers (bit 30 set) would get past every comparison below
        ins += [(_JGE_K, 0, 1, _X32_BIT), (_RET_K, 0, 0, _RET_KILL_PROCESS)]
    for table, errno in ((_NUMBERS, _EPERM), (_CREATE, _EROFS), (_NOSYS, _ENOSYS)):
        for numbers in table.values():
            if numbers[col] is not None:  # jump over the return when the number differs
                ins += [(_JEQ_K, 0, 1, numbers[col]), (_RET_K, 0, 0, _RET_ERRNO | errno)]
    for numbers, arg, flags, errno in ((*_CLONE, _EPERM), (*_OPEN, _EROFS), (*_OPENAT, _EROFS)):
        if numbers[col] is None:
            continue
        ins += [
            (_JEQ_K, 0, 4, numbers[col]),  # not this call: on to the next check
            (_LD_W_ABS, 0, 0, _OFF_ARGS + 8 * arg),
            (_JSET_K, 0, 1, flags),
            (_RET_K, 0, 0, _RET_ERRNO | errno),
            (_RET_K, 0, 0, _RET_ALLOW),
        ]
    ins.append((_RET_K, 0, 0, _RET_ALLOW))
    return b"".join(_INSN.pack(*i) for i in ins)


def program_fd() -> int:
    """A pipe's read end holding :func:`program` (closed for writing): pass it to bubblewrap's
    ``--seccomp`` or, as ``$LAB_SECCOMP_FD``, to the uid mode's child. The caller closes it."""
    data = program()
    r, w = os.pipe()
    try:
        os.write(w, data)  # far below a pipe's capacity: never blocks
    finally:
        os.close(w)
    return r


def attach(cmd: list[str], env: dict[str, str], bubblewrap: bool) -> int:
    """Give the child started by ``cmd`` the filter: bubblewrap's ``--seccomp FD`` (inserted after the
    bwrap executable) or, in the uid mode, ``$LAB_SECCOMP_FD`` in ``env`` (the child installs it once it
    is its throwaway uid). Returns the file descriptor to pass to the child and close afterwards."""
    fd = program_fd()
    if bubblewrap:
        cmd[1:1] = ["--seccomp", str(fd)]
    else:
        env[ENV_FD] = str(fd)
    return fd


def number(name: str) -> int:
    """This machine's number of the system call ``name`` (one the filter refuses), for the checks that
    try it."""
    col = _ARCH[platform.machine().lower()][0]
    for table in (_NUMBERS, _CREATE, _NOSYS):
        if name in table and table[name][col] is not None:
            return table[name][col]
    raise KeyError(f"{name} is not a system call the filter knows on this architecture")
