"""The built-in courtyard: deterministic, well-formed and built for culling and shadows."""

from __future__ import annotations

import hashlib
from collections import Counter

import numpy as np
import pytest

from rfw.scene import courtyard, default_scene


@pytest.fixture(scope="module")
def scene():
    return courtyard(0)


def digest(s) -> str:
    h = hashlib.sha256()
    for m in s.meshes:
        for a in (m.positions, m.normals, m.uvs, m.tangents, m.indices):
            h.update(a.tobytes())
        h.update(str(m.material).encode())
    for t in s.textures:
        h.update(t.pixels.tobytes())
    for i in s.instances:
        h.update(i.transform.tobytes())
        h.update(str(i.mesh).encode())
    h.update(repr((s.materials, s.lights, s.cameras)).encode())
    return h.hexdigest()


def test_deterministic(scene):
    assert digest(courtyard(0)) == digest(scene)
    assert digest(default_scene()) == digest(scene)
    assert digest(courtyard(1)) != digest(scene)


def test_size(scene):
    assert 50_000 <= scene.triangle_count <= 200_000
    assert len(scene.instances) > 3 * len(scene.meshes)
    lo, hi = scene.bounds()
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
    assert lo[1] == pytest.approx(0.0, abs=1e-6)
    assert np.all(hi - lo < 100) and np.all(lo[[0, 2]] < -12.8) and np.all(hi[[0, 2]] > 12.8)


def test_instancing(scene):
    uses = Counter(i.mesh for i in scene.instances)
    names = {scene.meshes[k].name: n for k, n in uses.items()}
    assert names["column"] == 64
    assert names["baluster"] >= 100
    for inst in scene.instances:
        t = inst.transform
        assert t.dtype == np.float32 and t.shape == (4, 4)
        np.testing.assert_array_equal(t[3], [0, 0, 0, 1])
        # rotation times uniform scale: normals transform with the matrix itself
        r = t[:3, :3].astype(np.float64)
        gram = r.T @ r
        np.testing.assert_allclose(gram, np.identity(3) * gram[0, 0], atol=1e-5)


def test_meshes_are_well_formed(scene):
    for m in scene.meshes:
        v = len(m.positions)
        assert m.positions.dtype == m.normals.dtype == m.uvs.dtype == m.tangents.dtype \
            == np.float32
        assert m.indices.dtype == np.uint32 and len(m.indices) % 3 == 0
        assert m.positions.shape == m.normals.shape == (v, 3)
        assert m.uvs.shape == (v, 2) and m.tangents.shape == (v, 4)
        assert int(m.indices.max()) < v, m.name
        for a in (m.positions, m.normals, m.uvs, m.tangents, m.indices):
            assert a.flags.c_contiguous and np.all(np.isfinite(a))
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1, atol=1e-5,
                                   err_msg=m.name)
        np.testing.assert_allclose(np.linalg.norm(m.tangents[:, :3], axis=1), 1, atol=1e-5)
        assert np.all(np.abs(np.sum(m.normals * m.tangents[:, :3], axis=1)) < 1e-4), m.name
        assert set(np.unique(m.tangents[:, 3])) <= {-1.0, 1.0}
        assert 0 <= m.material < len(scene.materials)


def test_triangles_wind_outward(scene):
    """Counter-clockwise seen from the side the normals point to (back-face culling)."""
    for m in scene.meshes:
        tri = m.indices.reshape(-1, 3).astype(np.int64)
        p = m.positions.astype(np.float64)
        face = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        area = np.linalg.norm(face, axis=1)
        n = m.normals[tri].sum(axis=1)
        agree = np.sum(face * n, axis=1) > 0
        assert np.all(agree | (area < 1e-9)), m.name


def test_materials_and_textures(scene):
    assert len(scene.textures) >= 6
    assert any(m.metallic == 1.0 and m.base_color_texture is None for m in scene.materials)
    assert any(m.alpha_mode == "BLEND" for m in scene.materials)
    for t in scene.textures:
        h, w, c = t.pixels.shape
        assert c == 4 and t.pixels.dtype == np.uint8 and h <= 512 and w <= 512
        assert t.pixels.flags.c_contiguous
    srgb = {"base": True, "emissive": True, "metallic_roughness": False, "normal": False,
            "occlusion": False}
    for m in scene.materials:
        for slot, want in srgb.items():
            index = getattr(m, f"{slot}_texture" if slot != "base" else "base_color_texture")
            if index is not None:
                assert 0 <= index < len(scene.textures)
                assert scene.textures[index].srgb is want, (m.name, slot)
    floor = next(m for m in scene.materials if m.name == "floor")
    assert floor.normal_texture is not None and floor.metallic_roughness_texture is not None
    normal = scene.textures[floor.normal_texture].pixels.astype(float) / 255 * 2 - 1
    # a tangent-space normal map: unit vectors, mostly facing out of the surface
    np.testing.assert_allclose(np.linalg.norm(normal[..., :3], axis=-1), 1, atol=0.02)
    assert np.mean(normal[..., 2]) > 0.8


def test_lights(scene):
    kinds = Counter(light.kind for light in scene.lights)
    assert kinds["directional"] == 1 and 3 <= kinds["point"] <= 6
    sun = next(light for light in scene.lights if light.kind == "directional")
    d = np.array(sun.direction)
    assert np.linalg.norm(d) == pytest.approx(1)
    elevation = np.degrees(np.arcsin(-d[1]))
    assert 20 <= elevation <= 50  # low enough for long shadows
    colours = {light.color for light in scene.lights if light.kind == "point"}
    assert len(colours) >= 3
    for light in scene.lights:
        if light.kind == "point":
            assert all(abs(c) < 12 for c in light.position) and light.range > 0


def test_camera_looks_into_the_courtyard(scene):
    (cam,) = scene.cameras
    eye, target = np.array(cam.position), np.array(cam.target)
    assert np.all(np.abs(eye[[0, 2]]) < 8) and 1.4 < eye[1] < 2.0  # eye height, inside
    assert np.all(np.abs(target[[0, 2]]) < 12)
    forward = target - eye
    assert forward @ -eye > 0  # towards the centre
    assert scene.default_camera() is cam
    view = cam.view()
    centre = view @ [0, 1, 0, 1]
    assert centre[2] < 0  # the court's centre is in front of the camera


def test_walls_hide_the_outside_from_the_camera(scene):
    """Houses stand beyond the walls: a renderer that culls by occlusion has work to do."""
    houses = [i for i in scene.instances if i.name.startswith("house ")]
    assert len(houses) >= 8
    for inst in houses:
        x, _, z = inst.transform[:3, 3]
        assert max(abs(x), abs(z)) > 12.8
