"""Every notebook executes headless in fast mode (LAB_FAST=1) and its own assertions hold."""

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))
# Wall time of a fast-mode run on a quiet machine, measured: 02 runs two closed loops of rendered
# frames (~29 s); 05 two 10 m localization drives (~32 s of CPU, ~40 s wall on 2 shared cores, plus
# ~30 s to train the landmark databases into an empty cache); the others take 3-15 s. The slow ones
# still run in the full suite (CI); `make test-fast` leaves them out.
SLOW = {"02_entropy_planning", "05_localization"}
PARAMS = [pytest.param(p, id=p.stem, marks=[pytest.mark.slow] if p.stem in SLOW else []) for p in NOTEBOOKS]


@pytest.mark.parametrize("path", PARAMS)
def test_notebook_runs_in_fast_mode(path, monkeypatch):
    monkeypatch.setenv("LAB_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), (
        "commit notebooks without outputs"
    )
    NotebookClient(
        nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    assert os.environ["LAB_FAST"] == "1"
