"""Points and lines (glTF modes 0 to 3): read into ``Scene.strokes`` with the segments each
mode means, and drawn one pixel wide and unlit by the ``points_lines`` pass, through the CLI
on both backends with identical images; triangles beside them are drawn as before."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.scene import SceneError, load_gltf

from ..cli.warm import warm_cli
from .test_gltf import PIXELS, QUAD_POS, Gltf, png

ROOT = Path(__file__).resolve().parents[2]
# a square beside the unit quad (x from 1.5 to 2.5), a little in front of it
SQUARE = QUAD_POS + np.float32([1.5, 0, 0.05])


@pytest.mark.parametrize("mode, indices", [
    (0, [0, 1, 2, 3]),
    (1, [0, 1, 2, 3]),
    (2, [0, 1, 1, 2, 2, 3, 3, 0]),  # LINE_LOOP closes
    (3, [0, 1, 1, 2, 2, 3]),  # LINE_STRIP does not
])
def test_modes_become_point_or_line_lists(tmp_path, mode, indices):
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(), g.primitive(pos=SQUARE, idx=[0, 1, 2, 3], uv=None,
                                                  mode=mode)))
    scene = load_gltf(g.write(tmp_path))
    assert len(scene.meshes) == 1 and len(scene.instances) == 1
    (stroke,) = scene.strokes
    assert stroke.topology == ("point-list" if mode == 0 else "line-list")
    assert stroke.indices.tolist() == indices
    assert stroke.colors.tolist() == [[1, 1, 1, 1]] * 4  # white without COLOR_0
    assert [i.mesh for i in scene.stroke_instances] == [0]
    # the bounds take the strokes in (the camera frames them)
    lo, hi = scene.bounds()
    assert lo.tolist() == [0, 0, 0] and np.allclose(hi, [2.5, 1, 0.05])


def test_color_0_is_kept_per_vertex_and_odd_lines_are_refused(tmp_path):
    g = Gltf()
    prim = g.primitive(pos=SQUARE, idx=None, uv=None, mode=1)
    colors = np.float32([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    prim["attributes"]["COLOR_0"] = g.accessor(colors)
    g.node(mesh=g.mesh(prim))
    (stroke,) = load_gltf(g.write(tmp_path)).strokes
    assert stroke.colors[:, :3].tolist() == colors.tolist() and stroke.colors[:, 3].min() == 1
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(pos=SQUARE, idx=[0, 1, 2], uv=None, mode=1)))
    with pytest.raises(SceneError, match=r"accessors\[1\].*3 indices is not a whole number "
                                         r"of lines"):
        load_gltf(g.write(tmp_path, "odd.gltf"))


def render(scene: Path, out: Path, backend: str, config: str = "configs/flat.toml",
           *sets: str) -> tuple[np.ndarray, list[str]]:
    args = [a for s in sets for a in ("--set", s)]
    p = warm_cli("run", config, "--scene", scene, "--size", "48x32", "--frames", "1", "--out", out,
                 "--backend", backend, *args, cwd=ROOT)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    png = next(out.glob("*.png"))
    return np.asarray(Image.open(png).convert("RGB")), p.stderr.splitlines()


def strokes_file(tmp_path: Path, *modes: int) -> Path:
    g = Gltf()
    g.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 1, 1]}}]
    prims = [g.primitive(material=0)]
    prims += [g.primitive(pos=SQUARE, idx=None, uv=None, mode=m, material=0) for m in modes]
    g.node(mesh=g.mesh(*prims))
    return g.write(tmp_path, f"strokes{''.join(map(str, modes))}.gltf")


def test_lines_and_points_among_triangles_are_drawn_alike_on_both_backends(tmp_path):
    scene = strokes_file(tmp_path, 0, 2)
    images = {}
    for backend in ("wgpu", "vk"):
        images[backend], err = render(scene, tmp_path / backend, backend)
        assert err == [], err  # read whole: no warning
    assert (images["wgpu"] == images["vk"]).all()
    rgb = images["wgpu"].astype(int)
    # control: the same scene (and camera) with the pass left out of the graph draws the
    # triangles only, the quad's half of the image
    (tmp_path / "tri.toml").write_text(
        (ROOT / "configs/flat.toml").read_text().split("# the scene's points")[0])
    none, _ = render(scene, tmp_path / "tri", "wgpu", str(tmp_path / "tri.toml"))
    drawn = np.any(rgb != none, axis=-1)
    assert 20 < drawn.sum() < 0.3 * drawn.size, drawn.sum()
    # the square's outline and corners in the material's colour, unlit (flat.color is
    # linear; the flat pass shades the quad grey)
    assert {tuple(c) for c in rgb[drawn]} == {(51, 102, 255)}
    assert drawn[:, : drawn.shape[1] // 2].sum() == 0

def test_only_lines_is_a_scene_with_something_drawable(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(pos=SQUARE, idx=None, uv=None, mode=3)))
    rgb, err = render(g.write(tmp_path), tmp_path / "out", "vk")
    assert err == [] and (rgb.sum(axis=-1) > 0).sum() > 20, err
    # control: an empty scene says nothing is drawable and draws nothing
    rgb, err = render(Gltf().write(tmp_path, "empty.gltf"), tmp_path / "empty", "vk")
    assert len(err) == 1 and "nothing is drawable" in err[0] and rgb.sum() == 0


def test_lit_configs_draw_strokes_over_the_shaded_image(tmp_path):
    scene = strokes_file(tmp_path, 1)
    lit = {}
    for backend in ("wgpu", "vk"):
        lit[backend], err = render(scene, tmp_path / backend, backend, "configs/deferred.toml")
        assert err == [], err
    assert (lit["wgpu"] == lit["vk"]).all()
    alone, _ = render(strokes_file(tmp_path), tmp_path / "alone", "wgpu",
                      "configs/deferred.toml")
    assert np.any(lit["wgpu"] != alone, axis=-1).sum() > 20


def test_textured_stroke_warns_once(tmp_path):
    g = Gltf()
    (tmp_path / "t.png").write_bytes(png(PIXELS))
    g.doc["images"] = [{"uri": "t.png"}]
    g.doc["textures"] = [{"source": 0}]
    g.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    g.node(mesh=g.mesh(g.primitive(pos=SQUARE, idx=None, mode=1, material=0)))
    _, err = render(g.write(tmp_path), tmp_path / "out", "wgpu")
    assert len(err) == 1 and "textures of points and lines not read" in err[0], err


PLY_POINTS = b"""ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
property uchar alpha
end_header
0 0 0 255 0 0 255
1 0 0 0 255 0 255
1 1 0 0 0 255 255
0 1 0 255 255 255 255
"""


def test_mesh_file_points_are_a_point_cloud_with_their_colours(tmp_path):
    from rfw.scene import load_meshfile
    (tmp_path / "p.ply").write_bytes(PLY_POINTS)
    scene = load_meshfile(tmp_path / "p.ply")
    (cloud,) = scene.strokes
    assert scene.meshes == [] and len(scene.stroke_instances) == 1
    assert cloud.topology == "point-list" and cloud.indices.tolist() == [0, 1, 2, 3]
    assert cloud.colors.tolist() == [[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 1, 1]]
    # an OBJ of vertices only is one too; a triangle whose NaN corner trimesh dropped is not
    (tmp_path / "p.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    assert load_meshfile(tmp_path / "p.obj").strokes[0].indices.tolist() == [0, 1, 2]
    (tmp_path / "n.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match="no triangles or points found"):
        load_meshfile(tmp_path / "n.obj")
    images = {}
    for backend in ("wgpu", "vk"):
        images[backend], err = render(tmp_path / "p.ply", tmp_path / backend, backend)
        assert err == [], err
    assert (images["wgpu"] == images["vk"]).all()
    lit = {tuple(c) for c in images["wgpu"].reshape(-1, 3) if c.any()}
    assert lit == {(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 255)}, lit
