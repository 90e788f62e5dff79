"""What every backend's frame driver shares: the ``Result`` of a run, the scene and camera a
config asks for, and the fields of ``timings.json`` every backend writes. Below
:mod:`rfw.render` and the backends, so both import it and neither imports the other back."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .config import Config, pass_class
from .errors import RfwError


@dataclass
class Result:
    config: Config
    images: dict[str, np.ndarray]  # output resource -> (H, W, C) array
    timings: dict[str, Any]  # what timings.json holds
    executor: Any


def load_scene_for(cfg: Config, scene: Any = None) -> Any:
    if scene is not None:
        return scene
    from .scene import default_scene, load_scene

    if cfg.scene == "default":
        return default_scene()
    if not Path(cfg.scene).exists():  # say which config (or --scene) asked for it
        raise RfwError(f"scene file not found: {cfg.scene}", file=cfg.source,
                       element="scene")
    return load_scene(cfg.scene)


def camera_for(cfg: Config, scene: Any) -> Any:
    cam = scene.default_camera()
    if cfg.camera:
        from dataclasses import replace

        values = dict(cfg.camera)
        if "yfov" in values:
            values["yfov"] = float(np.radians(values["yfov"]))
        cam = replace(cam, **{k: tuple(v) if isinstance(v, list) else v
                              for k, v in values.items()})
    return cam


def pass_timings(order: Any, timings: dict[str, Any]) -> list[dict[str, Any]]:
    """``timings.json``'s per-pass entries: medians over the timed frames."""
    return [{"name": n, "gpu_ms": median(timings[n].gpu_ms),
             "cpu_ms": median(timings[n].cpu_ms)} for n in order]


def frame_record(cfg: Config, frames: int, scene: Any, default_light: bool,
                 passes: list[dict[str, Any]], *, timestamps: bool) -> dict[str, Any]:
    """The fields of ``timings.json`` every backend writes (the device's come first)."""
    return {"config": cfg.name, "variants": cfg.chosen, "size": list(cfg.size),
            "frames": frames, "scene": scene.name, "triangles": scene.triangle_count,
            "default_light": default_light, "timestamps": timestamps, "passes": passes,
            "gpu_ms_total": sum(p["gpu_ms"] or 0.0 for p in passes)}


def pinned_elsewhere(cfg: Config, backend: str) -> bool:
    """Whether an enabled pass of ``cfg`` is pinned (in the config or by its class) to a
    backend other than ``backend``: its frame then mixes backends."""
    return any(e.enabled and (e.backend or pass_class(cfg, e).backend) not in (None, backend)
               for e in cfg.passes)


def median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None
