"""rfw's own ray casting (``rfw.raycast``, Vulkan ray queries or a ray-tracing pipeline), on
the same rays as the CPU peers.

``rfw.raycast`` builds its acceleration structures on every call, so each frame times two
calls: all rays, and one ray. Their difference is the cast; the one-ray call is the build and
set-up. Both are reported."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .common import Geometry, Unavailable, depth_image


def measure(geo: Geometry, origins: np.ndarray, directions: np.ndarray, width: int,
            height: int, *, frames: int, warmup: int) -> dict[str, Any]:
    try:
        import rfw

        raycast = rfw.raycast
    except (ImportError, AttributeError) as e:
        raise Unavailable(f"rfw.raycast is not available in this tree ({e})") from None
    v, i = geo.positions, geo.indices
    one_o, one_d = origins[:1], directions[:1]
    try:
        for _ in range(max(1, warmup)):
            raycast(v, i, origins, directions)
            raycast(v, i, one_o, one_d)
    except Exception as e:
        raise Unavailable(f"rfw.raycast failed: {type(e).__name__}: {e}") from None
    cast, build, full = [], [], []
    hits = None
    for _ in range(frames):
        t0 = time.perf_counter()
        hits = raycast(v, i, origins, directions)
        t1 = time.perf_counter()
        raycast(v, i, one_o, one_d)
        t2 = time.perf_counter()
        full.append((t1 - t0) * 1e3)
        build.append((t2 - t1) * 1e3)
        cast.append(max(0.0, full[-1] - build[-1]))
    t = hits["t"]
    from rfw import raycasting
    from vkext.device import VkDevice  # noqa: F401 - vkext is there when raycast ran

    dev = getattr(raycasting, "_default_device", None)
    name = "Vulkan"
    if dev is not None and hasattr(dev, "describe"):
        d = dev.describe()
        name = f"{d.get('device')} ({d.get('driver')})"
    return {"frame_ms": cast, "call_ms": full, "setup_ms": build,
            "timing": "wall: raycast(all rays) - raycast(1 ray); each call builds the BVH",
            "rays": len(origins), "image": depth_image(t, width, height), "version": "rfw",
            "device": name, "hits": int(np.isfinite(t).sum())}
