"""Charts of runs along a camera path: GPU ms per frame per pass (the median over repeats at
each frame of the path), and the culling counters per frame where the runs have them.

A run's record holds ``camera_path`` (each timed frame's camera, ``rfw.camera_path``), its
passes' per-frame ``gpu_ms`` and, on meshlet configs, ``culling_frames`` (the counters of
each frame of the path, read in an untimed replay of it: ``rfw.bench.worker``).
"""

from __future__ import annotations

import re
import statistics
from pathlib import Path
from typing import Any

from ..fileio import inside
from .images import PNG_METADATA

# culling counters drawn per frame, where a record has them (None: not measured)
CULLING_KEYS = ("meshlets_drawn", "culled_frustum", "culled_cone", "culled_occlusion",
                "instances_culled")


def on_path(variant: Any) -> bool:
    """Whether ``variant``'s runs followed a camera path."""
    return bool(variant.ok and variant.get("camera_path"))


def per_frame(records: list[dict[str, Any]], name: str) -> list[float]:
    """Pass ``name``'s GPU ms at each frame of the path: the median over the runs."""
    runs = [next((p["gpu_ms"] for p in r.get("passes", []) if p["name"] == name), [])
            for r in records]
    runs = [r for r in runs if r]
    if not runs:
        return []
    return [statistics.median(v) for v in zip(*runs, strict=False)]


def path_params(variant: Any) -> list[float]:
    """The path parameter t of each timed frame (from the first run: every run has the
    same path)."""
    return [float(c["t"]) for c in variant.get("camera_path")["frames"]]


def path_charts(out_dir: Path, variants: list[Any], img: Any) -> list[Any]:
    """One chart per variant that ran along a camera path, ``charts/path_<variant>.png``:
    GPU ms per frame per pass against the path parameter, and below it the culling
    counters per frame when the runs have them. Returns ``img(path, alt)`` entries (the
    report's ``Img``)."""
    along = [v for v in variants if on_path(v)]
    if not along:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = inside(out_dir, "charts")
    folder.mkdir(exist_ok=True)
    out = []
    for i, v in enumerate(along):
        t = path_params(v)
        culling = [c for c in (v.get("culling_frames") or []) if c]
        keys = [k for k in CULLING_KEYS if any(c.get(k) is not None for c in culling)]
        rows = 2 if keys else 1
        fig, axes = plt.subplots(rows, 1, figsize=(10, 3.2 * rows), sharex=True,
                                 squeeze=False)
        ax = axes[0][0]
        for p in v.passes:
            ys = per_frame(v.records, p["name"])
            if ys:
                ax.plot(t[:len(ys)], ys, marker=".", label=p["name"])
        kind = v.get("camera_path").get("kind", "path")
        ax.set_title(f"{v.label}: GPU ms per frame along the {kind} "
                     f"({len(v.records)} run(s), median per frame)")
        ax.set_ylabel("GPU ms")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        if keys:
            cax = axes[1][0]
            for k in keys:
                cax.plot(t[:len(culling)], [c.get(k) for c in culling], marker=".", label=k)
            cax.set_ylabel("count")
            cax.set_title("culling counters per frame")
            cax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        axes[-1][0].set_xlabel("path parameter t (frame k of N)")
        fig.tight_layout()
        name = f"path_{i}_{re.sub(r'[^A-Za-z0-9._-]+', '_', v.label).strip('_') or 'run'}.png"
        fig.savefig(folder / name, dpi=100, metadata=PNG_METADATA)
        plt.close(fig)
        out.append(img(f"charts/{name}", f"GPU ms per frame along the camera path: {v.label}"))
    return out
