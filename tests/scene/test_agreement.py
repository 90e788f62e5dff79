"""The agreement scenes (``cornell``, ``spheres``): deterministic, found by name, small, made
of the materials rfw's path tracer and Mitsuba share, closed where light must not leak, and
framed by their own cameras."""

from __future__ import annotations

import numpy as np
import pytest

from rfw.scene import BUILTIN_SCENES, builtin_scene, cornell, is_builtin, load_scene, spheres
from rfw.scene.names import known_names

from .test_courtyard import digest

SCENES = {"cornell": cornell, "spheres": spheres}


@pytest.mark.parametrize("name", SCENES)
def test_deterministic_and_found_by_name(name):
    a = SCENES[name]()
    assert digest(a) == digest(SCENES[name]()) == digest(load_scene(name))
    assert digest(builtin_scene(name)) == digest(a) and a.name == name
    assert is_builtin(name) and name in BUILTIN_SCENES and name in known_names()
    assert a.drawable() is a


def test_triangles_and_bounds():
    box, balls = cornell(), spheres()
    assert box.triangle_count == 34 and len(box.instances) == 5
    lo, hi = box.bounds()
    np.testing.assert_allclose(lo, [-1, 0, -1], atol=1e-6)
    np.testing.assert_allclose(hi, [1, 2, 1], atol=1e-6)
    assert balls.triangle_count == 4418
    lo, hi = balls.bounds()
    np.testing.assert_allclose(lo, [-20, 0, -20], atol=1e-6)
    np.testing.assert_allclose(hi, [20, 1.2, 20], atol=1e-6)


def _world(scene, inst):
    m = scene.meshes[inst.mesh]
    t = inst.transform.astype(np.float64)
    p = m.positions @ t[:3, :3].T + t[:3, 3]
    n = m.normals @ np.linalg.inv(t[:3, :3])
    return p, n / np.linalg.norm(n, axis=1, keepdims=True), m.indices.reshape(-1, 3)


@pytest.mark.parametrize("name", SCENES)
def test_winding_agrees_with_normals(name):
    """Every triangle's face normal points the way its vertex normals do, and no triangle
    has zero area (the spheres' poles are left out)."""
    s = SCENES[name]()
    for inst in s.instances:
        p, n, tri = _world(s, inst)
        face = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        area = np.linalg.norm(face, axis=1)
        assert area.min() > 1e-6, inst.name
        assert np.all(np.sum(face / area[:, None] * n[tri].mean(axis=1), axis=1) > 0.9)
        np.testing.assert_allclose(np.linalg.norm(s.meshes[inst.mesh].normals, axis=1), 1,
                                   atol=1e-6)


def test_cornell_walls_face_in_and_boxes_out():
    s = cornell()
    center = np.array([0.0, 1.0, 0.0])
    for inst in s.instances:
        p, n, tri = _world(s, inst)
        mid = p[tri].mean(axis=1)
        toward = np.sum(n[tri].mean(axis=1) * (center - mid), axis=1)
        if inst.name.startswith("wall"):
            assert np.all(toward > 0), inst.name  # the room is seen from inside only
        else:
            box = p.mean(axis=0)
            assert np.all(np.sum(n[tri].mean(axis=1) * (mid - box), axis=1) > 0), inst.name
    by_name = {i.name: _world(s, i)[0] for i in s.instances}
    assert by_name["wall red"][:, 0].max() == pytest.approx(-1)  # red on the left (-X)
    assert by_name["wall green"][:, 0].min() == pytest.approx(1)
    tall, short = by_name["tall box"], by_name["short box"]
    assert tall[:, 1].max() == pytest.approx(1.2) and short[:, 1].max() == pytest.approx(0.6)
    assert tall[:, 0].mean() < 0 < short[:, 0].mean()
    for box in (tall, short):  # inside the room, clear of the walls
        assert np.all(np.abs(box[:, [0, 2]]) < 0.95)


def test_materials_are_the_shared_ones():
    for scene in (cornell(), spheres()):
        assert not scene.textures
        for m in scene.materials:
            assert m.emissive == (0, 0, 0) and m.alpha_mode == "OPAQUE"
            assert m.base_color_texture is None and m.normal_texture is None
            # pure Lambert (no dielectric lobe) or a metal: nothing in between
            assert (m.metallic, m.specular) == (0.0, 0.0) or m.metallic == 1.0, m.name
    box = {m.name: m for m in cornell().materials}
    assert box["red"].base_color[0] > 5 * box["red"].base_color[1]
    assert box["green"].base_color[1] > 2 * box["green"].base_color[0]
    metal = [m for m in spheres().materials if m.metallic == 1.0]
    assert len(metal) == 1 and metal[0].roughness == pytest.approx(0.4)
    assert [li.kind for li in cornell().lights] == ["point"]
    light = cornell().lights[0]
    assert light.range is None and 1.5 < light.position[1] < 2.0  # below the ceiling
    assert [li.kind for li in spheres().lights] == ["directional"]


def _projected(scene, points, aspect=1.0):
    cam = scene.cameras[0]
    clip = np.c_[points, np.ones(len(points))] @ (cam.projection(aspect).astype(np.float64)
                                                    @ cam.view().astype(np.float64)).T
    return clip[:, :3] / clip[:, 3:], clip[:, 3]


def test_cameras_frame_the_scenes():
    """Cornell: the camera stands outside the open side and sees the whole opening, so the
    room fills the middle of the image with background around it. Spheres: both spheres
    are in view, and the plane's far edge is too (rays past it miss everything)."""
    box = cornell()
    assert box.cameras[0].position[2] > 1.0
    opening = np.array([[x, y, 1.0] for x in (-1, 1) for y in (0, 2)])
    ndc, w = _projected(box, opening)
    assert np.all(w > 0) and np.all(np.abs(ndc[:, :2]) < 0.95)
    assert np.all(np.abs(ndc[:, :2]) > 0.5)
    balls = spheres()
    for inst in balls.instances[1:]:
        ndc, w = _projected(balls, _world(balls, inst)[0], aspect=4 / 3)
        assert np.all(w > 0) and np.all(np.abs(ndc[:, :2]) < 0.9), inst.name
    far_edge = np.array([[0.0, 0.0, -20.0]])
    ndc, w = _projected(balls, far_edge, aspect=4 / 3)
    assert w[0] > 0 and -1 < ndc[0, 1] < 0.9  # the horizon is below the top of the image
