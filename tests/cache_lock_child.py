"""A stand-in artefact of the training caches and the child processes of their lock tests
(tests/test_training_cache.py; not a test module). Module level, so that a 'spawn' child can import them.

The stand-in's file holds one line of text. Its build sleeps instead of rendering, leaves one empty
file per build in a record folder (``<time ns>-<name>-<pid>``: which artefact, in which process, in
which order) and returns ``"<name> built by <pid>"``, so a reader can tell whose file it read.
"""

from __future__ import annotations

import os
import time
from pathlib import Path


def stand_in(folder: Path, record: Path, name: str, sleep_s: float = 0.0, fail: bool = False):
    """The artefact ``name`` in the cache ``folder`` (``<folder>/<name>.txt``); ``fail``: its build
    raises (for a warm cache, which must never build)."""
    from lab.io import write_text_atomic
    from lab.training.cache import Artefact

    path = Path(folder) / f"{name}.txt"

    def load():
        if not path.is_file():
            return None, "it is not in the cache"
        return path.read_text(), ""

    def build():
        if fail:
            raise AssertionError(f"{name} was built")
        time.sleep(sleep_s)
        (Path(record) / f"{time.time_ns()}-{name}-{os.getpid()}").touch()
        return f"{name} built by {os.getpid()}"

    def save(value, target):
        write_text_atomic(target, value)

    return Artefact(path, f"the stand-in {name}", load, build, save)


def builds(record: Path) -> list[tuple[str, int]]:
    """The recorded builds in time order: (name, pid) each."""
    rows = sorted(p.name.split("-", 1) for p in Path(record).iterdir())
    return [(rest.rsplit("-", 1)[0], int(rest.rsplit("-", 1)[1])) for _, rest in rows]


def child(names, folder, record, sleep_s, barrier, results) -> None:
    """A 'spawn' child: import, meet the other process at ``barrier``, then get ``names`` (one name:
    ``load_or_build``; several: ``load_or_build_all``); put (pid, values) on ``results``."""
    from lab.training.cache import load_or_build, load_or_build_all

    artefacts = [stand_in(folder, record, n, sleep_s) for n in names]
    barrier.wait()
    if len(artefacts) == 1:
        values = [load_or_build(artefacts[0], progress=False)]
    else:
        values = load_or_build_all(artefacts, progress=False)
    results.put((os.getpid(), values))
