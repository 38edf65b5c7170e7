"""Every notebook runs in fast mode (LAB_FAST=1) and its own assertions hold, once per notebook: in a
real JupyterLab in headless Chromium where there is a Chromium (always under CI), else headless
through nbclient.

In JupyterLab the test opens the notebook, runs it with Run All Cells (the menu's command), waits
until the kernel is idle with no cell queued, and reads the run back from the page:

* **no error output**: no cell raised (a failing ``assert`` of the notebook's own is one), and every
  code cell ran. Text on stderr that carries a traceback or names an error fails too; other stderr
  (pybullet's build banner, a Python warning) is not an error: it is kept in the test's log and is no
  reason to fail;
* **widgets drawn**: each ipywidgets output is a drawn widget (not "Loading widget...", not "Error
  displaying widget");
* **every 3D view drawn** (``lab.viz.view3d.show_page``: whatever cells show one): its canvas, at
  the recording's last step, is not blank;
* the page asked nothing of the web (every request off this machine is failed and recorded by
  tests/browser.py), and logged no console error.

A screenshot of each notebook after its run, and of each 3D view in it, is kept
(tests/browser.py: ``screenshot_dir``).
"""

import os
import re
from pathlib import Path

import nbformat
import pytest
from browser import Browser, find_chromium, screenshot_dir

REPO = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((REPO / "notebooks").glob("*.ipynb"))
# Wall time of a fast-mode run on a quiet machine, measured: 02 runs two closed loops of rendered
# frames (~29 s); 05 two 10 m localization drives (~32 s of CPU, ~40 s wall on 2 shared cores, plus
# ~30 s to train the landmark databases into an empty cache); the others take 3-15 s. The slow ones
# still run in the full suite (CI); `make test-fast` leaves them out.
SLOW = {"02_entropy_planning", "05_localization"}
PARAMS = [pytest.param(p, id=p.stem, marks=[pytest.mark.slow] if p.stem in SLOW else []) for p in NOTEBOOKS]
FAST_ENV = {"LAB_FAST": "1", "MPLBACKEND": "Agg"}
#: stderr that is an error: a traceback, or a line naming an exception or an error
ERROR_TEXT = re.compile(r"Traceback \(most recent call last\)|^\w*(Error|Exception)\b", re.MULTILINE)
RUN_TIMEOUT_S = 900  # a whole notebook in JupyterLab, on a loaded machine


@pytest.fixture(scope="module")
def jupyterlab(tmp_path_factory):
    """A JupyterLab serving a copy of the checkout, and a Chromium page to drive it; None where there
    is no Chromium (the notebooks then run through nbclient), except under CI, which must have one."""
    chromium = find_chromium()
    if chromium is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(
                "CI=true and no chromium on PATH to run the notebooks in JupyterLab; .ci/run installs it"
            )
        yield None
        return
    pytest.importorskip("jupyterlab", reason="JupyterLab is not installed (uv sync: the dev group has it)")
    from jupyterlab_run import JupyterLab, checkout_copy

    home = tmp_path_factory.mktemp("jupyterlab")
    root = checkout_copy(REPO, home / "checkout")
    with (
        JupyterLab(root, home, FAST_ENV) as lab,
        Browser(size=(1280, 900), timeout=240, chromium=chromium) as b,
    ):
        yield lab, b


@pytest.mark.parametrize("path", PARAMS)
def test_notebook_runs_in_fast_mode(path, jupyterlab, monkeypatch):
    nb = nbformat.read(path, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), (
        "commit notebooks without outputs"
    )
    if jupyterlab is None:
        run_in_nbclient(nb, path, monkeypatch)
        return
    from jupyterlab_run import run_notebook

    lab, b = jupyterlab
    b.blocked.clear()
    b.errors.clear()
    try:
        run = run_notebook(b, lab, f"notebooks/{path.name}", RUN_TIMEOUT_S, screenshot_dir())
    finally:
        lab.shut_down_kernels()
    print(f"{path.stem}: {run.wall_s:.1f} s in JupyterLab; stderr: {run.stderr()}")
    assert run.errors() == []
    n_code = sum(c.cell_type == "code" for c in nb.cells)
    assert len(run.counts) == n_code and None not in run.counts, f"cells that did not run: {run.counts}"
    assert [s for s in run.stderr() if ERROR_TEXT.search(s)] == []
    drawn = run.rendered
    assert drawn["loading"] == 0 and drawn["widget_errors"] == [], drawn
    assert drawn["widgets_drawn"] == run.widget_outputs(), drawn
    assert drawn["frames"] == run.view_outputs() == len(run.views), (drawn, run.views)
    assert all(v["std"] > 10 for v in run.views), run.views  # a scene, not a blank canvas
    assert b.blocked == [] and b.errors == [], (b.blocked, b.errors)


def run_in_nbclient(nb, path: Path, monkeypatch) -> None:
    """The notebook headless through nbclient (no browser here): its own assertions hold."""
    from nbclient import NotebookClient

    for k, v in FAST_ENV.items():
        monkeypatch.setenv(k, v)
    NotebookClient(
        nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    assert os.environ["LAB_FAST"] == "1"
