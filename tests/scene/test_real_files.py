"""What real files need, on small files made here and run through the CLI: triangles seen
from behind in mesh files, points and lines among triangles, and one warning line for each
thing a file holds that is not drawn as it means (skins, morphs, a missing
TEXCOORD set, unknown extensions); KHR_texture_transform, TEXCOORD_1 and COLOR_0 read."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.scene import SceneError, load_gltf, load_meshfile
from rfw.scene.model import Material, Mesh, Scene
from rfw.scene.sides import back_faced, closed_outward, with_back_faces

from ..cli.warm import warm_cli
from .test_gltf import PIXELS, QUAD_IDX, QUAD_POS, QUAD_UV, Gltf, png

ROOT = Path(__file__).resolve().parents[2]
BACK_IDX = np.array([0, 2, 1, 0, 3, 2])  # the quad wound clockwise: its front faces -z


def run(scene: Path, out: Path, backend: str = "wgpu") -> tuple[int, list[str], int]:
    """``rfw run configs/flat.toml --scene SCENE`` at 32x32: exit code, stderr lines and the
    pixels covered (the flat pass clears to black)."""
    p = warm_cli("run", "configs/flat.toml", "--scene", scene, "--size", "32x32", "--frames", "1",
                 "--out", out, "--backend", backend, cwd=ROOT)
    assert "Traceback" not in p.stderr, p.stderr
    covered = -1
    if p.returncode == 0:
        rgb = np.asarray(Image.open(out / "flat.color.png").convert("RGB"), int)
        covered = int((rgb.sum(axis=-1) > 0).sum())
    return p.returncode, p.stderr.splitlines(), covered


def quad(idx=QUAD_IDX, **material) -> Gltf:
    g = Gltf()
    if material:
        g.doc["materials"] = [material]
        g.node(mesh=g.mesh(g.primitive(idx=idx, material=0)))
    else:
        g.node(mesh=g.mesh(g.primitive(idx=idx)))
    return g


# ---------------------------------------------------------------------------------------------
# sides


def test_mesh_file_triangle_seen_from_behind_renders(tmp_path):
    obj = tmp_path / "back.obj"
    obj.write_text("v 0 0 0\nv 0 1 0\nv 1 0 0\nf 1 2 3\n")  # front faces -z, camera on +z
    code, err, covered = run(obj, tmp_path / "out")
    assert (code, err) == (0, []) and covered > 50
    # control: the same triangle as glTF, single-sided, is culled away
    g = quad(idx=BACK_IDX, doubleSided=False)
    code, _, covered = run(g.write(tmp_path, "single.gltf"), tmp_path / "single")
    assert (code, covered) == (0, 0)
    g = quad(idx=BACK_IDX, doubleSided=True)
    code, _, covered = run(g.write(tmp_path, "double.gltf"), tmp_path / "double")
    assert code == 0 and covered > 50


def test_back_faces_are_the_same_on_both_backends(tmp_path):
    g = quad(idx=BACK_IDX, doubleSided=True)
    path = g.write(tmp_path)
    _, _, covered = run(path, tmp_path / "wgpu", "wgpu")
    _, _, covered_vk = run(path, tmp_path / "vk", "vk")
    assert covered == covered_vk > 50
    a, b = (np.asarray(Image.open(tmp_path / k / "flat.color.png")) for k in ("wgpu", "vk"))
    np.testing.assert_array_equal(a, b)


CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
# outward (counter-clockwise seen from outside) triangles of the unit cube
CUBE_F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def test_closed_outward():
    assert closed_outward(CUBE_V, CUBE_F)
    assert not closed_outward(CUBE_V, CUBE_F[:, ::-1])  # wound inward
    assert not closed_outward(CUBE_V, CUBE_F[1:])  # a hole
    flipped = CUBE_F.copy()
    flipped[0] = flipped[0, ::-1]
    assert not closed_outward(CUBE_V, flipped)  # one triangle wound against the rest
    # a seam: the same corner twice in the vertex list still closes
    v = np.vstack([CUBE_V, CUBE_V[:1]])
    f = CUBE_F.copy()
    f[0, 0] = 8
    assert closed_outward(v, f)


def test_mesh_files_are_single_sided_only_when_closed_outward(tmp_path):
    def obj(faces) -> Path:
        path = tmp_path / f"m{len(faces)}.obj"
        path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_V)
                        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
        return path

    def sided(path: Path) -> bool:
        scene = load_meshfile(path)
        return scene.materials[scene.meshes[0].material].double_sided

    assert not sided(obj(CUBE_F))
    assert sided(obj(CUBE_F[1:]))


def test_with_back_faces():
    tri = Mesh("t", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
               np.tile(np.float32([0, 0, 1]), (3, 1)), np.zeros((3, 2), np.float32),
               np.tile(np.float32([1, 0, 0, 1]), (3, 1)), np.array([0, 1, 2], np.uint32))
    single = Scene("s", meshes=[tri], materials=[Material()])
    assert with_back_faces(single) is single  # nothing double-sided: the scene as it was
    double = Scene("d", meshes=[tri], materials=[Material(double_sided=True)])
    out = with_back_faces(double)
    mesh = out.meshes[0]
    assert mesh.indices.tolist() == [0, 1, 2, 3, 5, 4]
    assert mesh.normals[3:].tolist() == [[0, 0, -1]] * 3
    assert mesh.tangents[3:, 3].tolist() == [-1] * 3
    assert not out.materials[0].double_sided
    assert with_back_faces(out) is out  # twice changes nothing
    assert len(back_faced(tri).positions) == 6


# ---------------------------------------------------------------------------------------------
# points and lines


def test_points_among_triangles_are_read_without_a_warning(tmp_path):
    # drawn by the points_lines pass (tests/scene/test_strokes.py); a file that held them
    # was refused whole, then had them skipped with a warning
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(), g.primitive(idx=None, mode=0),
                       g.primitive(idx=None, mode=0)))
    code, err, covered = run(g.write(tmp_path), tmp_path / "out")
    assert (code, err) == (0, []) and covered > 50


# ---------------------------------------------------------------------------------------------
# warnings for what is not read


def textured(g: Gltf, tmp_path: Path, **info) -> None:
    (tmp_path / "t.png").write_bytes(png(PIXELS))
    g.doc["images"] = [{"uri": "t.png"}]
    g.doc["textures"] = [{"source": 0}]
    g.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0,
                                                                         **info}}}]


def test_textured_primitive_without_texcoord_warns_once(tmp_path):
    g = Gltf()
    textured(g, tmp_path)
    g.node(mesh=g.mesh(g.primitive(uv=None, material=0)))
    code, err, _ = run(g.write(tmp_path), tmp_path / "out")
    assert code == 0 and len(err) == 1, err
    assert "meshes[0].primitives[0]: has no TEXCOORD_0, which the textures of materials[0] " \
           "use: they are sampled at (0, 0)" in err[0]
    g = Gltf()  # control: with TEXCOORD_0, nothing to say
    textured(g, tmp_path)
    g.node(mesh=g.mesh(g.primitive(material=0)))
    assert run(g.write(tmp_path, "uv.gltf"), tmp_path / "uv")[:2] == (0, [])


@pytest.mark.parametrize("what,expected", [
    ("skin", "nodes[0]: skins not read: skinned meshes are drawn unposed"),
    ("morph", "meshes[0].primitives[0]: morph targets not read"),
    ("extension", "extensionsUsed: EXT_made_up ignored"),
])
def test_unread_features_warn_once(tmp_path, capfd, what, expected):
    g = Gltf()
    target = {"POSITION": g.accessor(QUAD_POS * 0)}
    prim = g.primitive(**({"targets": [target]} if what == "morph" else {}))
    node = {"mesh": g.mesh(prim)}
    if what == "skin":
        g.doc["skins"] = [{"joints": [1]}]
        node["skin"] = 0
    g.node(**node)
    if what == "skin":
        g.node(root=False)
    if what == "extension":
        g.doc["extensionsUsed"] = ["EXT_made_up"]
    path = g.write(tmp_path)
    load_gltf(path)
    load_gltf(path)  # a second load of the same file in one process says nothing more
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("rfw: warning: ") and expected in err[0], err


# ---------------------------------------------------------------------------------------------
# texture coordinates and colours


def test_texture_transform_is_applied_to_the_uvs(tmp_path):
    g = Gltf()
    textured(g, tmp_path, extensions={"KHR_texture_transform": {
        "offset": [0.5, 0.25], "scale": [2, 3], "rotation": np.pi / 2}})
    g.doc["extensionsUsed"] = ["KHR_texture_transform"]
    g.node(mesh=g.mesh(g.primitive(material=0)))
    uv = load_gltf(g.write(tmp_path)).meshes[0].uvs
    # rotation by pi/2: (u, v) -> (v, -u) before the offset, after the scale
    expected = np.column_stack([3 * QUAD_UV[:, 1] + 0.5, -2 * QUAD_UV[:, 0] + 0.25])
    np.testing.assert_allclose(uv, expected, atol=1e-6)
    g.doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].pop("extensions")
    np.testing.assert_array_equal(load_gltf(g.write(tmp_path, "plain.gltf")).meshes[0].uvs,
                                  QUAD_UV)  # control


def test_texcoord_1_is_read_when_the_textures_use_it(tmp_path):
    g = Gltf()
    textured(g, tmp_path, texCoord=1)
    prim = g.primitive(material=0)
    prim["attributes"]["TEXCOORD_1"] = g.accessor(QUAD_UV * 0.5)
    g.node(mesh=g.mesh(prim))
    np.testing.assert_array_equal(load_gltf(g.write(tmp_path)).meshes[0].uvs, QUAD_UV * 0.5)


def test_textures_on_two_uv_sets_warn(tmp_path, capfd):
    g = Gltf()
    textured(g, tmp_path)
    g.doc["materials"][0]["occlusionTexture"] = {"index": 0, "texCoord": 1}
    prim = g.primitive(material=0)
    prim["attributes"]["TEXCOORD_1"] = g.accessor(QUAD_UV * 0.5)
    g.node(mesh=g.mesh(prim))
    scene = load_gltf(g.write(tmp_path))
    np.testing.assert_array_equal(scene.meshes[0].uvs, QUAD_UV)  # the base colour's set
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and "materials[0].occlusionTexture uses other texture coordinates " \
        "than materials[0].baseColorTexture" in err[0], err


def test_constant_vertex_colour_tints_the_material(tmp_path, capfd):
    g = Gltf()
    g.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 1, 1]}}]
    prim = g.primitive(material=0)
    prim["attributes"]["COLOR_0"] = g.accessor(np.tile(np.float32([0.5, 1, 0.25]), (4, 1)))
    other = g.primitive(material=0)  # the same material without colours stays as it was
    g.node(mesh=g.mesh(prim, other))
    scene = load_gltf(g.write(tmp_path))
    tinted, plain = (scene.materials[m.material] for m in scene.meshes)
    assert tinted.base_color == (0.5, 0.5, 0.25, 1.0) and plain.base_color == (1, 0.5, 1, 1)
    assert capfd.readouterr().err == ""
    # varying colours: their mean, and one line saying so
    g = Gltf()
    prim = g.primitive()
    colors = np.array([[0, 0, 0, 255], [255, 255, 255, 255]] * 2, np.uint8)
    prim["attributes"]["COLOR_0"] = g.accessor(colors, 5121, normalized=True)
    g.node(mesh=g.mesh(prim))
    scene = load_gltf(g.write(tmp_path, "varying.gltf"))
    assert scene.materials[scene.meshes[0].material].base_color == (0.5, 0.5, 0.5, 1.0)
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and "COLOR_0 varies per vertex; drawn with its mean" in err[0]


def test_runner_summary_is_json_lines(tmp_path):
    """benchmarks/real_files.py over a folder of one OBJ and one glTF with points."""
    root = tmp_path / "models"
    root.mkdir()
    (root / "back.obj").write_text("v 0 0 0\nv 0 1 0\nv 1 0 0\nf 1 2 3\n")
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(), g.primitive(idx=None, mode=0)))
    g.write(root, "points.gltf")
    (root / "old.gltf").write_text(json.dumps({"asset": {"version": "1.0"}}))
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "benchmarks/real_files.py", "--root", str(root),
                        "--out", str(out), "--backends", "wgpu"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rows = {r["file"]: r for r in map(json.loads, (out / "real_files.jsonl").open())}
    assert rows["back.obj"]["verdict"] == "renders"
    assert rows["points.gltf"]["verdict"] == "renders"
    assert rows["points.gltf"]["backends"]["wgpu"]["warnings"] == []
    assert rows["old.gltf"]["skipped"].startswith("glTF 1.0")
    summary = json.loads((out / "summary.json").read_text())
    # no validator given: the glTF file is judged by nothing, like the mesh file
    assert summary["counts"] == {"renders (mesh file)": 2, "skipped (not glTF 2.0)": 1}


def test_draco_primitive_is_decoded(tmp_path):
    import DracoPy

    pos = QUAD_POS.astype(np.float32)
    blob = DracoPy.encode(pos, QUAD_IDX.reshape(-1, 3), quantization_bits=14)
    g = Gltf()
    view = g.view(bytes(blob))
    acc = len(g.doc["accessors"])
    g.doc["accessors"] += [{"componentType": 5126, "count": 4, "type": "VEC3"},
                           {"componentType": 5123, "count": 6, "type": "SCALAR"}]
    g.doc["extensionsUsed"] = g.doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    g.node(mesh=g.mesh({"attributes": {"POSITION": acc}, "indices": acc + 1, "extensions": {
        "KHR_draco_mesh_compression": {"bufferView": view, "attributes": {"POSITION": 0}}}}))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    assert mesh.triangle_count == 2
    # the decoder may reorder vertices: the same corners, within the quantization
    np.testing.assert_allclose(np.sort(mesh.positions[mesh.indices], axis=0),
                               np.sort(pos[QUAD_IDX], axis=0), atol=1e-3)
    # control: broken Draco bytes are one SceneError naming the element
    start = g.doc["bufferViews"][view]["byteOffset"]
    g.bin[start:start + 8] = b"\0" * 8
    with pytest.raises(SceneError, match="KHR_draco_mesh_compression: cannot decode"):
        load_gltf(g.write(tmp_path, "broken.gltf"))
