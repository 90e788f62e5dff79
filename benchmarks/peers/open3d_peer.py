"""Open3D's RaycastingScene (Embree inside, CPU): closest hits of the primary rays.
The BVH is built on the first cast, a warm-up; frames time ``cast_rays`` (wall)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import Geometry, Unavailable, depth_image, time_frames


def measure(geo: Geometry, origins: np.ndarray, directions: np.ndarray, width: int,
            height: int, *, frames: int, warmup: int) -> dict[str, Any]:
    try:
        import open3d as o3d
    except ImportError as e:
        raise Unavailable(f"open3d cannot be imported ({e})") from None
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(geo.positions), o3d.core.Tensor(geo.indices))
    rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
    out: dict[str, Any] = {}

    def frame() -> None:
        out["t"] = scene.cast_rays(rays)["t_hit"].numpy()

    wall = time_frames(frame, frames=frames, warmup=max(1, warmup))
    return {"frame_ms": wall, "timing": "wall: cast_rays (BVH built in warm-up)",
            "rays": len(origins), "image": depth_image(out["t"], width, height),
            "version": f"open3d {o3d.__version__}", "device": "CPU (Embree)",
            "hits": int(np.isfinite(out["t"]).sum())}
