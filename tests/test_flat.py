"""The ``flat`` technique (passes/flat): analytic colours on the tiny scene, and its setting
checked where it enters.

Every face of the tiny scene's boxes has its own vertices and one normal, so Gouraud shading
paints each face one colour: ``base * (ambient + (1 - ambient) * max(n.l, 0))`` in linear
8-bit levels, with ``l`` towards the scene's sun. Every pixel is one of those colours or the
black background (within one level: the interpolation of equal values may round either way).
"""

from __future__ import annotations

import numpy as np

from .cli.warm import warm_cli
from .conftest import ROOT, tiny_scene
from .test_golden import config, rgb

NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)


def face_colors(ambient: float = 0.25) -> np.ndarray:
    """(K, 3) levels: the background, then every (material, face normal) of the tiny scene."""
    scene = tiny_scene()
    sun = next(li for li in scene.lights if li.kind == "directional")
    to_sun = -np.asarray(sun.direction, float) / np.linalg.norm(sun.direction)
    light = ambient + (1 - ambient) * np.clip(NORMALS @ to_sun, 0, None)
    bases = np.array([m.base_color[:3] for m in scene.materials], float)
    levels = (bases[:, None, :] * light[None, :, None]).reshape(-1, 3) * 255
    return np.vstack([np.zeros(3), levels])


def unexplained(image: np.ndarray, colors: np.ndarray) -> float:
    """The share of pixels more than one level from every colour in ``colors``."""
    d = np.abs(image.reshape(-1, 1, 3).astype(float) - colors[None]).max(-1)
    return float((d.min(-1) > 1.0).mean())


def test_every_pixel_is_an_analytic_face_colour(renders):
    image = rgb(renders(config("flat"), "tiny"))
    colors = face_colors()
    assert unexplained(image, colors) == 0.0
    # the floor's top and the cube's three faces towards the camera (+x, +y, +z) all show
    counts = [(np.abs(image.reshape(-1, 3) - c).max(-1) <= 1).sum() for c in colors]
    floor_top, cube = 1 + 2, 1 + 6
    assert counts[floor_top] > 1000
    assert all(counts[cube + k] > 20 for k in (0, 2, 4)), counts


def test_other_ambient_is_not_explained(renders):
    # negative control: the colours of ambient 0.3 do not explain the ambient 0.25 image,
    # and the ambient setting reaches the shader
    image = rgb(renders(config("flat"), "tiny"))
    assert unexplained(image, face_colors(0.3)) > 0.5
    brighter = rgb(renders(config("flat", "flat.ambient=0.3"), "tiny"))
    assert unexplained(brighter, face_colors(0.3)) == 0.0


def test_ambient_out_of_range_is_one_line(tmp_path):
    done = warm_cli("run", "configs/flat.toml", "--size", "32x18", "--set", "flat.ambient=1.5",
                    "--out", tmp_path, cwd=ROOT)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("rfw: error: ") and "ambient" in lines[0]
    assert "Traceback" not in done.stderr
