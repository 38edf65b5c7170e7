"""The training caches' one rule for building: read the cache, else build under the file's lock.

Each cached artefact of :mod:`lab.training` -- an object's feature database, a true model's lookup
tables, a poster's landmark database -- is one file, written atomically and checked when read (its
format, its digest, the hash of what it was built from). Building one takes seconds (a database) to
minutes (a model's tables), and a cold cache is often read by several processes at once: the test
workers (pytest-xdist, which share ``$LAB_CACHE``) and the workers of ``lab eval``. Without a lock
each process builds every artefact it needs, and all but the last file written are wasted work.

So an artefact is built under a lock file beside it (``<file>.lock``), and the cache is read once more
when the lock is held (its last holder may have just written the file):

* :func:`load_or_build`, one artefact: a process that finds the lock taken waits for it, then reads
  what the other process built.
* :func:`load_or_build_all`, a list (the posters of a room, the box models' tables): processes split
  the list. Each builds the artefacts whose lock is free, skips those another process holds, and at
  the end waits for those and reads them.

A warm cache is read before any lock is taken, so it needs no write access (a read-only or shared
cache). The locks are the operating system's (:class:`filelock.FileLock`): a crashed process's lock
is freed with it, and the next process to take it builds that artefact; a lock file left on disk
holds nothing.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

from filelock import FileLock, Timeout

__all__ = ["Artefact", "load_or_build", "load_or_build_all"]

T = TypeVar("T")

_HELD = object()  # another process holds the lock (and the caller would not wait)


@dataclass(frozen=True)
class Artefact(Generic[T]):
    """One file of a cache: where it is, how it is read, built and written.

    Attributes
    ----------
    path : Path
        Its file; its lock is ``<path>.lock``, beside it.
    what : str
        What it is, for the messages on stderr: ``"the feature database of M0"``.
    load : callable () -> (T or None, str)
        The cached artefact when the file holds the current one; else None and why not (missing,
        corrupt, stale: said in the message of a build).
    build : callable () -> T
    save : callable (T, Path) -> None
        Writes it atomically (a reader never sees half a file).
    """

    path: Path
    what: str
    load: Callable[[], tuple[T | None, str]]
    build: Callable[[], T]
    save: Callable[[T, Path], None]


def _locked(a: Artefact[T], wait: bool, progress: bool, rebuild: bool = False):
    """``a`` under its lock: read once more from the cache (the lock's last holder may have just saved it;
    not with ``rebuild``), else built and saved. :data:`_HELD` when another process holds the lock and
    not ``wait``; with ``wait``, blocks until it is free (the OS frees a dead holder's lock)."""
    a.path.parent.mkdir(parents=True, exist_ok=True)
    lock = FileLock(a.path.with_name(f"{a.path.name}.lock"))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        if not wait:
            return _HELD
        if progress:
            print(f"lab: waiting for another process to build {a.what}", file=sys.stderr)
        lock.acquire(timeout=-1)
    try:
        got, reason = (None, "rebuild requested") if rebuild else a.load()
        if got is None:
            if progress:
                print(f"lab: building {a.what} ({reason}) -> {a.path}", file=sys.stderr)
            got = a.build()
            a.save(got, a.path)
        return got
    finally:
        lock.release()


def load_or_build(a: Artefact[T], progress: bool = True, rebuild: bool = False) -> T:
    """``a`` from the cache, read without a lock; else built under its lock, or, when another process is
    building it, read once that one is done. ``rebuild``: built under the lock whatever the cache holds.
    A build says so on stderr (with ``progress``), with the reason."""
    if not rebuild:
        got, _ = a.load()
        if got is not None:
            return got
    return _locked(a, True, progress, rebuild)


def load_or_build_all(
    artefacts: Sequence[Artefact[T]], progress: bool = True, rebuild: bool = False
) -> list[T]:
    """Each of ``artefacts``, in order, from the cache or built. Processes on one cold cache split them:
    each builds those whose lock is free, skips those another process holds, and when it has built all
    it can, waits for the first of those (then tries the rest again, which may be done by then).
    ``rebuild``: each built, in order, under its lock (:func:`load_or_build`)."""
    if rebuild:
        return [load_or_build(a, progress, rebuild=True) for a in artefacts]
    out = [a.load()[0] for a in artefacts]
    todo = [i for i, got in enumerate(out) if got is None]
    while todo:
        held = []
        for i in todo:
            out[i] = _locked(artefacts[i], False, progress)
            if out[i] is _HELD:
                held.append(i)
        if held:
            out[held[0]] = _locked(artefacts[held[0]], True, progress)
        todo = held[1:]
    return out
