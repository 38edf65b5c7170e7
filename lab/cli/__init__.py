"""The ``lab`` command: ``lab --help`` lists the subcommands, ``lab CMD --help`` explains each.

Errors a user can fix (unknown world, bad option value, missing file) print one line naming what is
wrong and what is allowed, and exit with status 2; no traceback. The arguments are
:mod:`lab.cli.parser`'s, the commands :mod:`lab.cli.commands`'.
"""

from __future__ import annotations

import os
import sys

from lab.cli import commands
from lab.cli.parser import build_parser
from lab.errors import LabError

__all__ = ["main", "build_parser"]


def _one_blas_thread() -> None:
    """Keep OpenBLAS to one thread unless the user chose otherwise (``OPENBLAS_NUM_THREADS``).

    The loops' matrix products are small (a frame's ~200 descriptors against a database of ~700), and
    OpenBLAS's worker threads spin while they wait for work: measured on a 2-core machine, a ``lab
    identify`` episode took 33.6 s of CPU with the default threads and 18.6 s with one, for the same
    wall time and the same result. It only takes effect before numpy is first imported, which is why
    it is set here, at the command's entry, and not in the library.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    _one_blas_thread()
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command is None:
        ap.print_help()
        return 0
    try:
        return commands.HANDLERS[args.command](args)
    except LabError as e:
        print(f"lab {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lab {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
