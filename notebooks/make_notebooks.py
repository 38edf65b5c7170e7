"""Write the notebooks from their cells, without outputs (run from the repository root).

    python notebooks/make_notebooks.py

Each notebook is a list of ("md" | "code", text) cells: its ``cells_NN_topic.py`` beside this script holds
``INTRO`` (the title cell and the learning objectives, prerequisites and time), ``SUMMARY`` (the closing
cell: what was learnt, the next notebook, the assignment) and ``CELLS``; this script puts the common set-up
cell after ``INTRO`` and ``SUMMARY`` at the end.
Keeping the source in Python makes diffs readable and guarantees the committed notebooks carry no
outputs; the tests execute them headless with LAB_FAST=1.
"""

from __future__ import annotations

from pathlib import Path

import cells_00_simulator_and_stereo  # notebooks/ is the script's folder: sys.path[0]
import cells_01_pose_ekf
import cells_02_entropy_planning
import cells_03_grid_search
import cells_04_real_robot
import cells_05_localization
import nbformat

HERE = Path(__file__).resolve().parent

SETUP = """\
import os
import math
import numpy as np
import matplotlib.pyplot as plt
%matplotlib inline
FAST = os.environ.get("LAB_FAST") == "1"   # CI runs the notebooks quickly with LAB_FAST=1
"""


def notebook(cells) -> list[tuple[str, str]]:
    """A notebook's cells: its title cell(s), the common set-up cell, the rest, then its summary."""
    return [*cells.INTRO, ("code", SETUP), *cells.CELLS, *cells.SUMMARY]


def write(name: str, cells) -> Path:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [
        nbformat.v4.new_markdown_cell(t) if k == "md" else nbformat.v4.new_code_cell(t) for k, t in cells
    ]
    for n, cell in enumerate(nb.cells):  # stable ids: rewriting a notebook changes only what changed
        cell["id"] = f"cell-{n:02d}"
    path = HERE / name
    nbformat.write(nb, path)
    return path


NOTEBOOKS = {
    "00_simulator_and_stereo.ipynb": notebook(cells_00_simulator_and_stereo),
    "01_pose_ekf.ipynb": notebook(cells_01_pose_ekf),
    "02_entropy_planning.ipynb": notebook(cells_02_entropy_planning),
    "03_grid_search.ipynb": notebook(cells_03_grid_search),
    "04_real_robot.ipynb": notebook(cells_04_real_robot),
    "05_localization.ipynb": notebook(cells_05_localization),
}

if __name__ == "__main__":
    for name, cells in NOTEBOOKS.items():
        print(write(name, cells))
