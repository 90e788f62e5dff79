"""pygfx off screen (wgpu, so the same Vulkan driver rfw's wgpu backend runs on): the scene as
one mesh with a Lambert material and a directional light. Wall time of a draw, waited for
with a small buffer read-back (``render`` then ``flush`` then a queue read)."""

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
    renderer = gfx.renderers.WgpuRenderer(canvas, pixel_ratio=1)
    scene = gfx.Scene()
    scene.add(gfx.Background.from_color("#000"))
    mesh = gfx.Mesh(gfx.Geometry(positions=geo.positions, normals=geo.normals,
                                 colors=geo.colors.astype(np.float32),
                                 indices=geo.indices.astype(np.int32)),
                    gfx.MeshPhongMaterial(color_mode="vertex", shininess=0, specular="#000"))
    scene.add(mesh)
    scene.add(gfx.AmbientLight(intensity=0.25))
    sun = gfx.DirectionalLight(intensity=2.5)
    sun.local.position = tuple(float(v) * 10 for v in geo.light_dir)
    scene.add(sun)
    # pygfx's fov spans the mean of width and height: the one whose height spans yfov
    aspect = width / height
    fov = 2 * np.arctan(np.tan(camera.yfov / 2) * (1 + aspect) / 2)
    cam = gfx.PerspectiveCamera(fov=float(np.degrees(fov)), aspect=aspect,
                                depth_range=(camera.znear, camera.zfar))
    cam.local.position = tuple(camera.position)
    cam.look_at(tuple(camera.target))
    device = renderer.device
    fence = device.create_buffer(size=16, usage=wgpu.BufferUsage.COPY_SRC
                                 | wgpu.BufferUsage.COPY_DST, label="peer:fence")

    def frame() -> None:
        renderer.render(scene, cam, flush=True)
        device.queue.read_buffer(fence)  # returns once the queue's work is done

    canvas.request_draw(lambda: renderer.render(scene, cam))
    wall = time_frames(frame, frames=frames, warmup=warmup)
    image = np.asarray(canvas.draw())[..., :3]
    info = device.adapter.info
    return {"frame_ms": wall, "timing": "wall: render + flush + queue read",
            "image": np.ascontiguousarray(image), "version": f"pygfx {gfx.__version__}",
            "device": f"{info['device']} ({info['description']})"}
