"""Render a config headless: images for each graph output and per-pass timings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .config import MAX_FRAMES, Config, build
from .errors import RfwError, check_number
from .fileio import atomic_write, inside
from .frame import (
    Result,
    camera_for,
    frame_record,
    load_scene_for,
    pass_timings,
    pinned_elsewhere,
)
from .graph import compile
from .graph.formats import format_info


def render(cfg: Config, *, scene: Any = None, frames: int | None = None, warmup: int = 1,
           device: Any = None, backend: str = "wgpu", validation: bool = False,
           alias: bool = True) -> Result:
    """Build, compile and run ``cfg``; returns images and timings (GPU ms from timestamps).

    ``backend="vk"`` runs it on raw Vulkan (``vkext.backend.render_vk``: ``validation`` turns
    the validation layer on, ``alias=False`` gives every transient its own allocation).

    A config that pins passes to a backend other than ``backend`` runs on both
    (``vkext.mixed.render_mixed``): ``backend`` is then the one of unpinned passes, bridges
    copy resources across through host memory and are timed as passes of their own, and
    ``device`` may be either backend's (the other one is made and dropped here)."""
    if backend not in ("wgpu", "vk"):
        raise RfwError(f"unknown backend '{backend}' (wgpu or vk)", file=cfg.source)
    if frames is not None:
        check_number(frames, "frames", kind=int, lo=1, hi=MAX_FRAMES, file=cfg.source)
    if backend == "vk" and not _is_wgpu_device(device):
        from vkext.backend import render_vk

        # render_vk resolves auto variants for its device, then mixes backends if pinned
        return render_vk(cfg, scene=scene, frames=frames, warmup=warmup, device=device,
                         validation=validation, alias=alias)
    if pinned_elsewhere(cfg, backend):
        from vkext.device import VkDevice
        from vkext.mixed import render_mixed

        devices = {"vk_device" if isinstance(device, VkDevice) else "wgpu_device": device}
        return render_mixed(cfg, scene=scene, frames=frames, warmup=warmup, backend=backend,
                            validation=validation, alias=alias, **devices)
    if backend == "vk":
        from vkext.backend import render_vk

        return render_vk(cfg, scene=scene, frames=frames, warmup=warmup, device=device,
                         validation=validation, alias=alias)
    from .backends.gpu_scene import GpuScene
    from .backends.wgpu_backend import Device, Executor

    built = build(cfg)
    plan = compile(built.graph)
    device = device or Device()
    check_extents(plan, device.device.limits.get("max-texture-dimension-2d"), cfg.source)
    scene = load_scene_for(cfg, scene)
    gpu_scene = GpuScene(device.device, scene, camera_for(cfg, scene))
    gpu_scene.set_viewport(cfg.size)
    outputs = tuple(plan.outputs)
    ex = Executor(device, plan, built.passes, built.slots, gpu_scene, readback=outputs)
    try:
        ex.run(warmup)
        for t in ex.timings.values():
            t.gpu_ms.clear()
            t.cpu_ms.clear()
        ex.run(frames or cfg.frames)
        images = {name: ex.read(name) for name in outputs}
    finally:
        ex.destroy()
        gpu_scene.destroy()
    passes = pass_timings(plan.order, ex.timings)
    timings = {**device.describe(), **frame_record(
        cfg, frames or cfg.frames, scene, gpu_scene.default_light, passes,
        timestamps="timestamp-query" in device.features)}
    return Result(cfg, images, timings, ex)


def check_extents(plan: Any, limit: int | None, source: str) -> None:
    """Every image of ``plan`` within the device's 2D limit: a clear error, not a GPU one."""
    for r in plan.resources:
        if limit and r.kind == "image" and max(r.width, r.height) > limit:
            raise RfwError(f"'{r.name}' would be {r.width}x{r.height}, over the device's "
                           f"limit of {limit} pixels per side (use a smaller --size)",
                           file=source, element="size")


def backend_for(cfg: Config) -> str:
    """The backend a run takes when none is asked for: vk when every enabled pass is pinned
    to vk (in the config or by its class), else wgpu (pinned passes then mix in)."""
    from .config import pass_class

    pins = {e.backend or pass_class(cfg, e).backend for e in cfg.passes if e.enabled}
    return "vk" if pins == {"vk"} else "wgpu"


def _is_wgpu_device(device: Any) -> bool:
    return device is not None and type(device).__module__.startswith("rfw.backends")


def to_png_array(image: np.ndarray, fmt: str) -> np.ndarray:
    """8-bit RGBA for a PNG: unorm as is, floats clamped, depth and single channels grey."""
    info = format_info(fmt)
    a = image
    if a.dtype != np.uint8:
        a = a.astype(np.float32)
        if info.kind in ("unorm",):
            a = a / np.iinfo(image.dtype).max
        a = np.clip(a, 0.0, 1.0) * 255 + 0.5
        a = a.astype(np.uint8)
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    if a.shape[2] == 2:
        a = np.concatenate([a, np.zeros_like(a[..., :1])], axis=2)
    if a.shape[2] == 3:
        a = np.concatenate([a, np.full_like(a[..., :1], 255)], axis=2)
    if fmt.startswith("bgra") or fmt.startswith("VK_FORMAT_B8G8R8A8"):
        a = a[..., [2, 1, 0, 3]]
    return a


def output_paths(out_dir: Path, names: Any) -> list[Path]:
    """Where a run writes: ``<output>.png`` per name, then ``timings.json``, each refused
    unless it lands inside ``out_dir`` (symlinks resolved)."""
    return [inside(out_dir, f"{name}.png") for name in names] + [
        inside(out_dir, "timings.json")]


def clear_outputs(out_dir: Path, names: Any) -> None:
    """Remove what a previous run left at this run's paths: a run that fails then leaves no
    image or timings that could pass for its own."""
    for path in output_paths(out_dir, names):
        if path.is_file() or path.is_symlink():
            path.unlink()


FAILED_MARK = "RUN-FAILED.txt"  # beside outputs a failed run could not replace


def mark_failed(out_dir: Path, reason: str = "") -> None:
    """After a failed run into ``out_dir``: remove ``timings.json`` (it marks a complete run)
    and, if anything else is left, say in ``RUN-FAILED.txt`` that it is from an earlier run.
    A folder that does not exist is not created."""
    if not out_dir.is_dir():
        return
    (out_dir / "timings.json").unlink(missing_ok=True)  # a link goes, not what it points at
    mark = inside(out_dir, FAILED_MARK)
    if any(p.name != FAILED_MARK for p in out_dir.iterdir()):
        text = ("the last 'rfw run' into this folder failed: the other files here are from "
                f"an earlier run\n{reason}\n")
        atomic_write(mark, lambda f: f.write(text.encode("utf-8", "replace")))
    else:
        mark.unlink(missing_ok=True)


def write_outputs(result: Result, out_dir: Path, plan_formats: dict[str, str]) -> list[Path]:
    """``<output>.png`` per graph output, then ``timings.json`` (last: it marks a complete
    run), each written atomically inside ``out_dir``."""
    from PIL import Image

    *images, timings = output_paths(out_dir, result.images)
    out_dir.mkdir(parents=True, exist_ok=True)
    for path, (name, image) in zip(images, result.images.items(), strict=True):
        rgba = to_png_array(image, plan_formats[name])
        atomic_write(path, lambda f, a=rgba: Image.fromarray(a, "RGBA").save(f, format="PNG"))
    inside(out_dir, FAILED_MARK).unlink(missing_ok=True)
    atomic_write(timings, lambda f: f.write(json.dumps(result.timings, indent=2).encode()
                                            + b"\n"))
    return [*images, timings]


def table(timings: dict[str, Any]) -> str:
    rows = [f"{timings['config']} on {timings['device']} ({timings['driver']}), "
            f"{timings['size'][0]}x{timings['size'][1]}, {timings['frames']} frames, "
            f"{timings['triangles']:,} triangles"]
    w = max(24, *(len(p["name"]) for p in timings["passes"]))  # bridge names run long
    rows.append(f"  {'pass':<{w}} {'gpu ms':>9} {'cpu ms':>9}")
    for p in timings["passes"]:
        gpu = "-" if p["gpu_ms"] is None else f"{p['gpu_ms']:.3f}"
        rows.append(f"  {p['name']:<{w}} {gpu:>9} {p['cpu_ms']:>9.3f}")
    rows.append(f"  {'total':<{w}} {timings['gpu_ms_total']:>9.3f}")
    if timings.get("techniques"):  # what auto variants chose on this device
        rows.append("  techniques: " + ", ".join(f"{k}={v}" for k, v in
                                                 timings["techniques"].items()))
    if "bridge_ms_total" in timings:  # mixed backends: host copies, wall time
        rows.append(f"  {'bridges (host copies)':<{w}} {'-':>9} "
                    f"{timings['bridge_ms_total']:>9.3f}")
    return "\n".join(rows)
