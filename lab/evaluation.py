"""How results are reported: the seed splits, and success rates with their Wilson 95 % intervals.

**Tune on one split, report on another.** Seeds below :data:`TUNING_SEEDS_END` (1000) are for tuning
parameters; evaluations report on seeds from :data:`REPORT_SEEDS_START` on, far above them, so that a
reported figure never comes from the seeds it was tuned on. The evaluation scripts default to
the report split and print the split they used (:func:`split_of`).

**Success rates** are given with the Wilson score interval (:func:`wilson_interval`), which stays
inside [0, 1] and keeps its coverage for rates near 0 or 1 and small counts, where the normal
approximation does not.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from lab.errors import ConfigError

__all__ = [
    "REPORT_SEEDS_START",
    "TUNING_SEEDS_END",
    "parse_seeds",
    "report_seeds",
    "split_of",
    "wilson_interval",
]

TUNING_SEEDS_END = 1000  #: the tuning split is the seeds below this
REPORT_SEEDS_START = 100000  #: the report split starts here


def report_seeds(n: int, start: int = REPORT_SEEDS_START) -> list[int]:
    """The first ``n`` seeds of the report split."""
    if int(n) != n or n < 1:
        raise ConfigError(f"the number of report seeds must be a positive integer, got {n!r}")
    return list(range(start, start + int(n)))


def parse_seeds(text: str) -> list[int]:
    """``"3-6,9"`` -> ``[3, 4, 5, 6, 9]``: the evaluation scripts' ``--seeds`` (ranges ``A-B`` and single
    numbers, comma-separated).

    Raises
    ------
    ConfigError
        A part that is neither a number nor ``A-B`` with A <= B.
    """
    out: list[int] = []
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        a, sep, b = part.partition("-")
        try:
            lo, hi = (int(a), int(b)) if sep else (int(a), int(a))
        except ValueError:
            msg = f"seeds must look like 100000-100024 or 0,3,5, got {part!r} in {text!r}"
            raise ConfigError(msg) from None
        if hi < lo:
            raise ConfigError(f"seed range {part!r} runs backwards (write {hi}-{lo})")
        out += range(lo, hi + 1)
    return out


def split_of(seeds: Iterable[int]) -> str:
    """``"report"`` (every seed >= :data:`REPORT_SEEDS_START`), ``"tuning"`` (every seed below
    :data:`TUNING_SEEDS_END`) or ``"mixed"``: what a figure measured on ``seeds`` may be called."""
    seeds = list(seeds)
    if not seeds:
        raise ConfigError("no seeds")
    if all(s >= REPORT_SEEDS_START for s in seeds):
        return "report"
    if all(0 <= s < TUNING_SEEDS_END for s in seeds):
        return "tuning"
    return "mixed"


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    r"""The Wilson score interval of a success rate ``k / n`` (95 % for the default ``z``).

    .. math::

        \frac{\hat p + \frac{z^2}{2n} \pm z \sqrt{\frac{\hat p (1 - \hat p)}{n} + \frac{z^2}{4n^2}}}
             {1 + \frac{z^2}{n}}, \qquad \hat p = k / n

    Raises
    ------
    ConfigError
        ``n`` < 1, or ``k`` outside 0..n.
    """
    if int(n) != n or n < 1 or int(k) != k or not 0 <= k <= n:
        raise ConfigError(f"a success rate needs 0 <= k <= n and n >= 1, got k={k!r}, n={n!r}")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)
