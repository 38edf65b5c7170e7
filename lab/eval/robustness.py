"""The robustness curve of a sweep (``lab eval identify|search --error-scale 1,2,3``): success against
the scale of every error of the sensing profile (:meth:`lab.sim.sensing.SensingProfile.scaled`), with
Wilson 95 % intervals, as a table in ``report.md`` and a figure ``robustness.png``; so that the margin
between the profile and a worse room is a number."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from lab.errors import ConfigError

__all__ = [
    "ERROR_SCALE_FLAG",
    "RobustnessPoint",
    "parse_error_scales",
    "robustness_lines",
    "robustness_points",
    "scale_suffix",
]

ERROR_SCALE_FLAG = "--error-scale"
MAX_SCALE = 20.0  #: beyond it a profile's errors stop meaning anything (a 1 s latency at 20 x 50 ms)


def parse_error_scales(value) -> tuple[float, ...]:
    """``"1,2,3"`` (or a list of numbers, a sweep file's) -> ``(1.0, 2.0, 3.0)``.

    Raises
    ------
    ConfigError
        Naming the bad value and what is allowed: not a number, not finite, not in (0, 20], given twice,
        or none at all.
    """
    parts = value if isinstance(value, (list, tuple)) else [p.strip() for p in str(value).split(",")]
    parts = [p for p in parts if p != ""]
    allowed = f"{ERROR_SCALE_FLAG} takes comma-separated numbers in (0, {MAX_SCALE:g}], e.g. 1,2,3"
    if not parts:
        raise ConfigError(f"{ERROR_SCALE_FLAG} is empty: {allowed}")
    out: list[float] = []
    for p in parts:
        try:
            if isinstance(p, bool):
                raise ValueError
            k = float(p)
        except (TypeError, ValueError):
            raise ConfigError(f"{ERROR_SCALE_FLAG}: {p!r} is not a number; {allowed}") from None
        if not math.isfinite(k) or not 0 < k <= MAX_SCALE:
            raise ConfigError(f"{ERROR_SCALE_FLAG}: {p!r} is out of range; {allowed}")
        if k in out:
            raise ConfigError(f"{ERROR_SCALE_FLAG}: {p!r} is given twice; {allowed}")
        out.append(k)
    return tuple(out)


def scale_suffix(k: float) -> str:
    """A job key's suffix for error scale ``k``: none at 1 (the keys as before), ``_x2`` at 2."""
    return "" if k == 1 else f"_x{k:g}"


@dataclass(frozen=True)
class RobustnessPoint:
    """Success of one sensing profile at one error scale: ``successes`` of ``runs`` (jobs that ran), and
    the Wilson 95 % interval ``low``..``high`` (fractions)."""

    sensing: str
    scale: float
    successes: int
    runs: int
    low: float
    high: float

    @property
    def rate(self) -> float:
        return self.successes / self.runs


def robustness_points(rows) -> list[RobustnessPoint]:
    """Success per sensing profile and error scale over every job of the sweep that ran (its
    ``sensing``, ``error_scale`` and ``success`` columns; a row without ``error_scale`` is at scale 1;
    every other condition pooled), sorted by profile and scale."""
    from lab.evaluation import wilson_interval

    by: dict[tuple[str, float], list] = {}
    for r in rows:
        if not r.get("error"):
            key = (str(r.get("sensing", "")), float(r.get("error_scale") or 1.0))
            by.setdefault(key, []).append(bool(r["success"]))
    out = []
    for sensing, k in sorted(by):
        n, s = len(by[sensing, k]), sum(by[sensing, k])
        lo, hi = wilson_interval(s, n)
        out.append(RobustnessPoint(sensing, k, s, n, lo, hi))
    return out


def robustness_lines(out: Path, rows, what: str) -> list[str]:
    """The report's section (a table: profile, scale, success, Wilson 95 %) and ``out/robustness.png``,
    when the sweep has more than one error scale; nothing otherwise."""
    points = robustness_points(rows)
    if len({p.scale for p in points}) < 2:
        return []
    from lab.viz.robustness import robustness_figure

    robustness_figure(points, out / "robustness.png", f"lab eval {what}: success against error scale")
    lines = [
        "## Robustness: success against error scale",
        "",
        "Every error of the sensing profile times the scale (every other condition pooled); the figure: "
        "robustness.png.",
        "",
        "| sensing | error scale | success | rate | Wilson 95 % |",
        "|---|---|---|---|---|",
    ]
    for p in points:
        lines.append(
            f"| {p.sensing} | {p.scale:g} | {p.successes}/{p.runs} | {100 * p.rate:.1f} % | "
            f"[{100 * p.low:.1f}, {100 * p.high:.1f}] % |"
        )
    return [*lines, ""]
