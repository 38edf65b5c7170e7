"""The figure of a robustness curve (:mod:`lab.eval.robustness`): success against error scale."""

from __future__ import annotations

import io
from pathlib import Path

__all__ = ["robustness_figure"]


def robustness_figure(points, path: Path, title: str) -> Path:
    """Success rate [%] against error scale, a curve per sensing profile, each point with its Wilson 95 %
    interval as an error bar (``points``: :class:`lab.eval.robustness.RobustnessPoint`), written to
    ``path`` (PNG, atomically)."""
    from matplotlib.figure import Figure

    from lab.io import write_bytes_atomic

    fig = Figure(figsize=(5, 3.5), layout="constrained")
    ax = fig.subplots()
    profiles = list(dict.fromkeys(p.sensing for p in points))
    span = max(p.scale for p in points) - min(p.scale for p in points)
    for i, sensing in enumerate(profiles):  # one curve per profile, nudged sideways to keep each visible
        pts = [p for p in points if p.sensing == sensing]
        dx = 0.02 * span * (i - (len(profiles) - 1) / 2)
        xs, ys = [p.scale + dx for p in pts], [100 * p.rate for p in pts]
        err = [[100 * (p.rate - p.low) for p in pts], [100 * (p.high - p.rate) for p in pts]]
        ax.errorbar(xs, ys, yerr=err, fmt="o-", capsize=4, label=sensing, color=f"C{i}")
        for p, y in zip(pts, ys, strict=True):
            ax.annotate(
                f"{p.successes}/{p.runs}",
                (p.scale + dx, y),
                textcoords="offset points",
                xytext=(6, -12),
                fontsize=8,
            )
    ax.set_xlabel("error scale (every error of the sensing profile times this)")
    ax.set_ylabel("success [%] (Wilson 95 %)")
    ax.set_ylim(-2, 102)
    ax.set_xticks(sorted({p.scale for p in points}))
    ax.legend(fontsize=8, title="sensing", title_fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=9)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return write_bytes_atomic(path, buf.getvalue())
