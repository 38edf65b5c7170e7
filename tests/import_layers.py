"""The import layers of ``lab/`` (docs/architecture.md), checked by reading the source.

Every ``import`` and ``from ... import`` counts, at module level or inside a function, a class or a
``try``/``if`` block, and relative imports are resolved, so a forbidden import cannot hide in a lazy
import. :func:`violations` returns one line per broken rule: the module, the line, what it imports and
the rule it breaks.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

#: The algorithm packages: handed a Robot and their data, they never render, plot, train or run.
ALGORITHMS = (
    "lab.estimation",
    "lab.vision",
    "lab.localization",
    "lab.navigation",
    "lab.identification",
    "lab.search",
    "lab.exercises",  # the checks of the notebooks' exercises: beside the algorithms
)


@dataclass(frozen=True)
class Rule:
    """Modules under any of ``packages`` must not import any of ``forbidden`` (a prefix match on dotted
    names: ``lab.sim`` forbids ``lab.sim.world`` too)."""

    name: str
    packages: tuple[str, ...]
    forbidden: tuple[str, ...]
    exempt: tuple[str, ...] = ()  # modules the rule does not apply to


_ABOVE_ALGORITHMS = ("lab.sim", "lab.viz", "lab.training", "lab.runs", "lab.cli", "lab.hardware")

RULES = (
    Rule(
        "algorithms never render, plot, train or run",
        ALGORITHMS,
        ("pybullet", "matplotlib", *_ABOVE_ALGORITHMS),
    ),
    Rule("only lab.hardware talks to serial devices", ("lab",), ("serial",), exempt=("lab.hardware",)),
    Rule("only lab.sim imports pybullet", ("lab",), ("pybullet",), exempt=("lab.sim",)),
    Rule("only lab.viz plots", ("lab",), ("matplotlib",), exempt=("lab.viz",)),
    Rule(
        "the two robots sit below the algorithms",
        ("lab.sim", "lab.hardware"),
        (
            "lab.localization",
            "lab.navigation",
            "lab.identification",
            "lab.search",
            "lab.estimation",
            "lab.viz",
            "lab.training",
            "lab.runs",
            "lab.cli",
        ),
    ),
    Rule(
        "localization sits beside navigation, below the searches that use it",
        ("lab.localization",),
        ("lab.navigation", "lab.identification", "lab.search"),
    ),
    Rule("pictures never run experiments or train", ("lab.viz",), ("lab.training", "lab.runs", "lab.cli")),
    Rule("training runs no experiment", ("lab.training",), ("lab.runs", "lab.cli", "lab.viz")),
    Rule("runs are called by the command line, not the other way", ("lab.runs",), ("lab.cli",)),
    Rule("sweeps are called by the command line, not the other way", ("lab.eval",), ("lab.cli",)),
    Rule(
        "the grader stands apart (it grades code, it runs no robot)",
        ("lab.grading",),
        ("pybullet", "matplotlib", "serial", "lab.scene", *ALGORITHMS, *_ABOVE_ALGORITHMS),
    ),
    Rule(
        "the ground floor imports nothing above it",
        (
            "lab.robot",
            "lab.geometry",
            "lab.errors",
            "lab.io",
            "lab.paths",
            "lab.scene",
            "lab.evaluation",
            "lab.mounts",
        ),
        ("lab.sim", "lab.hardware", "lab.viz", "lab.training", "lab.runs", "lab.cli", *ALGORITHMS),
    ),
)


def module_name(path: Path, root: Path) -> str:
    """``lab/vision/stereo.py`` -> ``lab.vision.stereo`` (``__init__`` -> the package)."""
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(path: Path, module: str) -> list[tuple[int, str]]:
    """Every module ``path`` imports, with its line: absolute names, relative ones resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.append((node.lineno, name))
            # `from lab import sim` imports lab.sim
            out += [(node.lineno, f"{name}.{a.name}") for a in node.names if a.name != "*"]
    return out


def _under(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def violations(root: Path, rules: tuple[Rule, ...] = RULES) -> list[str]:
    """The broken rules under the package folder ``root`` (e.g. ``<repo>/lab``), one line each."""
    found = []
    for path in sorted(root.rglob("*.py")):
        module = module_name(path, root)
        for rule in rules:
            if not _under(module, rule.packages) or _under(module, rule.exempt):
                continue
            hits: dict[int, str] = {}  # the module each line imports (not also its names)
            for line, name in imports(path, module):
                if _under(name, rule.forbidden) and len(name) < len(hits.get(line, name + "_")):
                    hits[line] = name
            rel = path.relative_to(root.parent)
            found += [f"{rel}:{line}: {module} imports {name} ({rule.name})" for line, name in hits.items()]
    return sorted(found)
