"""``render_vk``: ``rfw.render.render`` on raw Vulkan, with the same ``Result``."""

from __future__ import annotations

from typing import Any

from rfw.config import Config, build, resolve_auto
from rfw.frame import (
    Result,
    camera_for,
    frame_record,
    load_scene_for,
    pass_timings,
    pinned_elsewhere,
)

from .device import VkDevice
from .executor import VkExecutor, check_passes, fit_plan
from .frame_stats import accel_stats, culling_counters
from .mixed import render_mixed
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
