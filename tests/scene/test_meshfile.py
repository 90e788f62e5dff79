"""OBJ, PLY, STL and OFF through trimesh, on tiny files written by the tests."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import trimesh
from PIL import Image

from rfw.scene import SceneError, load_meshfile, load_scene
from rfw.scene.meshfile import _Converter

QUAD_OBJ = """\
mtllib quad.mtl
o quad
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl red
f 1/1/1 2/2/1 3/3/1
usemtl textured
f 1/1/1 3/3/1 4/4/1
"""

QUAD_MTL = """\
newmtl red
Kd 1 0 0
Ns 100
newmtl textured
Kd 1 1 1
map_Kd tex.png
"""

TEX = np.array([[[255, 0, 0, 255], [0, 255, 0, 255]],
                [[0, 0, 255, 255], [255, 255, 255, 255]]], np.uint8)


def write_obj(folder):
    (folder / "quad.obj").write_text(QUAD_OBJ)
    (folder / "quad.mtl").write_text(QUAD_MTL)
    Image.fromarray(TEX, "RGBA").save(folder / "tex.png")
    return folder / "quad.obj"


def check_mesh(mesh) -> None:
    assert mesh.positions.dtype == np.float32 and mesh.indices.dtype == np.uint32
    assert int(mesh.indices.max()) < len(mesh.positions)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(mesh.tangents[:, :3], axis=1), 1, atol=1e-5)
    assert set(np.unique(mesh.tangents[:, 3])) <= {-1.0, 1.0}
    for a in (mesh.positions, mesh.normals, mesh.uvs, mesh.tangents, mesh.indices):
        assert a.flags.c_contiguous


def test_obj_with_materials_and_texture(tmp_path):
    scene = load_scene(write_obj(tmp_path))
    assert len(scene.meshes) == 2 and len(scene.instances) == 2
    by_material = {scene.materials[m.material].name: m for m in scene.meshes}
    assert set(by_material) == {"red", "textured"}
    red = scene.materials[by_material["red"].material]
    assert red.base_color == (1.0, 0.0, 0.0, 1.0)  # sRGB 1 and 0 are linear 1 and 0
    assert red.base_color_texture is None
    assert red.roughness == pytest.approx((2 / 102) ** 0.25)
    textured = scene.materials[by_material["textured"].material]
    tex = scene.textures[textured.base_color_texture]
    assert tex.srgb
    np.testing.assert_array_equal(tex.pixels, TEX)
    for mesh in scene.meshes:
        check_mesh(mesh)
        np.testing.assert_allclose(mesh.normals, np.tile([0, 0, 1], (len(mesh.normals), 1)),
                                   atol=1e-6)
        # OBJ's v points up; the model's (glTF's) points down the image
        for p, uv in zip(mesh.positions, mesh.uvs, strict=True):
            np.testing.assert_allclose(uv, [p[0], 1 - p[1]], atol=1e-6)
        np.testing.assert_allclose(mesh.tangents[:, :3],
                                   np.tile([1, 0, 0], (len(mesh.tangents), 1)), atol=1e-5)
    lo, hi = scene.bounds()
    np.testing.assert_allclose(lo, [0, 0, 0])
    np.testing.assert_allclose(hi, [1, 1, 0])


def test_ply_with_vertex_colours(tmp_path):
    path = tmp_path / "tri.ply"
    path.write_text("\n".join([
        "ply", "format ascii 1.0", "element vertex 3", "property float x", "property float y",
        "property float z", "property uchar red", "property uchar green", "property uchar blue",
        "element face 1", "property list uchar int vertex_indices", "end_header",
        "0 0 0 255 0 0", "1 0 0 255 0 0", "0 1 0 255 0 0", "3 0 1 2", ""]))
    scene = load_scene(path)
    (mesh,) = scene.meshes
    check_mesh(mesh)
    assert mesh.triangle_count == 1
    assert scene.materials[mesh.material].base_color == pytest.approx((1, 0, 0, 1))
    np.testing.assert_array_equal(mesh.uvs, np.zeros((3, 2)))


def test_binary_stl(tmp_path):
    tris = [((0, 0, 1), [(0, 0, 0), (1, 0, 0), (0, 1, 0)]),
            ((0, 0, 1), [(1, 0, 0), (1, 1, 0), (0, 1, 0)])]
    body = b"".join(struct.pack("<12fH", *n, *np.ravel(v), 0) for n, v in tris)
    path = tmp_path / "two.stl"
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(tris)) + body)
    scene = load_scene(path)
    assert scene.triangle_count == 2
    check_mesh(scene.meshes[0])
    np.testing.assert_allclose(scene.meshes[0].normals[:, 2], 1, atol=1e-6)


def test_off(tmp_path):
    path = tmp_path / "tet.off"
    path.write_text("OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                    "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
    scene = load_scene(path)
    (mesh,) = scene.meshes
    assert mesh.triangle_count == 4
    check_mesh(mesh)
    # closed and outward: normals point away from the centroid
    centre = mesh.positions.mean(axis=0)
    assert np.all(np.sum((mesh.positions - centre) * mesh.normals, axis=1) > 0)


def test_scene_graph_instances():
    box = trimesh.creation.box()
    graph = trimesh.Scene()
    graph.add_geometry(box, geom_name="box", node_name="a",
                       transform=trimesh.transformations.translation_matrix([3, 0, 0]))
    graph.graph.update(frame_to="b", geometry="box",
                       matrix=trimesh.transformations.translation_matrix([0, 0, -3]))
    scene = _Converter("mem.glb", "mem").convert(graph)
    assert len(scene.meshes) == 1 and len(scene.instances) == 2
    offsets = sorted(tuple(i.transform[:3, 3]) for i in scene.instances)
    assert offsets == [(0, 0, -3), (3, 0, 0)]
    check_mesh(scene.meshes[0])


@pytest.mark.parametrize(("name", "data", "message"), [
    ("missing.obj", None, "missing.obj: file not found"),
    ("garbage.obj", b"this is not\x00 an obj\n", "garbage.obj: no triangles"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n",
     "bad.ply: cannot read it as a mesh"),
    ("empty.stl", b"", "empty.stl"),
    ("points.off", b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "points.off"),
])
def test_broken_files_raise_scene_error(tmp_path, name, data, message):
    path = tmp_path / name
    if data is not None:
        path.write_bytes(data)
    with pytest.raises(SceneError, match=message.replace(".", r"\.")):
        load_meshfile(path)


def test_directory_is_refused(tmp_path):
    (tmp_path / "dir.obj").mkdir()
    with pytest.raises(SceneError, match=r"dir\.obj: not a file"):
        load_scene(tmp_path / "dir.obj")


def test_ply_normals_from_the_file_are_kept(tmp_path):
    path = tmp_path / "n.ply"
    path.write_text("\n".join([
        "ply", "format ascii 1.0", "element vertex 3", *(f"property float {c}" for c in
                                                        ("x", "y", "z", "nx", "ny", "nz")),
        "element face 1", "property list uchar int vertex_indices", "end_header",
        "0 0 0 0 0.6 0.8", "1 0 0 0 0 1", "0 1 0 0 0 1", "3 0 1 2", ""]))
    mesh = load_scene(path).meshes[0]
    np.testing.assert_allclose(mesh.normals, [[0, 0.6, 0.8], [0, 0, 1], [0, 0, 1]], atol=1e-6)
