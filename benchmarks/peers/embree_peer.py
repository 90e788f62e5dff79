"""Embree through embreex, as trimesh uses it (``RayMeshIntersector.intersects_first``):
closest hits of the primary rays, CPU, wall time; the scene is committed in the warm-up."""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import Geometry, Unavailable, depth_image, time_frames


def measure(geo: Geometry, origins: np.ndarray, directions: np.ndarray, width: int,
            height: int, *, frames: int, warmup: int) -> dict[str, Any]:
    try:
        import embreex
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
    except ImportError as e:
        raise Unavailable(f"embreex is not installed ({e}); pip install '.[peers]'") from None
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene=scene, vertices=geo.positions.astype(np.float32),
                 indices=geo.indices.astype(np.int32))
    o = origins.astype(np.float32)
    d = directions.astype(np.float32)
    out: dict[str, Any] = {}

    def frame() -> None:
        out["r"] = scene.run(o, d, output=1)

    wall = time_frames(frame, frames=frames, warmup=max(1, warmup))
    r = out["r"]
    t = np.where(r["geomID"] >= 0, r["tfar"], np.inf)
    return {"frame_ms": wall, "timing": "wall: EmbreeScene.run (closest hit)",
            "rays": len(origins), "image": depth_image(t, width, height),
            "version": f"embreex {getattr(embreex, '__version__', '?')}", "device": "CPU",
            "hits": int(np.isfinite(t).sum())}
