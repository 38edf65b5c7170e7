"""The import layers of docs/architecture.md hold: read from the source, and as Python imports them."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from import_layers import ALGORITHMS, violations

LAB = Path(__file__).resolve().parent.parent / "lab"


def test_the_package_keeps_its_layers():
    assert violations(LAB) == []


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "lab"
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
    for d in [root, *(p for p in root.rglob("*") if p.is_dir())]:
        (d / "__init__.py").touch()
    return root


def test_a_forbidden_import_is_caught_wherever_it_hides(tmp_path):
    root = _package(
        tmp_path,
        {
            "vision/clean.py": "import numpy as np\nfrom lab.geometry import se3\n",
            # inside a function, relative, and `from lab import sim`: all three are caught
            "vision/lazy.py": """\
                def render():
                    import pybullet
                    return pybullet
                """,
            "identification/rel.py": "from ..training import tables\n",
            "search/pkg.py": "from lab import sim\n",
            "navigation/plot.py": "try:\n    import matplotlib.pyplot\nexcept ImportError:\n    pass\n",
            "estimation/serial_use.py": "class A:\n    def f(self):\n        import serial\n",
            "hardware/ok.py": "import serial\n",  # the hardware adapter may
            "sim/world.py": "import pybullet\n",  # the simulator may
        },
    )
    found = violations(root)
    text = "\n".join(found)
    assert "lab/vision/lazy.py:2: lab.vision.lazy imports pybullet" in text
    assert "lab.identification.rel imports lab.training" in text
    assert "lab.search.pkg imports lab.sim" in text
    assert "lab.navigation.plot imports matplotlib" in text
    assert "lab.estimation.serial_use imports serial (only lab.hardware talks to serial devices)" in text
    assert "clean" not in text and "hardware/ok.py" not in text and "sim/world.py" not in text
    # each forbidden import once per rule, however many names it brings
    assert len([v for v in found if "lazy.py:2" in v]) == 2  # algorithms' rule and pybullet's


def test_importing_the_algorithms_starts_neither_pybullet_nor_matplotlib():
    """The issue's check, as anyone can run it: ``python -X importtime -c "import ..."``."""
    code = "import " + ", ".join(ALGORITHMS)
    r = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, check=True
    )
    loaded = [line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if "|" in line]
    assert "lab.identification" in loaded and "lab.search" in loaded  # the check sees the imports
    assert not [m for m in loaded if m.split(".")[0] in ("pybullet", "matplotlib", "serial")]
    assert not [m for m in loaded if m.startswith(("lab.sim", "lab.viz", "lab.training", "lab.runs"))]


def test_the_command_line_imports_numpy_only_after_its_blas_setting():
    """``lab`` keeps OpenBLAS to one thread (``lab.cli._one_blas_thread``), which takes effect only
    before numpy is first imported: importing the command imports neither numpy nor the library."""
    code = "import sys, lab.cli; print(sorted(m for m in sys.modules if m == 'numpy' or m == 'lab.robot'))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "[]"
