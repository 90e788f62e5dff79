"""glTF loading on small files built in the test: exact transforms, attributes, materials,
and a SceneError naming file and element for every malformed case."""

from __future__ import annotations

import base64
import contextlib
import copy
import io
import json
import math
import os
import struct
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from rfw.scene import SceneError, load_gltf, load_scene
from rfw.scene.gltf import read_uri, split_glb

F32, U8, U16, U32, I8, I16 = 5126, 5121, 5123, 5125, 5120, 5122
DTYPES = {F32: "<f4", U8: "u1", U16: "<u2", U32: "<u4", I8: "i1", I16: "<i2"}

# a unit quad in the xy plane facing +z; uv (0,0) at the top-left as glTF expects
QUAD_POS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
QUAD_IDX = np.array([0, 1, 2, 0, 2, 3])


class Gltf:
    """Builds a glTF document and its binary buffer."""

    def __init__(self) -> None:
        self.doc: dict = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [],
                          "accessors": [], "meshes": [], "nodes": [],
                          "scenes": [{"nodes": []}], "scene": 0}
        self.bin = bytearray()

    def view(self, data: bytes, stride: int | None = None) -> int:
        self.bin.extend(b"\0" * (-len(self.bin) % 4))
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.bin.extend(data)
        self.doc["bufferViews"].append(v)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array, ctype: int = F32, normalized: bool = False,
                 view: int | None = None, offset: int = 0, count: int | None = None,
                 type_: str | None = None) -> int:
        a = np.asarray(array)
        if view is None:
            view = self.view(a.astype(DTYPES[ctype]).tobytes())
        comps = 1 if a.ndim == 1 else a.shape[1]
        acc = {"bufferView": view, "componentType": ctype,
               "count": len(a) if count is None else count,
               "type": type_ or {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[comps]}
        if offset:
            acc["byteOffset"] = offset
        if normalized:
            acc["normalized"] = True
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def primitive(self, pos=QUAD_POS, idx=QUAD_IDX, uv=QUAD_UV, index_type: int = U16,
                  **extra) -> dict:
        attrs = {"POSITION": self.accessor(pos)}
        if uv is not None:
            attrs["TEXCOORD_0"] = self.accessor(uv)
        p = {"attributes": attrs, **extra}
        if idx is not None:
            p["indices"] = self.accessor(np.asarray(idx), index_type)
        return p

    def mesh(self, *primitives: dict, name: str | None = None) -> int:
        m = {"primitives": list(primitives)}
        if name:
            m["name"] = name
        self.doc["meshes"].append(m)
        return len(self.doc["meshes"]) - 1

    def node(self, root: bool = True, **kw) -> int:
        self.doc["nodes"].append(kw)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def finish(self) -> None:
        self.bin.extend(b"\0" * (-len(self.bin) % 4))
        self.doc["buffers"] = [{"byteLength": len(self.bin)}]

    def write(self, folder: Path, name: str = "scene.gltf", embed: bool = False) -> Path:
        self.finish()
        doc = copy.deepcopy(self.doc)
        if embed:
            doc["buffers"][0]["uri"] = ("data:application/octet-stream;base64,"
                                        + base64.b64encode(bytes(self.bin)).decode())
        else:
            doc["buffers"][0]["uri"] = "scene.bin"
            (folder / "scene.bin").write_bytes(bytes(self.bin))
        path = folder / name
        path.write_text(json.dumps(doc))
        return path

    def glb(self, folder: Path, name: str = "scene.glb") -> Path:
        self.finish()
        text = json.dumps(self.doc).encode()
        text += b" " * (-len(text) % 4)
        body = struct.pack("<I4s", len(text), b"JSON") + text
        body += struct.pack("<I4s", len(self.bin), b"BIN\0") + bytes(self.bin)
        path = folder / name
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return path


def quad_scene() -> Gltf:
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive()))
    return g


def png(pixels: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(pixels, "RGBA").save(out, "PNG")
    return out.getvalue()


PIXELS = np.array([[[255, 0, 0, 255], [0, 255, 0, 128]],
                   [[0, 0, 255, 255], [10, 20, 30, 0]]], np.uint8)


# ---------------------------------------------------------------------------------------------
# geometry


def test_quad_normals_and_tangents_are_computed(tmp_path):
    scene = load_gltf(quad_scene().write(tmp_path))
    (mesh,) = scene.meshes
    assert mesh.positions.dtype == np.float32 and mesh.indices.dtype == np.uint32
    np.testing.assert_allclose(mesh.normals, np.tile([0, 0, 1], (4, 1)), atol=1e-6)
    # +U runs along +x; v runs down the image, so the bitangent cross(n, t) * w is +y
    np.testing.assert_allclose(mesh.tangents, np.tile([1, 0, 0, 1], (4, 1)), atol=1e-6)
    np.testing.assert_array_equal(mesh.uvs, QUAD_UV)
    assert mesh.indices.tolist() == QUAD_IDX.tolist()
    assert scene.instances[0].mesh == 0
    np.testing.assert_array_equal(scene.instances[0].transform, np.identity(4))


def test_mirrored_uvs_flip_the_tangent_sign(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(uv=QUAD_UV * [-1, 1])))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_allclose(mesh.tangents, np.tile([-1, 0, 0, -1], (4, 1)), atol=1e-6)


def test_tangents_without_uvs_are_an_orthonormal_frame(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(g.primitive(uv=None)))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_array_equal(mesh.uvs, np.zeros((4, 2)))
    t = mesh.tangents
    np.testing.assert_allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-6)
    np.testing.assert_allclose(np.sum(t[:, :3] * mesh.normals, axis=1), 0, atol=1e-6)
    assert set(t[:, 3]) <= {-1.0, 1.0}


def test_given_normals_and_tangents_are_kept(tmp_path):
    g = Gltf()
    p = g.primitive()
    p["attributes"]["NORMAL"] = g.accessor(np.tile([0, 0, 2.0], (4, 1)))  # unnormalised
    p["attributes"]["TANGENT"] = g.accessor(np.tile([0, 1, 0, -1.0], (4, 1)))
    g.node(mesh=g.mesh(p))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_allclose(mesh.normals, np.tile([0, 0, 1], (4, 1)))
    np.testing.assert_allclose(mesh.tangents, np.tile([0, 1, 0, -1], (4, 1)))


def rotation_y(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])


def translation(x, y, z) -> np.ndarray:
    m = np.identity(4)
    m[:3, 3] = (x, y, z)
    return m


def test_hierarchy_composes_trs_and_matrices(tmp_path):
    g = Gltf()
    mesh = g.mesh(g.primitive())
    leaf = g.node(root=False, mesh=mesh, translation=[0, 0, 1], scale=[3, 3, 3])
    child_matrix = translation(1, 0, 0)
    child = g.node(root=False, matrix=child_matrix.T.ravel().tolist(), children=[leaf],
                   mesh=mesh)
    s45 = math.sin(math.radians(45))
    g.node(translation=[10, 0, 0], rotation=[0, s45, 0, s45], scale=[2, 2, 2],
           children=[child])
    scene = load_gltf(g.write(tmp_path))
    root = translation(10, 0, 0) @ rotation_y(90) @ np.diag([2, 2, 2, 1])
    child_world = root @ child_matrix
    leaf_world = child_world @ translation(0, 0, 1) @ np.diag([3, 3, 3, 1])
    transforms = [i.transform for i in scene.instances]
    np.testing.assert_allclose(transforms[0], child_world, atol=1e-5)
    np.testing.assert_allclose(transforms[1], leaf_world, atol=1e-5)
    # a vertex, worked by hand: (1,0,0) -> child (2,0,0) -> scale 2 (4,0,0) -> rot (0,0,-4)
    world = transforms[0] @ [1, 0, 0, 1]
    np.testing.assert_allclose(world[:3], [10, 0, -4], atol=1e-5)
    lo, hi = scene.bounds()
    assert lo[0] == pytest.approx(10, abs=1e-5) and hi[1] == pytest.approx(6, abs=1e-5)


def test_scene_index_picks_the_scene(tmp_path):
    g = Gltf()
    mesh = g.mesh(g.primitive())
    g.node(mesh=mesh, translation=[1, 0, 0])
    g.node(root=False, mesh=mesh, translation=[5, 0, 0])
    g.doc["scenes"].append({"nodes": [1]})
    g.doc["scene"] = 1
    scene = load_gltf(g.write(tmp_path))
    assert [i.transform[0, 3] for i in scene.instances] == [5]
    del g.doc["scene"]  # without it: scenes[0]
    scene = load_gltf(g.write(tmp_path))
    assert [i.transform[0, 3] for i in scene.instances] == [1]


def test_no_scenes_shows_root_nodes(tmp_path):
    g = Gltf()
    mesh = g.mesh(g.primitive())
    child = g.node(root=False, mesh=mesh)
    g.node(mesh=mesh, children=[child])
    del g.doc["scenes"], g.doc["scene"]
    assert len(load_gltf(g.write(tmp_path)).instances) == 2


def test_primitives_become_meshes_shared_by_nodes(tmp_path):
    g = Gltf()
    g.doc["materials"] = [{"name": "a"}, {"name": "b"}]
    mesh = g.mesh(g.primitive(material=0), g.primitive(pos=QUAD_POS + 2, material=1),
                  name="pair")
    g.node(mesh=mesh)
    g.node(mesh=mesh, translation=[0, 5, 0])
    scene = load_gltf(g.write(tmp_path))
    assert [m.name for m in scene.meshes] == ["pair.0", "pair.1"]
    assert [i.mesh for i in scene.instances] == [0, 1, 0, 1]
    assert [scene.materials[m.material].name for m in scene.meshes] == ["a", "b"]
    assert scene.triangle_count == 8


@pytest.mark.parametrize("index_type", [U8, U16, U32, None])
def test_index_types_and_non_indexed(tmp_path, index_type):
    g = Gltf()
    if index_type is None:
        pos, idx = QUAD_POS[QUAD_IDX], None
        uv = QUAD_UV[QUAD_IDX]
    else:
        pos, idx, uv = QUAD_POS, QUAD_IDX, QUAD_UV
    g.node(mesh=g.mesh(g.primitive(pos, idx, uv, index_type=index_type or U16)))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    tris = mesh.positions[mesh.indices].reshape(-1, 3, 3)
    np.testing.assert_array_equal(tris, QUAD_POS[QUAD_IDX].reshape(-1, 3, 3))
    np.testing.assert_allclose(mesh.normals, np.tile([0, 0, 1], (len(mesh.positions), 1)),
                               atol=1e-6)


def test_normalized_and_quantized_attributes(tmp_path):
    g = Gltf()
    pos = (QUAD_POS * 100).astype(np.int16)  # KHR_mesh_quantization style, not normalised
    uv = (QUAD_UV * 65535).astype(np.uint16)
    normals = np.tile([0, 0, 127], (4, 1)).astype(np.int8)
    prim = {"attributes": {"POSITION": g.accessor(pos, I16),
                           "TEXCOORD_0": g.accessor(uv, U16, normalized=True),
                           "NORMAL": g.accessor(normals, I8, normalized=True)},
            "indices": g.accessor(QUAD_IDX, U8)}
    g.node(mesh=g.mesh(prim))
    g.doc["extensionsUsed"] = g.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_array_equal(mesh.positions, QUAD_POS * 100)
    np.testing.assert_array_equal(mesh.uvs, QUAD_UV)
    np.testing.assert_array_equal(mesh.normals, np.tile([0, 0, 1], (4, 1)))


def test_signed_normalized_clamps_at_minus_one(tmp_path):
    g = Gltf()
    uv = np.array([[-128, 127], [0, 0], [64, -127], [1, 1]], np.int8)
    prim = g.primitive()
    prim["attributes"]["TEXCOORD_0"] = g.accessor(uv, I8, normalized=True)
    g.node(mesh=g.mesh(prim))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_allclose(mesh.uvs[0], [-1, 1])
    np.testing.assert_allclose(mesh.uvs[2], [64 / 127, -1])


def test_interleaved_byte_stride(tmp_path):
    g = Gltf()
    # position (12) + normal (12) + uv (8) + 4 bytes padding: stride 36
    rows = [np.concatenate([p, [0, 0, 1], uv, [0]]).astype("<f4").tobytes()
            for p, uv in zip(QUAD_POS, QUAD_UV, strict=True)]
    view = g.view(b"".join(rows), stride=36)
    prim = {"attributes": {"POSITION": g.accessor(QUAD_POS, view=view),
                           "NORMAL": g.accessor(QUAD_POS, view=view, offset=12),
                           "TEXCOORD_0": g.accessor(QUAD_UV, view=view, offset=24)},
            "indices": g.accessor(QUAD_IDX, U16)}
    g.node(mesh=g.mesh(prim))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_array_equal(mesh.positions, QUAD_POS)
    np.testing.assert_array_equal(mesh.uvs, QUAD_UV)
    np.testing.assert_array_equal(mesh.normals, np.tile([0, 0, 1], (4, 1)))


def test_sparse_accessor(tmp_path):
    g = Gltf()
    prim = g.primitive()
    base = g.doc["accessors"][prim["attributes"]["POSITION"]]
    base["sparse"] = {"count": 1,
                      "indices": {"bufferView": g.view(np.array([2], "<u2").tobytes()),
                                  "componentType": U16},
                      "values": {"bufferView": g.view(np.array([2, 2, 0], "<f4").tobytes())}}
    g.node(mesh=g.mesh(prim))
    mesh = load_gltf(g.write(tmp_path)).meshes[0]
    np.testing.assert_array_equal(mesh.positions[2], [2, 2, 0])
    np.testing.assert_array_equal(mesh.positions[[0, 1, 3]], QUAD_POS[[0, 1, 3]])


def test_sparse_without_buffer_view_starts_from_zeros(tmp_path):
    g = Gltf()
    prim = g.primitive()
    acc = g.doc["accessors"][prim["attributes"]["POSITION"]]
    del acc["bufferView"]
    acc["sparse"] = {"count": 4,
                     "indices": {"bufferView": g.view(np.arange(4, dtype="<u1").tobytes()),
                                 "componentType": U8},
                     "values": {"bufferView": g.view(QUAD_POS.tobytes())}}
    g.node(mesh=g.mesh(prim))
    np.testing.assert_array_equal(load_gltf(g.write(tmp_path)).meshes[0].positions, QUAD_POS)


def test_triangle_strip_and_fan_become_lists(tmp_path):
    g = Gltf()
    strip_pos = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [2, 0, 0]], np.float32)
    fan_pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 1, 0]], np.float32)
    strip = g.primitive(strip_pos, [1, 0, 3, 2, 4], None, mode=5)
    fan = g.primitive(fan_pos, None, None, mode=6)
    g.node(mesh=g.mesh(strip, fan))
    scene = load_gltf(g.write(tmp_path))
    for mesh, count in zip(scene.meshes, (3, 3), strict=True):
        assert mesh.triangle_count == count
        tri = mesh.positions[mesh.indices.astype(int)].reshape(-1, 3, 3)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        # every converted triangle keeps the counter-clockwise winding (+z)
        assert np.all(n[:, 2] > 0), n
    assert scene.meshes[1].indices.tolist() == [1, 2, 0, 2, 3, 0, 3, 4, 0]


def test_strip_stitches_are_dropped(tmp_path):
    g = Gltf()
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    g.node(mesh=g.mesh(g.primitive(pos, [0, 1, 2, 3, 3, 3], None, mode=5)))
    assert load_gltf(g.write(tmp_path)).meshes[0].triangle_count == 2


def test_glb_and_embedded_match_external(tmp_path):
    g = quad_scene()
    a = load_gltf(g.write(tmp_path))
    b = load_gltf(g.glb(tmp_path))
    c = load_gltf(g.write(tmp_path, "embedded.gltf", embed=True))
    for other in (b, c):
        for field in ("positions", "normals", "uvs", "tangents", "indices"):
            np.testing.assert_array_equal(getattr(a.meshes[0], field),
                                          getattr(other.meshes[0], field))


def test_load_scene_dispatches_by_suffix(tmp_path):
    path = quad_scene().glb(tmp_path, "x.GLB")
    assert load_scene(path).meshes[0].triangle_count == 2
    with pytest.raises(SceneError, match=r"x\.xyz2: unknown scene file type '\.xyz2'"):
        load_scene(tmp_path / "x.xyz2")


# ---------------------------------------------------------------------------------------------
# materials, textures, samplers


def textured_scene(tmp_path: Path, where: str = "file") -> Gltf:
    g = Gltf()
    g.doc["materials"] = [{
        "name": "brick",
        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1, 0.75],
                                 "metallicFactor": 0.3, "roughnessFactor": 0.6,
                                 "baseColorTexture": {"index": 0},
                                 "metallicRoughnessTexture": {"index": 1}},
        "normalTexture": {"index": 1, "scale": 0.5},
        "occlusionTexture": {"index": 1, "strength": 0.25},
        "emissiveTexture": {"index": 0},
        "emissiveFactor": [1, 0.5, 0],
        "alphaMode": "MASK", "alphaCutoff": 0.3, "doubleSided": True,
    }]
    g.doc["samplers"] = [{"magFilter": 9728, "minFilter": 9986, "wrapS": 33071,
                          "wrapT": 33648}]
    g.doc["textures"] = [{"source": 0, "sampler": 0}, {"source": 0}]
    data = png(PIXELS)
    if where == "file":
        (tmp_path / "albedo.png").write_bytes(data)
        g.doc["images"] = [{"uri": "albedo.png"}]
    elif where == "data":
        g.doc["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(data).decode()}]
    else:
        g.doc["images"] = [{"bufferView": g.view(data), "mimeType": "image/png"}]
    g.node(mesh=g.mesh(g.primitive(material=0)))
    return g


@pytest.mark.parametrize("where", ["file", "data", "bufferView"])
def test_material_and_textures(tmp_path, where):
    g = textured_scene(tmp_path, where)
    path = g.glb(tmp_path) if where == "bufferView" else g.write(tmp_path)
    scene = load_gltf(path)
    m = scene.materials[scene.meshes[0].material]
    assert m.name == "brick"
    assert m.base_color == (0.5, 0.25, 1, 0.75)
    assert (m.metallic, m.roughness) == (0.3, 0.6)
    assert m.emissive == (1, 0.5, 0)
    assert (m.normal_scale, m.occlusion_strength) == (0.5, 0.25)
    assert (m.alpha_mode, m.alpha_cutoff, m.double_sided) == ("MASK", 0.3, True)
    base = scene.textures[m.base_color_texture]
    assert base.srgb and base.pixels.dtype == np.uint8 and base.pixels.shape == (2, 2, 4)
    np.testing.assert_array_equal(base.pixels, PIXELS)
    assert (base.mag_filter, base.min_filter, base.mipmap_filter) == \
        ("nearest", "nearest", "linear")
    assert (base.address_u, base.address_v) == ("clamp-to-edge", "mirror-repeat")
    assert m.emissive_texture == m.base_color_texture  # same texture, same colour space
    linear = scene.textures[m.normal_texture]
    assert not linear.srgb
    assert m.metallic_roughness_texture == m.occlusion_texture == m.normal_texture
    assert (linear.mag_filter, linear.address_u) == ("linear", "repeat")  # no sampler
    np.testing.assert_array_equal(linear.pixels, PIXELS)


def test_same_texture_in_both_colour_spaces_is_two_textures(tmp_path):
    g = textured_scene(tmp_path)
    mat = g.doc["materials"][0]
    mat["normalTexture"]["index"] = 0  # textures[0] is also the base colour
    scene = load_gltf(g.write(tmp_path))
    m = scene.materials[0]
    assert m.normal_texture != m.base_color_texture
    assert scene.textures[m.base_color_texture].srgb
    assert not scene.textures[m.normal_texture].srgb


@pytest.mark.parametrize(("min_filter", "expected"), [
    (9728, ("nearest", "nearest")), (9729, ("linear", "nearest")),
    (9984, ("nearest", "nearest")), (9985, ("linear", "nearest")),
    (9986, ("nearest", "linear")), (9987, ("linear", "linear")),
    (None, ("linear", "linear")),
])
def test_min_filters(tmp_path, min_filter, expected):
    g = textured_scene(tmp_path)
    sampler = {"magFilter": 9729, "wrapS": 10497}
    if min_filter is not None:
        sampler["minFilter"] = min_filter
    g.doc["samplers"] = [sampler]
    scene = load_gltf(g.write(tmp_path))
    t = scene.textures[scene.materials[0].base_color_texture]
    assert (t.min_filter, t.mipmap_filter) == expected
    assert (t.mag_filter, t.address_u, t.address_v) == ("linear", "repeat", "repeat")


def test_material_defaults_follow_gltf(tmp_path):
    g = Gltf()
    g.doc["materials"] = [{}]
    g.node(mesh=g.mesh(g.primitive(material=0), g.primitive()))
    scene = load_gltf(g.write(tmp_path))
    for mesh in scene.meshes:
        m = scene.materials[mesh.material]
        assert (m.base_color, m.metallic, m.roughness) == ((1, 1, 1, 1), 1.0, 1.0)
        assert m.alpha_mode == "OPAQUE" and m.base_color_texture is None
    assert scene.meshes[0].material != scene.meshes[1].material


def test_unsupported_optional_extensions_warn(tmp_path):
    g = quad_scene()
    g.doc["extensionsUsed"] = ["KHR_materials_sheen", "KHR_lights_punctual"]
    with pytest.warns(UserWarning, match=r"extensionsUsed: KHR_materials_sheen ignored"):
        assert load_gltf(g.write(tmp_path)).meshes


def test_emissive_strength_extension(tmp_path):
    g = Gltf()
    g.doc["materials"] = [{"emissiveFactor": [1, 0.5, 0],
                           "extensions": {"KHR_materials_emissive_strength":
                                          {"emissiveStrength": 4}}}]
    g.node(mesh=g.mesh(g.primitive(material=0)))
    assert load_gltf(g.write(tmp_path)).materials[0].emissive == (4, 2, 0)


def test_specular_extension(tmp_path):
    g = Gltf()
    g.doc["extensionsUsed"] = g.doc["extensionsRequired"] = ["KHR_materials_specular"]
    g.doc["materials"] = [{"extensions": {"KHR_materials_specular": {"specularFactor": 0.25}}},
                          {"extensions": {"KHR_materials_specular": {}}}, {}]
    g.node(mesh=g.mesh(*(g.primitive(material=k) for k in range(3))))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        scene = load_gltf(g.write(tmp_path))
    assert [scene.materials[m.material].specular for m in scene.meshes] == [0.25, 1.0, 1.0]
    assert not [w for w in seen if "specular" in str(w.message)]  # all of it was read


@pytest.mark.parametrize("unread", [{"specularTexture": {"index": 0}},
                                    {"specularColorFactor": [1, 0.5, 0.5]},
                                    {"specularColorTexture": {"index": 0}}])
def test_specular_parts_not_read_warn(tmp_path, unread):
    g = Gltf()
    ext = {"specularFactor": 0.5, **unread}
    g.doc["materials"] = [{"extensions": {"KHR_materials_specular": ext}}] * 2
    g.node(mesh=g.mesh(g.primitive(material=0), g.primitive(material=1)))
    with pytest.warns(UserWarning) as seen:
        scene = load_gltf(g.write(tmp_path))
    lines = [str(w.message) for w in seen if "specular" in str(w.message)]
    # one line for every material that has them, naming the first
    assert len(lines) == 1 and "materials[0].extensions.KHR_materials_specular and 1 more: " \
        "specularTexture, specularColorFactor and specularColorTexture not read" in lines[0]
    assert [m.specular for m in scene.materials] == [0.5, 0.5]


def test_bad_specular_factor_names_the_element(tmp_path):
    g = Gltf()
    g.doc["materials"] = [{"extensions": {"KHR_materials_specular": {"specularFactor": "x"}}}]
    g.node(mesh=g.mesh(g.primitive(material=0)))
    with pytest.raises(SceneError, match=r"materials\[0\]\.extensions\.KHR_materials_specular: "
                                         r"specularFactor must be a finite number"):
        load_gltf(g.write(tmp_path))


# ---------------------------------------------------------------------------------------------
# cameras and lights


def test_camera_from_node(tmp_path):
    g = quad_scene()
    g.doc["cameras"] = [{"type": "perspective", "name": "eye",
                         "perspective": {"yfov": 0.8, "znear": 0.1, "zfar": 50}},
                        {"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.5}}]
    s45 = math.sin(math.radians(45))
    g.node(camera=0, translation=[0, 1, 5])
    g.node(camera=1, translation=[3, 0, 0], rotation=[0, s45, 0, s45])  # looks down -x
    scene = load_gltf(g.write(tmp_path))
    a, b = scene.cameras
    assert a.name == "eye" and (a.yfov, a.znear, a.zfar) == (0.8, 0.1, 50)
    np.testing.assert_allclose(a.position, [0, 1, 5])
    np.testing.assert_allclose(np.subtract(a.target, a.position), [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(a.up, [0, 1, 0], atol=1e-9)
    np.testing.assert_allclose(np.subtract(b.target, b.position), [-1, 0, 0], atol=1e-9)
    assert b.zfar >= 500  # glTF's infinite far plane becomes a finite one
    view = a.view()
    np.testing.assert_allclose(view @ [0, 1, 4, 1], [0, 0, -1, 1], atol=1e-6)


def test_orthographic_camera_is_approximated(tmp_path):
    g = quad_scene()
    g.doc["cameras"] = [{"type": "orthographic",
                         "orthographic": {"xmag": 2, "ymag": 2, "znear": 0.1, "zfar": 10}}]
    g.node(camera=0, translation=[0, 0, 5])
    with pytest.warns(UserWarning, match="orthographic"):
        cam = load_gltf(g.write(tmp_path)).cameras[0]
    np.testing.assert_allclose(cam.target, [0, 0, 5])
    assert cam.position[2] > 5 and cam.yfov < math.radians(15)


def test_lights_from_nodes(tmp_path):
    g = quad_scene()
    g.doc["extensionsUsed"] = ["KHR_lights_punctual"]
    g.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "directional", "color": [1, 0.9, 0.8], "intensity": 3, "name": "sun"},
        {"type": "point", "intensity": 20, "range": 7},
        {"type": "spot", "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
    ]}}
    down = [-math.sin(math.radians(45)), 0, 0, math.cos(math.radians(45))]  # -90 deg about x
    g.node(rotation=down, extensions={"KHR_lights_punctual": {"light": 0}})
    parent = g.node(translation=[1, 2, 3])
    child = g.node(root=False, translation=[0, 1, 0],
                   extensions={"KHR_lights_punctual": {"light": 1}})
    spot = g.node(root=False, extensions={"KHR_lights_punctual": {"light": 2}})
    g.doc["nodes"][parent]["children"] = [child, spot]
    scene = load_gltf(g.write(tmp_path))
    sun, point, cone = scene.lights
    assert (sun.kind, sun.name, sun.color, sun.intensity) == \
        ("directional", "sun", (1, 0.9, 0.8), 3)
    np.testing.assert_allclose(sun.direction, [0, -1, 0], atol=1e-9)
    assert (point.kind, point.intensity, point.range) == ("point", 20, 7)
    np.testing.assert_allclose(point.position, [1, 3, 3])
    assert (cone.kind, cone.inner_cone, cone.outer_cone) == ("spot", 0.2, 0.5)
    np.testing.assert_allclose(cone.direction, [0, 0, -1])
    np.testing.assert_allclose(cone.position, [1, 2, 3])


# ---------------------------------------------------------------------------------------------
# malformed files: SceneError naming the file and the element, nothing read outside


def _set(path: str, value):
    """A mutation setting doc[path] (dotted, with list indices) to value."""
    def mutate(g: Gltf, folder: Path) -> None:
        *keys, last = path.split(".")
        obj = g.doc
        for k in keys:
            obj = obj[int(k)] if k.isdigit() else obj[k]
        if last.isdigit():
            obj[int(last)] = value
        else:
            obj[last] = value
    return mutate


def _uri(uri: str):
    def mutate(g: Gltf, folder: Path) -> None:
        g.after = lambda: _rewrite(folder, lambda d: d["buffers"][0].__setitem__("uri", uri))
    return mutate


def _rewrite(folder: Path, change) -> None:
    path = folder / "scene.gltf"
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def _truncate_bin(g: Gltf, folder: Path) -> None:
    g.after = lambda: (folder / "scene.bin").write_bytes((folder / "scene.bin").read_bytes()
                                                         [:20])


def _delete_bin(g: Gltf, folder: Path) -> None:
    g.after = lambda: (folder / "scene.bin").unlink()


def _secret_outside(g: Gltf, folder: Path) -> None:
    secret = folder.parent / "secret.bin"
    secret.write_bytes(b"\0" * 4096)
    _uri("../secret.bin")(g, folder)


def _symlink_outside(g: Gltf, folder: Path) -> None:
    secret = folder.parent / "secret.bin"
    secret.write_bytes(b"\0" * 4096)
    (folder / "link.bin").symlink_to(secret)
    _uri("link.bin")(g, folder)


def _bad_image(data: bytes):
    def mutate(g: Gltf, folder: Path) -> None:
        (folder / "img.png").write_bytes(data)
        g.doc["images"] = [{"uri": "img.png"}]
        g.doc["textures"] = [{"source": 0}]
        g.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
        g.doc["meshes"][0]["primitives"][0]["material"] = 0
    return mutate


def _cycle(g: Gltf, folder: Path) -> None:
    g.doc["nodes"][0]["children"] = [0]


def _index_seven(g: Gltf, folder: Path) -> None:
    # the indices accessor holds 0..3: overwrite the first index in the bytes
    start = g.doc["bufferViews"][2]["byteOffset"]
    g.bin[start:start + 2] = struct.pack("<H", 7)


def _sparse_nine(g: Gltf, folder: Path) -> None:
    g.doc["accessors"][0]["sparse"] = {
        "count": 1, "indices": {"bufferView": g.view(struct.pack("<H", 9)), "componentType": U16},
        "values": {"bufferView": 0}}


def _accessor_count(count: int):
    return _set("accessors.0.count", count)


PRIM = "meshes[0].primitives[0]"
MALFORMED = {
    "truncated buffer": (_truncate_bin, ["buffers[0]", "truncated", "'scene.bin' has 20 bytes"]),
    "missing buffer file": (_delete_bin, ["buffers[0]", "'scene.bin' not found"]),
    "uri escapes folder": (_secret_outside, ["buffers[0]", "'../secret.bin'", "outside"]),
    "symlink escapes folder": (_symlink_outside, ["buffers[0]", "'link.bin'", "outside"]),
    "absolute path": (_uri("/etc/hostname"), ["buffers[0]", "not a relative path"]),
    "file uri": (_uri("file:///etc/hostname"), ["buffers[0]", "not a relative path"]),
    "bad base64": (_uri("data:application/octet-stream;base64,@@@"),
                   ["buffers[0]", "base64"]),
    "accessor out of range": (_set("meshes.0.primitives.0.attributes.POSITION", 99),
                              [f"POSITION of {PRIM}", "accessors[99]", "has 3 accessors"]),
    "buffer view out of range": (_set("accessors.0.bufferView", 42),
                                 ["accessors[0] (POSITION of", "bufferViews[42]"]),
    "count exceeds view": (_accessor_count(100),
                           [f"accessors[0] (POSITION of {PRIM}): needs 1200 bytes, "
                            "bufferViews[0] has 48"]),
    "view outside buffer": (_set("bufferViews.0.byteLength", 10000),
                            ["bufferViews[0]", "outside buffers[0]"]),
    "view offset outside buffer": (_set("bufferViews.1.byteOffset", 10 ** 9),
                                   ["bufferViews[1]", "outside buffers[0]"]),
    "stride too small": (_set("bufferViews.0.byteStride", 4),
                         ["accessors[0]", "byteStride 4", "12 bytes"]),
    "stride too large": (_set("bufferViews.0.byteStride", 256), ["bufferViews[0]", "252"]),
    "index out of range": (_index_seven, [f"accessors[2] (indices of {PRIM})",
                                          "index 7 out of range for 4 vertices"]),
    "bad component type": (_set("accessors.0.componentType", 5124),
                           ["accessors[0]", "componentType 5124"]),
    "float indices": (_set("accessors.2.componentType", F32),
                      [f"accessors[2] (indices of {PRIM})", "UNSIGNED"]),
    "wrong accessor type": (_set("accessors.0.type", "VEC2"), ["accessors[0]", "VEC3"]),
    "normalized float": (_set("accessors.1.normalized", True),
                         ["accessors[1] (TEXCOORD_0", "normalized"]),
    "negative offset": (_set("accessors.0.byteOffset", -4), ["accessors[0]", "byteOffset"]),
    "zero count": (_accessor_count(0), ["accessors[0]", "count"]),
    # points and lines are strokes (tests/scene/test_strokes.py)
    "unknown mode": (_set("meshes.0.primitives.0.mode", 7), [PRIM, "mode 7"]),
    "no position": (_set("meshes.0.primitives.0.attributes", {"TEXCOORD_0": 1}),
                    [PRIM, "no POSITION"]),
    "attribute count mismatch": (_set("accessors.1.count", 3),
                                 ["accessors[1] (TEXCOORD_0", "count 3 differs"]),
    "mesh out of range": (_set("nodes.0.mesh", 5), ["nodes[0].mesh", "meshes[5]"]),
    "child out of range": (_set("nodes.0.children", [7]), ["nodes[0].children[0]",
                                                           "nodes[7]"]),
    "scene out of range": (_set("scene", 3), ["scene", "scenes[3]"]),
    "cycle": (_cycle, ["nodes[0]", "reached twice"]),
    "zero quaternion": (_set("nodes.0.rotation", [0, 0, 0, 0]), ["nodes[0]", "zero"]),
    "short matrix": (_set("nodes.0.matrix", [1, 0, 0]), ["nodes[0]", "matrix", "16"]),
    "wrong json type": (_set("accessors.0.count", "many"),
                        ["accessors[0].count: expected an integer"]),
    "object for list": (_set("nodes", 5), ["nodes: expected an array"]),
    "material out of range": (_set("meshes.0.primitives.0.material", 3),
                              [f"{PRIM}.material", "materials[3]"]),
    "bad alpha mode": (lambda g, f: (g.doc.__setitem__("materials", [{"alphaMode": "CLIP"}]),
                                     _set("meshes.0.primitives.0.material", 0)(g, f)),
                       ["materials[0]", "alphaMode"]),
    "garbage image": (_bad_image(b"not a png at all"), ["images[0]", "cannot decode"]),
    "missing image": (lambda g, f: (_bad_image(b"")(g, f), (f / "img.png").unlink()),
                      ["images[0]", "'img.png' not found"]),
    "texture out of range": (lambda g, f: (_bad_image(png(PIXELS))(g, f),
                                           g.doc.__setitem__("textures", [])),
                             ["materials[0].baseColorTexture", "textures[0]"]),
    "bad sampler": (lambda g, f: (_bad_image(png(PIXELS))(g, f),
                                  g.doc.__setitem__("samplers", [{"wrapS": 1}]),
                                  g.doc["textures"][0].__setitem__("sampler", 0)),
                    ["samplers[0]", "wrapS 1"]),
    # KHR_draco_mesh_compression is read (tests/scene/test_real_files.py)
    "webgl technique required": (_set("extensionsRequired", ["KHR_technique_webgl"]),
                                 ["extensionsRequired", "KHR_technique_webgl",
                                  "not supported"]),
    "meshopt and basisu": (_set("extensionsRequired", ["EXT_meshopt_compression",
                                                       "KHR_texture_basisu"]),
                           ["EXT_meshopt_compression, KHR_texture_basisu"]),
    "gltf 1": (_set("asset", {"version": "1.0"}), ["asset", "'1.0'"]),
    "light without lights": (_set("nodes.0.extensions", {"KHR_lights_punctual": {"light": 0}}),
                             ["nodes[0].extensions.KHR_lights_punctual"]),
    "camera out of range": (_set("nodes.0.camera", 0), ["nodes[0].camera", "cameras[0]"]),
    "sparse index out of range": (_sparse_nine, ["accessors[0]", "sparse",
                                                 "index 9 out of range for count 4"]),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_raises_scene_error(tmp_path, case):
    mutate, expected = MALFORMED[case]
    folder = tmp_path / "scene"
    folder.mkdir()
    g = quad_scene()
    g.after = None
    mutate(g, folder)
    path = g.write(folder)
    if g.after:
        g.after()
    with pytest.raises(SceneError) as info:
        load_gltf(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    for text in expected:
        assert text in message, message
    assert "\n" not in message


GLB_CASES = {
    "short header": lambda data: data[:8],
    "length past end": lambda data: data[:-8],
    "chunk past end": lambda data: data[:12] + struct.pack("<I4s", 10 ** 6, b"JSON") + data[20:],
    "version 1": lambda data: data[:4] + struct.pack("<I", 1) + data[8:],
    "bin chunk truncated": lambda data: data[:8] + struct.pack("<I", len(data) - 8)
    + data[12:-8],
    # not read as a .gltf's JSON ("JSON: malformed") but named for what it is
    "no magic": lambda data: b"\0gar" + data[4:],
}


@pytest.mark.parametrize("case", list(GLB_CASES))
def test_malformed_glb(tmp_path, case):
    path = quad_scene().glb(tmp_path)
    path.write_bytes(GLB_CASES[case](path.read_bytes()))
    with pytest.raises(SceneError, match=r"scene\.glb: (GLB|buffers\[0\])"):
        load_gltf(path)


def test_glb_json_chunk_length_without_padding(tmp_path):
    """Some writers leave the JSON chunk's padding out of its length (trimesh's cube.glb)."""
    g = quad_scene()
    g.finish()
    text = json.dumps(g.doc).encode()
    text += b" " * (-len(text) % 4 or 4)
    pad = 2
    body = struct.pack("<I4s", len(text) - pad, b"JSON") + text
    body += struct.pack("<I4s", len(g.bin), b"BIN\0") + bytes(g.bin)
    path = tmp_path / "odd.glb"
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    assert load_gltf(path).meshes[0].triangle_count == 2


@pytest.mark.parametrize("text", ["", "{", "[1, 2]", '{"asset": {"version": "2.0"}, '
                                  '"nodes": [{"translation": [NaN, 0, 0]}]}', "\xff\xfe"])
def test_malformed_json(tmp_path, text):
    path = tmp_path / "scene.gltf"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(SceneError, match=r"scene\.gltf: (JSON|asset)"):
        load_gltf(path)


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.gltf: file not found"):
        load_gltf(tmp_path / "nope.gltf")


def test_never_reads_outside_the_folder(tmp_path, monkeypatch):
    """Even where ../secret.bin exists and would make a valid scene, it is not opened."""
    folder = tmp_path / "scene"
    folder.mkdir()
    g = quad_scene()
    path = g.write(folder)
    (tmp_path / "secret.bin").write_bytes((folder / "scene.bin").read_bytes())
    _rewrite(folder, lambda d: d["buffers"][0].__setitem__("uri", "../secret.bin"))
    opened = []
    real = Path.read_bytes

    def spy(self):
        opened.append(self.resolve())
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", spy)
    with pytest.raises(SceneError, match="outside the scene's folder"):
        load_gltf(path)
    assert all(p.is_relative_to(folder.resolve()) for p in opened), opened
    # the same file inside the folder loads: the refusal was about the place alone
    os.replace(tmp_path / "secret.bin", folder / "secret.bin")
    _rewrite(folder, lambda d: d["buffers"][0].__setitem__("uri", "sub/../secret.bin"))
    assert load_gltf(path).meshes[0].triangle_count == 2


def test_percent_encoded_uri(tmp_path):
    g = quad_scene()
    path = g.write(tmp_path)
    (tmp_path / "scene.bin").rename(tmp_path / "my data.bin")
    _rewrite(tmp_path, lambda d: d["buffers"][0].__setitem__("uri", "my%20data.bin"))
    assert load_gltf(path).meshes[0].triangle_count == 2


# ---------------------------------------------------------------------------------------------
# fuzzing: any change to a valid document loads or raises SceneError, nothing else


def kitchen_sink(folder: Path) -> Gltf:
    """Every feature at once: textures, sparse, strides, strips, cameras and lights."""
    g = textured_scene(folder)
    rows = [np.concatenate([p, uv]).astype("<f4").tobytes()
            for p, uv in zip(QUAD_POS, QUAD_UV, strict=True)]
    view = g.view(b"".join(rows), stride=20)
    strided = {"attributes": {"POSITION": g.accessor(QUAD_POS, view=view),
                              "TEXCOORD_0": g.accessor(QUAD_UV, view=view, offset=12)},
               "indices": g.accessor(np.array([0, 1, 3, 2]), U8), "mode": 5, "material": 0}
    _sparse_nine(g, folder)
    g.doc["accessors"][0]["sparse"]["indices"]["bufferView"] = g.view(struct.pack("<H", 1))
    child = g.node(root=False, mesh=g.mesh(strided), scale=[2, 2, 2])
    g.doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 1, "znear": 0.1}}]
    g.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "spot", "spot": {"outerConeAngle": 0.4}}, {"type": "point"}]}}
    g.node(camera=0, translation=[0, 0, 3], children=[child],
           extensions={"KHR_lights_punctual": {"light": 0}})
    return g


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, (*prefix, i))


def _check_scene(scene) -> None:
    for mesh in scene.meshes:
        assert len(mesh.indices) % 3 == 0
        if len(mesh.indices):
            assert int(mesh.indices.max()) < len(mesh.positions)
        for a in (mesh.positions, mesh.normals, mesh.uvs, mesh.tangents):
            assert a.dtype == np.float32 and np.all(np.isfinite(a))
    for m in scene.materials:
        for t in (m.base_color_texture, m.normal_texture, m.occlusion_texture):
            assert t is None or 0 <= t < len(scene.textures)


def _fuzz_space():
    with tempfile.TemporaryDirectory() as d:
        doc = kitchen_sink(Path(d)).doc
    paths = sorted(set(_paths(doc)) - {()}, key=str)
    values = st.one_of(
        st.sampled_from([None, True, False, [], {}, "", "x", "VEC3", "SCALAR", "../x.bin",
                         "data:,", "albedo.png", [0, 0, 0], [1, 0, 0, 0], {"index": 0},
                         1.5, -1.0, 1e308, "<delete>"]),
        st.integers(-3, 10), st.sampled_from([255, 256, 4096, 2 ** 31, 2 ** 40, 5120, 5121,
                                              5123, 5125, 5126, 9728, 9987, 33071]))
    return st.sampled_from(paths), values


_FUZZ_PATHS, _FUZZ_VALUES = _fuzz_space()
FUZZ = settings(max_examples=int(os.environ.get("RFW_FUZZ_EXAMPLES", 200)), deadline=None,
                derandomize=True, suppress_health_check=list(HealthCheck))


@FUZZ
@given(st.lists(st.tuples(_FUZZ_PATHS, _FUZZ_VALUES), min_size=1, max_size=3), st.booleans())
def test_fuzzed_documents_load_or_raise_scene_error(changes, as_glb):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        g = kitchen_sink(folder)
        for path, value in changes:
            obj = g.doc
            try:
                for k in path[:-1]:
                    obj = obj[k]
                if value == "<delete>":
                    del obj[path[-1]]
                else:
                    obj[path[-1]] = copy.deepcopy(value)  # sampled values are shared
            except (KeyError, IndexError, TypeError):
                continue  # an earlier change removed the place
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                scene = load_gltf(g.glb(folder) if as_glb else g.write(folder))
            except SceneError as e:
                assert str(e).startswith(str(folder)), e
            else:
                _check_scene(scene)


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 10 ** 6), st.integers(0, 255)), min_size=1,
                max_size=6), st.integers(0, 10 ** 6))
def test_fuzzed_glb_bytes_load_or_raise_scene_error(flips, cut):
    with tempfile.TemporaryDirectory() as d:
        path = kitchen_sink(Path(d)).glb(Path(d))
        data = bytearray(path.read_bytes())
        for pos, value in flips:
            data[pos % len(data)] = value
        if cut % 3 == 0:
            data = data[:cut % len(data)]
        path.write_bytes(bytes(data))
        with warnings.catch_warnings(), contextlib.suppress(SceneError):
            warnings.simplefilter("ignore")
            _check_scene(load_gltf(path))


# ---------------------------------------------------------------------------------------------
# split_glb and read_uri: the loader's container and URI rules, public for packing


def test_split_glb_returns_both_chunks(tmp_path):
    g = quad_scene()
    path = g.glb(tmp_path)
    text, blob = split_glb(path.read_bytes(), path)
    assert json.loads(text) == g.doc
    assert blob == bytes(g.bin)


def test_split_glb_without_a_binary_chunk(tmp_path):
    text = b'{"asset":{"version":"2.0"}}'
    data = struct.pack("<4sII", b"glTF", 2, 20 + len(text)) \
        + struct.pack("<I4s", len(text), b"JSON") + text
    assert split_glb(data, tmp_path / "x.glb") == (text, None)


def test_split_glb_refuses_a_truncated_file(tmp_path):
    path = quad_scene().glb(tmp_path)
    data = path.read_bytes()
    with pytest.raises(SceneError, match=r"scene\.glb: GLB: truncated: the header says"):
        split_glb(data[:-4], path)


def test_read_uri_reads_data_uris_and_files_in_the_folder(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"abc")
    gltf = tmp_path / "s.gltf"
    assert read_uri(gltf, "a.bin", "buffers[0]") == b"abc"
    assert read_uri(gltf, "data:application/octet-stream;base64,"
                    + base64.b64encode(b"xyz").decode(), "buffers[1]") == b"xyz"


@pytest.mark.parametrize("uri", ["../secret.bin", "/etc/hostname", "file:///etc/hostname"])
def test_read_uri_refuses_what_lies_outside_the_folder(tmp_path, uri):
    (tmp_path / "secret.bin").write_bytes(b"secret")
    (tmp_path / "s").mkdir()
    with pytest.raises(SceneError, match=r"s\.gltf: images\[2\]: uri .* (outside|relative)"):
        read_uri(tmp_path / "s" / "s.gltf", uri, "images[2]")


def test_a_gltf_is_json_and_a_glb_needs_its_magic(tmp_path):
    # the same bytes without the magic: a .glb is "not a GLB file", a .gltf is JSON
    data = b"\0garbage" * 8
    for name, says in (("x.glb", "GLB: not a GLB file: it starts with b'\\x00gar'"),
                       ("x.gltf", "JSON: ")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(SceneError) as e:
            load_gltf(tmp_path / name)
        assert f"{name}: {says}" in str(e.value), str(e.value)
