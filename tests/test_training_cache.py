"""The training caches' rule for building (lab/training/cache.py): under concurrent processes on a cold
cache each artefact is built once (one artefact: the second process waits and reads it; a list: the
processes split it); a warm cache is read without a lock and without write access; a failed build
leaves no file and no held lock.

A stand-in artefact (tests/cache_lock_child.py) sleeps instead of rendering, so these take seconds; the
other processes are real ones, of the 'spawn' context (the one of macOS and Windows). The landmark
maps' use of the rule has its own tests (tests/test_landmark_cache.py: a stale lock file, a crashed
holder).
"""

from __future__ import annotations

import multiprocessing
import os
import stat
import sys
from collections import Counter
from pathlib import Path

import pytest
from cache_lock_child import builds, child, stand_in

from lab.training.cache import load_or_build, load_or_build_all

NAMES = ("a", "b", "c", "d")


def _dirs(tmp_path: Path) -> tuple[Path, Path]:
    cache, record = tmp_path / "cache", tmp_path / "record"
    record.mkdir()
    return cache, record


def _two_processes(names, cache: Path, record: Path, sleep_s: float) -> list[tuple[int, list[str]]]:
    """This process and a 'spawn' child get ``names`` at once (they meet at a barrier first):
    [(pid, values)] of both; the child exited cleanly."""
    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(2), ctx.Queue()
    proc = ctx.Process(target=child, args=(names, cache, record, sleep_s, barrier, results))
    proc.start()
    child(names, cache, record, sleep_s, barrier, results)
    out = [results.get(timeout=120) for _ in range(2)]
    proc.join(timeout=30)
    assert proc.exitcode == 0
    return out


def test_two_processes_on_a_cold_cache_build_one_artefact_once(tmp_path):
    """One process builds it; the other waits for the lock and reads that one's file."""
    cache, record = _dirs(tmp_path)
    (_, a), (_, b) = _two_processes(["a"], cache, record, 1.0)
    ((name, pid),) = builds(record)
    assert name == "a"
    assert a == b == [f"a built by {pid}"]


def test_two_processes_on_a_cold_cache_split_a_list(tmp_path):
    """Every artefact is built exactly once, both processes build some, and both get every artefact
    (the same values, in the list's order)."""
    cache, record = _dirs(tmp_path)
    (pid_a, a), (pid_b, b) = _two_processes(list(NAMES), cache, record, 0.5)
    done = builds(record)
    assert Counter(name for name, _ in done) == Counter(NAMES)  # each once
    assert {pid for _, pid in done} == {pid_a, pid_b}  # split: each process built some
    assert a == b == [f"{name} built by {pid}" for name, pid in sorted(done)]


def _read_only(folder: Path) -> bool:
    """Take write access to ``folder`` away; False where that does not bind (root, Windows)."""
    if sys.platform == "win32" or os.geteuid() == 0:
        return False
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    return True


def test_a_warm_cache_is_read_without_a_lock_or_write_access(tmp_path):
    """Built once, its lock files removed and the folder made read-only (where that binds): both calls
    read the cache, never build (the stand-in's build would raise) and create no lock file."""
    cache, record = _dirs(tmp_path)
    load_or_build_all([stand_in(cache, record, n) for n in NAMES], progress=False)
    for lock in cache.glob("*.lock"):
        lock.unlink()
    read_only = _read_only(cache)
    try:
        warm = [stand_in(cache, record, n, fail=True) for n in NAMES]
        assert load_or_build(warm[0], progress=False) == f"a built by {os.getpid()}"
        assert load_or_build_all(warm, progress=False) == [f"{n} built by {os.getpid()}" for n in NAMES]
        assert sorted(p.name for p in cache.iterdir()) == [f"{n}.txt" for n in NAMES]  # no lock file
    finally:
        if read_only:
            cache.chmod(stat.S_IRWXU)
    assert len(builds(record)) == len(NAMES)


def test_a_failed_build_leaves_no_file_and_frees_its_lock_and_rebuild_builds_again(tmp_path, capsys):
    """A build that raises: the error reaches the caller, nothing is cached, and the next call (in this
    process, so the lock was released) builds it. ``rebuild`` builds a warm one again, and says why."""
    cache, record = _dirs(tmp_path)
    with pytest.raises(AssertionError, match="a was built"):
        load_or_build(stand_in(cache, record, "a", fail=True), progress=False)
    assert not (cache / "a.txt").exists()
    assert load_or_build(stand_in(cache, record, "a"), progress=True) == f"a built by {os.getpid()}"
    assert "lab: building the stand-in a (it is not in the cache) -> " in capsys.readouterr().err
    load_or_build(stand_in(cache, record, "a"), progress=True, rebuild=True)
    assert "lab: building the stand-in a (rebuild requested)" in capsys.readouterr().err
    assert [name for name, _ in builds(record)] == ["a", "a"]
