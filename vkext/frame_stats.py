"""What a Vulkan frame reports about its executor beside the timings: the acceleration
structures its builder pass made and the meshlet passes' culling counters, for
:class:`vkext.backend.VkBackend` (one-backend and mixed frames alike)."""

from __future__ import annotations

from typing import Any

from .meshlet import meshlet_counters


def accel_stats(ex: Any) -> dict[str, Any] | None:
    """The acceleration structures the frame's builder pass made: counts, bytes before and
    after compaction, build times and the frame builds (rebuilds or refits)."""
    for name, p in ex.passes.items():
        accel = getattr(p, "accel", None)
        if accel is not None and hasattr(accel, "stats"):
            return {"pass": name, **accel.stats()}
    return None


def culling_counters(ex: Any) -> dict[str, Any] | None:
    """The last frame's GPU culling counters of the meshlet passes, in timings.json's
    names, read back through the executor (call before it is destroyed).
    ``culled_occlusion`` is None where no pass runs the occlusion test (no late phase),
    ``triangles_culled_backface`` where no pass culls triangles."""
    last = meshlet_counters(ex)
    if not last:
        return None
    params = [p.params for p in ex.passes.values() if getattr(p, "type", None) == "mesh"]
    occlusion = any(getattr(q, "phase", None) == "late" and not getattr(q, "freeze", False)
                    for q in params)
    triangles = any(getattr(q, "triangles", False) for q in params)
    return {
        "meshlets_total": last["meshlets_total"], "meshlets_drawn": last["drawn"],
        "culled_cone": last["cone_culled"], "culled_frustum": last["frustum_culled"],
        "culled_occlusion": last["occlusion_culled"] if occlusion else None,
        "triangles_drawn": last["triangles_in_drawn"] - last["triangles_backface"],
        "meshlets_considered": last["considered"],
        "meshlets_drawn_late": last["drawn_late"] if occlusion else None,
        "instances_culled": last["instances_culled"],
        "triangles_total": last["triangles_total"],
        "triangles_considered": last["triangles"],
        "triangles_culled_cone": last["triangles_cone"],
        "triangles_culled_frustum": last["triangles_frustum"],
        "triangles_culled_occlusion": last["triangles_occlusion"] if occlusion else None,
        "triangles_culled_backface": last["triangles_backface"] if triangles else None,
    }
