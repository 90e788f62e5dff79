"""Mitsuba 3, ``llvm_ad_rgb`` (Dr.Jit LLVM, CPU; ``cuda_ad_rgb`` with --mitsuba-variant on
NVIDIA): ``scene.ray_intersect`` of the primary rays, evaluated and synced each frame.
The first frames compile the kernel (warm-up); Dr.Jit caches it after."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from .common import Geometry, Unavailable, depth_image, time_frames


def measure(geo: Geometry, origins: np.ndarray, directions: np.ndarray, width: int,
            height: int, *, frames: int, warmup: int) -> dict[str, Any]:
    variant = os.environ.get("RFW_MITSUBA_VARIANT", "llvm_ad_rgb")
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:
        raise Unavailable(f"mitsuba is not installed ({e}); pip install '.[peers]'") from None
    try:
        mi.set_variant(variant)
    except Exception as e:
        raise Unavailable(f"mitsuba variant {variant} cannot run: {e}") from None
    mesh = mi.Mesh("peer", vertex_count=len(geo.positions), face_count=geo.triangles,
                   has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.TensorXf(geo.positions))
    params["faces"] = dr.ravel(mi.TensorXu(geo.indices.astype(np.uint32)))
    params.update()
    scene = mi.load_dict({"type": "scene", "mesh": mesh})
    o = mi.Point3f(*(origins[:, i].copy() for i in range(3)))
    d = mi.Vector3f(*(directions[:, i].copy() for i in range(3)))
    ray = mi.Ray3f(o, d)
    out: dict[str, Any] = {}

    def frame() -> None:
        si = scene.ray_intersect(ray)
        dr.eval(si.t)
        dr.sync_thread()
        out["t"] = si.t

    wall = time_frames(frame, frames=frames, warmup=max(2, warmup))
    t = np.array(out["t"], np.float64)
    t[~np.isfinite(t) | (t > 1e30)] = np.inf
    return {"frame_ms": wall, "timing": f"wall: ray_intersect + eval + sync ({variant})",
            "rays": len(origins), "image": depth_image(t, width, height),
            "version": f"mitsuba {mi.__version__}, drjit {dr.__version__}",
            "device": f"{variant} ({'CPU' if variant.startswith(('llvm', 'scalar')) else 'GPU'})",
            "hits": int(np.isfinite(t).sum())}
