"""``rfw meshlets show``: a mesh's meshlets in a pyvista window (or a PNG).

Each meshlet gets its own colour (cell data ``meshlet``: the meshlet id of every triangle),
its bounding sphere is drawn as a translucent wireframe, and meshlets with a useful normal
cone (``cone_cutoff < 1``) get an arrow from ``cone_apex`` along ``cone_axis``, as long as
0.8 times the bounding radius. ``--screenshot`` renders off screen, writes the PNG and exits.

The mesh is any file ``rfw.scene.load_scene`` reads (every instance's mesh, placed by its
transform, merged into one), ``default`` (the courtyard's fountain) or ``default:NAME`` (the
courtyard mesh of that name, e.g. ``default:column``).
``python -m rfw.meshlet_view`` runs the command (see ``__main__``).
"""

from __future__ import annotations

import argparse
import colorsys
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RfwError
from ..meshlets import Meshlets, build_meshlets

DEFAULT_MESH = "fountain"
CONE_LENGTH = 0.8  # arrow length in bounding radii


def load_mesh(spec: Any) -> tuple[np.ndarray, np.ndarray, str]:
    """``(positions (V, 3) float32, indices (T*3,) uint32, name)`` of what ``show`` draws.

    ``spec`` is a path, ``"default"``/``"default:NAME"``, an ``rfw.scene.Mesh`` or a
    ``(positions, indices)`` pair.
    """
    if isinstance(spec, tuple) and len(spec) == 2:
        positions, indices = spec
        return (np.asarray(positions, np.float32).reshape(-1, 3),
                np.asarray(indices, np.uint32).reshape(-1), "mesh")
    if hasattr(spec, "positions") and hasattr(spec, "indices"):
        return (np.asarray(spec.positions, np.float32), np.asarray(spec.indices, np.uint32),
                getattr(spec, "name", "mesh"))
    text = str(spec)
    if text == "default" or text.startswith("default:"):
        from ..scene import default_scene

        name = text.partition(":")[2] or DEFAULT_MESH
        meshes = default_scene().meshes
        for m in meshes:
            if m.name == name:
                return m.positions, m.indices.astype(np.uint32), f"courtyard {name}"
        names = ", ".join(sorted({m.name for m in meshes}))
        raise ValueError(f"the courtyard has no mesh '{name}' (it has: {names})")
    from ..scene import load_scene

    scene = load_scene(text)
    placed = [(scene.meshes[i.mesh], np.asarray(i.transform, np.float64))
              for i in scene.instances] or [(m, np.eye(4)) for m in scene.meshes]
    placed = [(m, t) for m, t in placed if len(m.indices)]
    if not placed:
        raise ValueError(f"{text}: no triangles")
    positions, indices, base = [], [], 0
    for mesh, transform in placed:
        p = np.asarray(mesh.positions, np.float64)
        positions.append(p @ transform[:3, :3].T + transform[:3, 3])
        indices.append(np.asarray(mesh.indices, np.int64) + base)
        base += len(p)
    return (np.concatenate(positions).astype(np.float32),
            np.concatenate(indices).astype(np.uint32), Path(text).name)


def triangle_meshlet_ids(meshlets: Meshlets, indices: np.ndarray) -> np.ndarray:
    """The meshlet of every triangle of ``indices``, (T,) int64; -1 where none holds it.

    Triangles are matched by their vertex indices up to rotation (winding kept); repeated
    triangles are handed out in order, so each meshlet triangle is used at most once.
    """
    tris = np.asarray(indices, np.int64).reshape(-1, 3)
    ids = np.full(len(tris), -1, np.int64)
    counts = meshlets.meshlets[:, 3].astype(np.int64)
    owner = np.repeat(np.arange(len(counts)), counts)
    ours = meshlets.triangle_indices().astype(np.int64).reshape(-1, 3)
    if not len(tris) or not len(ours):
        return ids

    def canonical(t: np.ndarray) -> np.ndarray:
        rolled = np.stack([np.roll(t, -k, axis=1) for k in range(3)])  # (3, T, 3)
        first = np.argmin(t, axis=1)
        return rolled[first, np.arange(len(t))]

    a, b = canonical(tris), canonical(ours)
    order_a = np.lexsort(a.T[::-1])
    order_b = np.lexsort(b.T[::-1])
    a_sorted, b_sorted = a[order_a], b[order_b]
    if len(a) == len(b) and np.array_equal(a_sorted, b_sorted):
        ids[order_a] = owner[order_b]  # the usual case: a bijection
        return ids
    pool: dict[tuple[int, int, int], list[int]] = {}
    for key, m in zip(map(tuple, b.tolist()), owner.tolist(), strict=True):
        pool.setdefault(key, []).append(m)
    for i, key in enumerate(map(tuple, a.tolist())):
        got = pool.get(key)
        if got:
            ids[i] = got.pop(0)
    return ids


def meshlet_colors(count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) uint8: well-separated hues (golden-ratio steps) in varied lightness."""
    out = np.empty((count, 3), np.uint8)
    for i in range(count):
        h = (seed * 0.1 + i * 0.618033988749895) % 1.0
        s = (0.55, 0.85, 0.7)[i % 3]
        v = (0.95, 0.75, 0.85, 0.65)[(i // 3) % 4]
        out[i] = np.round(np.array(colorsys.hsv_to_rgb(h, s, v)) * 255)
    return out


def _polydata(positions: np.ndarray, indices: np.ndarray):
    import pyvista as pv

    tris = indices.reshape(-1, 3).astype(np.int64)
    faces = np.hstack([np.full((len(tris), 1), 3, np.int64), tris]).reshape(-1)
    return pv.PolyData(positions.astype(np.float64), faces)


def build_scene(positions: np.ndarray, indices: np.ndarray, meshlets: Meshlets) -> dict:
    """The pyvista datasets ``show`` draws: ``mesh`` (cell data ``meshlet`` and ``colors``),
    ``spheres`` (merged wireframe spheres) and ``cones`` (arrow glyphs; None if no cone)."""
    import pyvista as pv

    mesh = _polydata(positions, indices)
    ids = triangle_meshlet_ids(meshlets, indices)
    palette = np.vstack([meshlet_colors(len(meshlets)), [[128, 128, 128]]]).astype(np.uint8)
    mesh.cell_data["meshlet"] = ids
    mesh.cell_data["colors"] = palette[ids]  # -1 (in no meshlet) picks the grey last row
    b = meshlets.bounds
    spheres = None
    if len(meshlets):
        unit = pv.Sphere(radius=1.0, theta_resolution=12, phi_resolution=8)
        parts = [unit.scale(float(r), inplace=False).translate(c.astype(np.float64),
                                                              inplace=False)
                 for c, r in zip(b.center, b.radius, strict=True)]
        spheres = pv.merge(parts) if len(parts) > 1 else parts[0]
    cones = None
    useful = b.cone_cutoff < 1.0
    if useful.any():
        points = pv.PolyData(b.cone_apex[useful].astype(np.float64))
        points["axis"] = b.cone_axis[useful].astype(np.float64)
        points["length"] = CONE_LENGTH * b.radius[useful].astype(np.float64)
        cones = points.glyph(orient="axis", scale="length", factor=1.0,
                             geom=pv.Arrow(tip_length=0.25, tip_radius=0.07, shaft_radius=0.025))
    return {"mesh": mesh, "spheres": spheres, "cones": cones, "ids": ids}


def show(mesh: Any, *, max_vertices: int = 64, max_triangles: int = 124,
         cone_weight: float = 0.25, screenshot: str | Path | None = None,
         size: tuple[int, int] = (1024, 768), spheres: bool = True,
         cones: bool = True) -> Path | None:
    """Draw ``mesh``'s meshlets; with ``screenshot``, render off screen to that PNG instead
    of opening a window and return its path."""
    positions, indices, name = load_mesh(mesh)
    meshlets = build_meshlets(positions, indices, max_vertices=max_vertices,
                              max_triangles=max_triangles, cone_weight=cone_weight)
    import pyvista as pv

    data = build_scene(positions, indices, meshlets)
    off = screenshot is not None
    plotter = pv.Plotter(off_screen=off, window_size=list(size),
                         title=f"rfw meshlets: {name}")
    try:
        plotter.set_background("white")
        plotter.add_mesh(data["mesh"], scalars="colors", rgb=True, show_edges=False,
                         smooth_shading=False)
        if spheres and data["spheres"] is not None:
            plotter.add_mesh(data["spheres"], style="wireframe", color="#404040", opacity=0.12,
                             line_width=1)
        if cones and data["cones"] is not None:
            plotter.add_mesh(data["cones"], color="#202020")
        useful = int((meshlets.bounds.cone_cutoff < 1.0).sum())
        plotter.add_text(f"{name}: {len(indices) // 3} triangles, {len(meshlets)} meshlets "
                         f"(<= {max_vertices} vertices, <= {max_triangles} triangles, cone "
                         f"weight {cone_weight:g}); {useful} with a cone", font_size=9,
                         color="black")
        plotter.view_vector((1.0, 0.8, 1.3), viewup=(0.0, 1.0, 0.0))  # scenes are y-up
        plotter.reset_camera()
        if off:
            out = Path(screenshot)
            out.parent.mkdir(parents=True, exist_ok=True)
            plotter.screenshot(str(out))
            return out
        plotter.show()
        return None
    finally:
        plotter.close()


def _check_screenshot(path: str | None) -> None:
    # a bad target fails before meshlets are built and a renderer starts
    if path is None:
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise RfwError("no display for a window (use --screenshot PNG, or run under "
                           "xvfb-run -a)", element="meshlets show")
        return
    out = Path(path)
    if out.is_dir():
        raise RfwError("is a folder, not a PNG file", file=path, element="--screenshot")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RfwError(f"cannot make its folder ({e.strerror})", file=path,
                       element="--screenshot") from None


def cmd_show(args: argparse.Namespace) -> int:
    try:
        _check_screenshot(args.screenshot)
        out = show(args.mesh, max_vertices=args.max_vertices, max_triangles=args.max_triangles,
                   cone_weight=args.cone_weight, screenshot=args.screenshot,
                   size=tuple(getattr(args, "size", None) or (1024, 768)))
    except (ValueError, ImportError) as e:  # bad limits, SceneError, no meshoptimizer
        print(f"rfw: error: {e}", file=sys.stderr)
        return 2
    if out is not None:
        print(f"wrote {out}")
    return 0
