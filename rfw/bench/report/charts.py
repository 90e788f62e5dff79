"""The report's charts (matplotlib, PNG files under ``charts/``): stacked per-pass medians with
each segment's 95% CI, and the distributions of frame times."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..images import PNG_METADATA
from ..summary import VariantSummary
from .document import Img


def _charts(out_dir: Path, rfw: list[VariantSummary]) -> list[Img]:
    done = [v for v in rfw if v.ok]
    if not done:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    charts = out_dir / "charts"
    charts.mkdir(exist_ok=True)
    names: list[str] = []
    for v in done:
        names.extend(p["name"] for p in v.passes if p["name"] not in names)
    cmap = plt.get_cmap("tab20")
    colors = {n: cmap(i % 20) for i, n in enumerate(names)}
    labels = [v.label for v in done]
    height = max(2.5, 0.45 * len(done) + 1.5)
    fig, axes = plt.subplots(1, 2, figsize=(14, height), sharey=True)
    for ax, metric, title in ((axes[0], "gpu_ms", "GPU ms per pass (median, 95% CI)"),
                              (axes[1], "cpu_ms", "CPU record ms per pass (median, 95% CI)")):
        ax.set_title(title)
        left = [0.0] * len(done)
        for n in names:
            widths, err, has = [], [[], []], []
            for i, v in enumerate(done):
                p = next((p for p in v.passes if p["name"] == n), None)
                s = p and p[metric]
                widths.append(s["median"] if s else 0.0)
                if s:  # a variant without this pass gets no bar
                    lo, hi = stacked_error(s)
                    err[0].append(lo)
                    err[1].append(hi)
                    has.append(i)
            ax.barh(labels, widths, left=left, color=colors[n], label=n)
            # each segment's CI drawn at its right end, where its median ends the stack
            ends = [a + b for a, b in zip(left, widths, strict=True)]
            if has:
                ax.errorbar([ends[i] for i in has], [labels[i] for i in has], xerr=err,
                            fmt="none", ecolor="black", elinewidth=0.8, capsize=2)
            left = ends
        ax.set_xlabel("ms")
    axes[0].invert_yaxis()  # shared: the first variant on top, as in the tables
    axes[1].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    fig.tight_layout()
    passes = charts / "passes.png"
    fig.savefig(passes, dpi=100, metadata=PNG_METADATA)
    plt.close(fig)
    fig, axes = plt.subplots(1, 2, figsize=(14, height), sharey=True)
    for ax, metric, title in ((axes[0], "gpu_ms", "frame GPU ms (all frames, all repeats)"),
                              (axes[1], "wall_ms", "wall ms per frame (one per run)")):
        data = [[x for run in v.samples.get(metric, []) for x in run] or [math.nan]
                for v in done]
        ax.boxplot(data, orientation="horizontal", tick_labels=labels, whis=(5, 95), showfliers=True,
                   flierprops={"markersize": 3})
        ax.set_title(title + " — whiskers p5-p95")
        ax.set_xlabel("ms")
    axes[0].invert_yaxis()
    fig.tight_layout()
    dist = charts / "distributions.png"
    fig.savefig(dist, dpi=100, metadata=PNG_METADATA)
    plt.close(fig)
    return [Img("charts/passes.png", "stacked per-pass medians"),
            Img("charts/distributions.png", "frame time distributions")]


def stacked_error(s: dict[str, Any] | None) -> tuple[float, float]:
    """The error bar of one stacked segment: distances from its median down to the CI's low
    end and up to its high end (zero for no samples)."""
    if not s:
        return 0.0, 0.0
    return max(0.0, s["median"] - s["ci_lo"]), max(0.0, s["ci_hi"] - s["median"])
