"""Synthetic result records (no GPU): what a run of ``rfw bench`` writes, with chosen numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def record(variant: str, repeat: int, passes: dict[str, float], *, noise: float = 0.01,
           frames: int = 20, seed: int = 0, **extra) -> dict:
    """One run of ``variant``: each pass's GPU ms around its given median."""
    rng = np.random.default_rng(seed * 1000 + repeat)
    out = []
    for name, mean in passes.items():
        gpu = (mean * (1 + noise * rng.standard_normal(frames))).tolist()
        cpu = (0.1 * (1 + noise * rng.standard_normal(frames))).tolist()
        out.append({"name": name, "gpu_ms": gpu, "cpu_ms": cpu})
    gpu_frame = [sum(v) for v in zip(*(p["gpu_ms"] for p in out), strict=True)]
    cpu_frame = [sum(v) for v in zip(*(p["cpu_ms"] for p in out), strict=True)]
    return {"kind": "rfw", "variant": variant, "variant_id": variant.replace("@", "_"),
            "repeat": repeat, "device": "synthetic", "driver": "test", "backend": "wgpu",
            "config": variant.split("@")[0], "scene": "courtyard", "size": [32, 18],
            "frames": frames, "warmup": 1, "repeats": 3, "passes": out,
            "frame": {"gpu_ms": gpu_frame, "cpu_ms": cpu_frame,
                      "wall_ms": [g + 1.0 for g in gpu_frame]}, **extra}


def results(path: Path, variants: dict[str, dict[str, float]], *, repeats: int = 3,
            seed: int = 0, noise: float = 0.01) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    lines = [record(v, r, p, seed=seed, noise=noise) for r in range(repeats)
             for v, p in variants.items()]
    (path / "results.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return path
