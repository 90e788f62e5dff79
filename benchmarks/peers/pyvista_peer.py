"""pyvista/VTK off screen (VTK picks EGL without a display): rfw's ``flat`` technique as one
PolyData with per-vertex colours (``Geometry.shaded_colors``), lighting off, back faces
culled. Wall time of ``Render()`` plus
``WaitForCompletion()``; VTK has no per-frame GPU timer in its Python API."""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import Geometry, Unavailable, time_frames


def measure(geo: Geometry, camera: Any, width: int, height: int, *, frames: int,
            warmup: int) -> dict[str, Any]:
    try:
        import pyvista as pv
        import vtk
    except ImportError as e:
        raise Unavailable(f"pyvista/vtk is not installed ({e})") from None
    pv.OFF_SCREEN = True
    faces = np.hstack([np.full((geo.triangles, 1), 3, np.int64),
                       geo.indices.astype(np.int64)]).ravel()
    mesh = pv.PolyData(geo.positions.astype(np.float32), faces)
    mesh.point_data["rgb"] = (geo.shaded_colors() * 255 + 0.5).astype(np.uint8)
    try:
        p = pv.Plotter(off_screen=True, window_size=(width, height))
    except Exception as e:
        raise Unavailable(f"no off-screen render window: {e}") from None
    try:
        p.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False,
                   culling="back")
        # one sample per pixel, as rfw (pyvista's theme turns on 8x MSAA)
        p.disable_anti_aliasing()
        p.ren_win.SetMultiSamples(0)
        p.set_background("black")
        p.camera.position = tuple(camera.position)
        p.camera.focal_point = tuple(camera.target)
        p.camera.up = tuple(camera.up)
        p.camera.view_angle = float(np.degrees(camera.yfov))
        p.camera.clipping_range = (camera.znear, camera.zfar)
        p.show(auto_close=False)
        win = p.ren_win

        def frame() -> None:
            p.renderer.Modified()
            win.Render()
            win.WaitForCompletion()

        wall = time_frames(frame, frames=frames, warmup=warmup)
        image = p.screenshot(return_img=True)[..., :3]
        return {"frame_ms": wall, "timing": "wall: Render + WaitForCompletion",
                "image": np.ascontiguousarray(image), "version": f"pyvista {pv.__version__}, "
                f"vtk {vtk.vtkVersion.GetVTKVersion()}",
                "device": f"{win.GetClassName()}: " + _renderer(win)}
    finally:
        p.close()


def _renderer(win: Any) -> str:
    caps = win.ReportCapabilities() or ""
    for line in caps.splitlines():
        if "renderer" in line.lower() and "opengl" in line.lower():
            return line.split(":", 1)[-1].strip()
    return "unknown renderer"
