"""The landmark databases' cache under concurrent processes (lab/training/landmarks.py): two processes on
a cold cache split the posters, each trained once; a lock file left on disk holds nothing; a process that
died holding a poster's lock neither hangs the others nor leaves that poster untrained.

A stand-in trainer (tests/landmark_lock_child.py) sleeps instead of rendering, so these take seconds;
the other processes are real ones, of the 'spawn' context (the one of macOS and Windows).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections import Counter
from pathlib import Path

from landmark_lock_child import crash_holding, landmark_map, train_child, trainings

from lab.training.landmarks import load_landmark_map

TEXTURES = Path(__file__).resolve().parent.parent / "worlds" / "textures"
POSTERS = ("poster_a", "poster_b", "poster_c", "poster_d")


def _landmark_file(tmp_path: Path) -> Path:
    """Four posters on the walls of a 6 m x 8 m room."""
    rows = ["room_size = [6.0, 8.0]"]
    for i, name in enumerate(POSTERS):
        rows += [
            "[[landmark]]",
            f'name = "{name}"',
            f'texture = "{(TEXTURES / f"poster{i}.png").as_posix()}"',
            "size = [1.0, 0.02, 0.8]",
            f"centre = [{-2.0 + i:.1f}, 3.94, 1.5]",
        ]
    path = tmp_path / "landmarks.toml"
    path.write_text("\n".join(rows) + "\n")
    return path


def _dirs(tmp_path: Path) -> tuple[Path, Path]:
    cache, record = tmp_path / "cache", tmp_path / "record"
    record.mkdir()
    return cache, record


def test_two_processes_on_a_cold_cache_split_the_posters(tmp_path):
    """This process and a child start at once (a barrier): every poster is trained exactly once, both
    train some, and both get the same map, in the file's order."""
    toml = _landmark_file(tmp_path)
    cache, record = _dirs(tmp_path)
    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(2), ctx.Queue()
    child = ctx.Process(target=train_child, args=(toml, cache, record, 0.5, barrier, results))
    child.start()
    train_child(toml, cache, record, 0.5, barrier, results)
    out = [results.get(timeout=120) for _ in range(2)]
    child.join(timeout=30)
    assert child.exitcode == 0
    done = trainings(record)
    assert Counter(name for name, _ in done) == Counter(POSTERS)  # each once
    assert {pid for _, pid in done} == {os.getpid(), child.pid}  # split: each process trained some
    (_, a, _), (_, b, _) = out
    assert a == b
    assert [name for name, _ in a] == load_landmark_map(toml).names()


def test_a_lock_file_left_on_disk_does_not_block(tmp_path):
    """Lock files beside a cold cache's databases, with no process holding them: trained at once."""
    toml = _landmark_file(tmp_path)
    cache, record = _dirs(tmp_path)
    landmark_map(toml, cache, record, 0.0)
    for db in cache.rglob("*.npz"):
        db.unlink()
        db.with_name(f"{db.name}.lock").write_text("12345\n")
    assert len(list(cache.rglob("*.npz.lock"))) == len(POSTERS)
    before = len(trainings(record))
    done = threading.Thread(target=landmark_map, args=(toml, cache, record, 0.0), daemon=True)
    done.start()
    done.join(timeout=30)
    assert not done.is_alive(), "a stale lock file blocked the training"
    assert sorted(name for name, _ in trainings(record)[before:]) == sorted(POSTERS)


def test_a_process_that_died_holding_a_lock_is_waited_for_then_its_poster_trained(tmp_path):
    """A child takes poster_a's lock and dies holding it, without a database: the others are trained
    first, then the lock (freed by the OS with the child) is taken and poster_a trained here."""
    toml = _landmark_file(tmp_path)
    cache, record = _dirs(tmp_path)
    landmark_map(toml, cache, record, 0.0)  # learn the cache's paths, then make it cold again
    (db_a,) = cache.rglob("poster_a-*.npz")
    for db in cache.rglob("*.npz"):
        db.unlink()
    ctx = multiprocessing.get_context("spawn")
    held = ctx.Event()
    child = ctx.Process(target=crash_holding, args=(str(db_a.with_name(f"{db_a.name}.lock")), held, 1.0))
    child.start()
    assert held.wait(timeout=60)
    before = len(trainings(record))
    t0 = time.monotonic()
    m = landmark_map(toml, cache, record, 0.0)
    child.join(timeout=30)
    assert child.exitcode == 1
    order = [name for name, _ in trainings(record)[before:]]
    assert order == ["poster_b", "poster_c", "poster_d", "poster_a"]
    assert time.monotonic() - t0 < 30
    assert m.names() == list(POSTERS) and m.trained
