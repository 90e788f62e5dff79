"""rfw.meshlet_view: per-triangle meshlet ids and an off-screen screenshot of a sphere."""

from __future__ import annotations

import colorsys
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pytest.importorskip("meshoptimizer")
Image = pytest.importorskip("PIL.Image")

from rfw.meshlet_view import load_mesh, meshlet_colors, triangle_meshlet_ids  # noqa: E402
from rfw.meshlets import build_meshlets  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _sphere() -> tuple[np.ndarray, np.ndarray]:
    s = pv.Sphere(radius=1.0, theta_resolution=40, phi_resolution=24).triangulate()
    return s.points.astype(np.float32), s.faces.reshape(-1, 4)[:, 1:].astype(np.uint32)


def test_every_triangle_is_in_exactly_one_meshlet():
    positions, tris = _sphere()
    m = build_meshlets(positions, tris, max_vertices=32, max_triangles=32)
    ids = triangle_meshlet_ids(m, tris)
    assert len(ids) == len(tris)
    assert ids.min() == 0 and ids.max() == len(m) - 1  # every triangle placed
    # each meshlet owns exactly as many triangles as it holds: no triangle counted twice
    assert np.array_equal(np.bincount(ids, minlength=len(m)), m.meshlets[:, 3])
    # and the triangle given to a meshlet really is one of that meshlet's
    for k in (0, len(m) // 2, len(m) - 1):
        v_off, _, v_count, _ = m.meshlets[k]
        assert set(tris[ids == k].ravel()) <= set(m.vertices[v_off:v_off + v_count])


def test_ids_with_repeated_and_missing_triangles():
    positions, tris = _sphere()
    m = build_meshlets(positions, tris)
    extra = np.concatenate([tris, tris[:1], tris[:1, ::-1]])  # a repeat, a flipped copy
    ids = triangle_meshlet_ids(m, extra)
    assert (ids[:len(tris)] >= 0).all() and (ids[len(tris):] == -1).all()


def test_colors_are_distinct():
    c = meshlet_colors(64)
    assert len({tuple(x) for x in c}) == 64


def test_load_mesh_default_and_file(tmp_path):
    _, idx, name = load_mesh("default:column")
    assert name == "courtyard column" and len(idx) % 3 == 0 and len(idx)
    with pytest.raises(ValueError, match="no mesh 'nope'"):
        load_mesh("default:nope")


def _hues(rgb: np.ndarray) -> set[int]:
    px = rgb.reshape(-1, 3).astype(np.float64) / 255.0
    hsv = np.array([colorsys.rgb_to_hsv(*p) for p in px[:: max(1, len(px) // 20000)]])
    vivid = hsv[(hsv[:, 1] > 0.35) & (hsv[:, 2] > 0.25)]
    return set((vivid[:, 0] * 24).astype(int).tolist())


def test_screenshot_of_a_sphere(tmp_path):
    positions, tris = _sphere()
    mesh = tmp_path / "sphere.ply"
    pv.PolyData(positions.astype(np.float64),
                np.hstack([np.full((len(tris), 1), 3), tris]).ravel()).save(mesh)
    png = tmp_path / "shots" / "sphere.png"
    cmd = [sys.executable, "-m", "rfw.meshlet_view", str(mesh), "--max-vertices", "32",
           "--max-triangles", "32", "--screenshot", str(png), "--size", "320x240"]
    env = dict(os.environ)
    if shutil.which("xvfb-run"):  # VTK may want a display; off-screen EGL works without one
        env = {k: v for k, v in env.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        cmd = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", *cmd]
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"wrote {png}" in done.stdout
    with Image.open(png) as im:
        assert im.size == (320, 240)
        rgb = np.asarray(im.convert("RGB"))
    assert len(_hues(rgb)) >= 8  # meshlets in many colours, not one shaded sphere


def test_bad_limits_exit_2(tmp_path):
    done = subprocess.run([sys.executable, "-m", "rfw.meshlet_view", "default",
                           "--max-triangles", "30", "--screenshot", str(tmp_path / "x.png")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2
    assert "max_triangles must be a multiple of 4" in done.stderr
    assert not (tmp_path / "x.png").exists()
