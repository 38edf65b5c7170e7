"""The command-line JSON contract, as JSON Schema files shipped with the package.

``lab/schemas/<kind>.schema.json`` (draft 2020-12) holds the fields that evaluation scripts read from
``lab identify --json`` (``identify``), ``lab search --json`` (``search``), the evaluation summary of
``benchmarks/eval_identify.py`` (``eval``) and ``lab grade --json`` (``grade``, Gradescope's
results.json). Outputs may carry more fields; these are kept. Validate a file from a script or a shell::

    from lab.contract import validate
    validate("identify", json.load(open("run.json")))       # raises ContractError

    python -m lab.contract identify run.json                 # "contract ok", or one line per problem
"""

from __future__ import annotations

import json
import sys
from functools import cache
from importlib import resources

from lab.errors import ConfigError, LabError

__all__ = ["KINDS", "ContractError", "schema", "problems", "validate"]

KINDS = ("identify", "search", "eval", "grade")


class ContractError(LabError, ValueError):
    """A JSON output lacks a contract field or has one of the wrong type (the message lists them)."""


@cache
def schema(kind: str) -> dict:
    """The JSON Schema of one output ``kind`` (one of :data:`KINDS`)."""
    if kind not in KINDS:
        raise ConfigError(f"unknown contract {kind!r}; contracts: {', '.join(KINDS)}")
    return json.loads(resources.files("lab.schemas").joinpath(f"{kind}.schema.json").read_text())


def problems(kind: str, data) -> list[str]:
    """Every way ``data`` breaks the ``kind`` contract, as ``"path: message"`` lines (empty: it keeps it)."""
    from jsonschema import Draft202012Validator

    v = Draft202012Validator(schema(kind))
    out = []
    for e in sorted(v.iter_errors(data), key=lambda e: list(map(str, e.absolute_path))):
        where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in e.absolute_path) or "(top)"
        out.append(f"{where.lstrip('.')}: {e.message}")
    return out


def validate(kind: str, data) -> None:
    """Raise :class:`ContractError` naming every broken field unless ``data`` keeps the ``kind`` contract."""
    found = problems(kind, data)
    if found:
        raise ContractError(f"{kind} output breaks the contract: " + "; ".join(found))


def main(argv: list[str] | None = None) -> int:
    """``python -m lab.contract KIND FILE.json``: 0 and "contract ok", or 1 and one line per problem."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2 or args[0] not in KINDS:
        print(f"usage: python -m lab.contract {{{','.join(KINDS)}}} FILE.json", file=sys.stderr)
        return 2
    kind, path = args
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        print(f"{path}: cannot read it as JSON ({e})", file=sys.stderr)
        return 2
    found = problems(kind, data)
    print("\n".join(f"{path}: {p}" for p in found) if found else "contract ok")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
