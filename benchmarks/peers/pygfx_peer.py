"""pygfx off screen (wgpu, so the same Vulkan driver rfw's wgpu backend runs on): rfw's
``flat`` technique as one unlit mesh with per-vertex colours (``Geometry.shaded_colors``:
pygfx takes vertex colours as linear, as rfw stores them). Wall time of a draw, waited for
with a small buffer read-back (``render`` then ``flush`` then a queue read). The image is
pygfx's colour target before its output pass (an sRGB texture: decoded to linear levels, which
costs up to about one level of precision near white)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import Geometry, Unavailable, time_frames


def measure(geo: Geometry, camera: Any, width: int, height: int, *, frames: int,
            warmup: int) -> dict[str, Any]:
    try:
        import pygfx as gfx
        import wgpu
        from rendercanvas.offscreen import RenderCanvas
    except ImportError as e:
        raise Unavailable(f"pygfx is not installed ({e}); pip install '.[peers]'") from None
    canvas = RenderCanvas(size=(width, height), pixel_ratio=1)
    # no antialiasing pass and no resampling filter: one sample per pixel, as rfw
    renderer = gfx.renderers.WgpuRenderer(canvas, pixel_ratio=1, pixel_filter="nearest",
                                          ppaa="none")
    scene = gfx.Scene()
    scene.add(gfx.Background.from_color("#000"))
    colors = geo.shaded_colors().astype(np.float32)
    # rfw culls back faces: counter-clockwise triangles are the front on both
    mesh = gfx.Mesh(gfx.Geometry(positions=geo.positions, colors=colors,
                                 indices=geo.indices.astype(np.int32)),
                    gfx.MeshBasicMaterial(color_mode="vertex", side="front"))
    scene.add(mesh)
    # pygfx's fov spans the mean of width and height: the one whose height spans yfov
    aspect = width / height
    fov = 2 * np.arctan(np.tan(camera.yfov / 2) * (1 + aspect) / 2)
    cam = gfx.PerspectiveCamera(fov=float(np.degrees(fov)), aspect=aspect,
                                depth_range=(camera.znear, camera.zfar))
    cam.local.position = tuple(camera.position)
    cam.world.reference_up = tuple(camera.up)
    cam.look_at(tuple(camera.target))
    device = renderer.device
    fence = device.create_buffer(size=16, usage=wgpu.BufferUsage.COPY_SRC
                                 | wgpu.BufferUsage.COPY_DST, label="peer:fence")

    def frame() -> None:
        renderer.render(scene, cam, flush=True)
        device.queue.read_buffer(fence)  # returns once the queue's work is done

    wall = time_frames(frame, frames=frames, warmup=warmup)
    image = _levels(renderer.snapshot()[..., :3])
    info = device.adapter.info
    return {"frame_ms": wall, "timing": "wall: render + flush + queue read",
            "image": np.ascontiguousarray(image), "version": f"pygfx {gfx.__version__}",
            "device": f"{info['device']} ({info['description']})"}


def _levels(target: np.ndarray) -> np.ndarray:
    """Linear 8-bit levels, as rfw stores them, of pygfx's colour target: rgba8unorm-srgb
    bytes (linear values sRGB-encoded by the hardware on store) or rgba16float."""
    if target.dtype == np.uint8:
        c = target.astype(np.float64) / 255
        linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    else:
        linear = target.astype(np.float64)
    return np.rint(np.clip(linear, 0, 1) * 255).astype(np.uint8)
