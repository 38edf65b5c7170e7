"""A stand-in landmark trainer and the child processes of the landmark cache's lock tests
(tests/test_landmark_cache.py; not a test module). Module level, so that a 'spawn' child can import them.

The stand-in sleeps instead of rendering, leaves one empty file per training in a record folder
(``<time ns>-<poster>-<pid>``: which poster, in which process, in which order) and returns a one-feature
database that the cache accepts (its asset hash is the one the real trainer would write).
"""

from __future__ import annotations

import os
import time
from functools import partial
from pathlib import Path


def stub_train(record: Path, sleep_s: float, poster, params, camera):
    """A database for ``poster`` after ``sleep_s`` [s], recorded in ``record``."""
    import numpy as np

    from lab.training.landmarks import _asset_hash
    from lab.vision.database import FORMAT_VERSION, FeatureDatabase

    time.sleep(sleep_s)
    name = poster.landmark.name
    (Path(record) / f"{time.time_ns()}-{name}-{os.getpid()}").touch()
    meta = {
        "format_version": FORMAT_VERSION,
        "name": name,
        "kind": "landmark",
        "asset_hash": _asset_hash(poster, params, camera),
    }
    return FeatureDatabase(
        name,
        np.array([[0.0, float(len(name)), 0.0]]),
        np.full((1, 128), float(len(name)), np.float32),
        np.ones((1, 1), bool),
        np.zeros((1, 2)),
        np.asarray(poster.landmark.size, dtype=np.float64),
        np.full((1, 1), 1.0, np.float32),
        meta,
    )


def trainings(record: Path) -> list[tuple[str, int]]:
    """The recorded trainings in time order: (poster, pid) each."""
    rows = sorted(p.name.split("-", 1) for p in Path(record).iterdir())
    return [(rest.rsplit("-", 1)[0], int(rest.rsplit("-", 1)[1])) for _, rest in rows]


def landmark_map(toml: Path, folder: Path, record: Path, sleep_s: float):
    """``trained_landmark_map`` of ``toml`` on the cache ``folder``, trained by the stand-in."""
    from lab.training.landmarks import trained_landmark_map

    train = partial(stub_train, Path(record), sleep_s)
    return trained_landmark_map(Path(toml), folder=Path(folder), progress=False, _train=train)


def train_child(toml, folder, record, sleep_s, barrier, results) -> None:
    """A 'spawn' child: import, meet the other child at ``barrier``, build the map; put (pid, [(name,
    digest)], wall time [s]) on ``results``."""
    import lab.training.landmarks  # noqa: F401  (imported before the barrier: both start the work at once)

    barrier.wait()
    t0 = time.monotonic()
    m = landmark_map(toml, folder, record, sleep_s)
    results.put((os.getpid(), [(lm.name, lm.database.digest()) for lm in m], time.monotonic() - t0))


def crash_holding(lock_path, held, hold_s: float) -> None:
    """A 'spawn' child that takes ``lock_path``'s lock, sets ``held``, and dies ``hold_s`` [s] later
    without releasing it (``os._exit``: no clean-up, as a crash)."""
    from filelock import FileLock

    lock = FileLock(lock_path)  # kept: a lock object that is collected releases its lock
    lock.acquire()
    held.set()
    time.sleep(hold_s)
    os._exit(1)
