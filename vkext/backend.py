"""``render_vk``: ``rfw.render.render`` on raw Vulkan, with the same ``Result``."""

from __future__ import annotations

from typing import Any

from rfw.config import Config, build, resolve_auto
from rfw.render import (
    Result,
    camera_for,
    frame_record,
    load_scene_for,
    pass_timings,
    pinned_elsewhere,
)

from .device import VkDevice
from .executor import VkExecutor, check_passes, fit_plan
from .scene import VkScene


def render_vk(cfg: Config, *, scene: Any = None, frames: int | None = None,
              device: VkDevice | None = None, validation: bool = False, alias: bool = True,
              warmup: int = 1) -> Result:
    """Build, compile (fitted to the device's memory requirements) and run ``cfg`` on
    Vulkan; returns images of the graph outputs and timings.json's fields (GPU ms from
    timestamps) plus ``memory``: transient bytes allocated against the plan's numbers.

    ``alias=False`` gives every transient its own allocation (``--no-alias``). Without a
    ``device`` one is made (with the validation layer when ``validation``) and destroyed
    here; ``timings["validation"]`` then counts the messages, leak reports included.

    A config that pins passes to wgpu runs as a mixed frame (``vkext.mixed.render_mixed``,
    unpinned passes on Vulkan).

    Variants left at an auto option (``shadows = "auto"``) are resolved for the device
    first (``rfw.config.resolve_auto``); ``timings["techniques"]`` reports what they chose.
    """
    own = device is None
    if own:
        device = VkDevice(validation=validation)
    try:
        cfg, techniques = resolve_auto(cfg, device.caps)
    except BaseException:
        if own:
            device.destroy()
        raise
    if pinned_elsewhere(cfg, "vk"):
        from .mixed import render_mixed

        if own:  # the mixed frame makes and counts its own
            device.destroy()
        result = render_mixed(cfg, scene=scene, frames=frames, warmup=warmup, backend="vk",
                              vk_device=None if own else device, validation=validation,
                              alias=alias)
        if techniques:
            result.timings["techniques"] = techniques
        return result
    built = build(cfg)
    validation = validation or device.validation
    try:
        plan, info = fit_plan(built.graph, device, alias=alias, readback=True)
        check_passes(plan, built.passes)  # a missing GLSL twin fails before any upload
        scene = load_scene_for(cfg, scene)
        vscene = VkScene(device, scene, camera_for(cfg, scene))
        outputs = tuple(plan.outputs)
        ex = None
        try:
            vscene.set_viewport(cfg.size)
            ex = VkExecutor(device, plan, built.passes, built.slots, vscene, readback=outputs,
                            alias=alias, memory_info=info)
            ex.run(warmup)
            for t in ex.timings.values():
                t.gpu_ms.clear()
                t.cpu_ms.clear()
            n = frames or cfg.frames
            ex.run(n)
            images = {name: ex.read(name) for name in outputs}
            memory = ex.memory()
            accel = accel_stats(ex)  # before the scene, which owns the structures, goes
        finally:
            if ex is not None:
                ex.destroy()
            vscene.destroy()
    finally:
        if own:
            device.destroy()  # leak reports arrive here, so count messages after it
    passes = pass_timings(plan.order, ex.timings)
    timings: dict[str, Any] = {
        **device.describe(), **frame_record(cfg, n, scene, vscene.default_light, passes,
                                            timestamps="timestamp" in device.caps),
        "memory": memory}
    culling = culling_counters(ex)
    if culling is not None:
        timings["culling"] = culling
    if techniques:
        timings["techniques"] = techniques
    if accel is not None:
        timings["accel"] = accel
    if validation:
        timings["validation"] = {"messages": len(device.messages),
                                 "texts": [m.text for m in device.messages[:20]]}
    return Result(cfg, images, timings, ex)


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
    names. ``culled_occlusion`` is None where no pass runs the occlusion test (no late
    phase), ``triangles_culled_backface`` where no pass culls triangles."""
    meshlets = [p for p in ex.passes.values() if getattr(p, "meshlets", None) is not None]
    last = next((p.meshlets.last for p in meshlets if p.meshlets.last), None)
    if not last:
        return None
    params = [getattr(p, "params", None) for p in meshlets]
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
