"""The figure of a robustness curve (:mod:`lab.eval.robustness`): success against error scale."""

from __future__ import annotations

import io
from pathlib import Path

__all__ = ["robustness_figure"]


def robustness_figure(points, path: Path, title: str) -> Path:
    """Success rate [%] against error scale, each point with its Wilson 95 % interval as an error bar
    (``points``: :class:`lab.eval.robustness.RobustnessPoint`), written to ``path`` (PNG, atomically)."""
    from matplotlib.figure import Figure

    from lab.io import write_bytes_atomic

    fig = Figure(figsize=(5, 3.5), layout="constrained")
    ax = fig.subplots()
    xs = [p.scale for p in points]
    ys = [100 * p.rate for p in points]
    err = [[100 * (p.rate - p.low) for p in points], [100 * (p.high - p.rate) for p in points]]
    ax.errorbar(xs, ys, yerr=err, fmt="o-", capsize=4, color="tab:blue")
    for p, y in zip(points, ys, strict=True):
        ax.annotate(
            f"{p.successes}/{p.runs}", (p.scale, y), textcoords="offset points", xytext=(6, -12), fontsize=8
        )
    ax.set_xlabel("error scale (every error of the sensing profile times this)")
    ax.set_ylabel("success [%] (Wilson 95 %)")
    ax.set_ylim(-2, 102)
    ax.set_xticks(xs)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=9)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return write_bytes_atomic(path, buf.getvalue())
