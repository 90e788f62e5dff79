"""rfw.raycast against Embree, both GPU methods, under validation (zero messages).

The issue's criterion: hit-or-miss agreement on >= 99.9% of rays, and distances within 1e-4
relative where both hit. Measured on lavapipe (Mesa 25.0.7) with 20k rays per mesh: hit-or-
miss agreement is 100% everywhere; relative t differences stay below 3e-6 on the trimesh
meshes. On the courtyard, rays starting a few thousandths from a wall reach 5e-4 relative:
their t is ~1e-3 while float32 coordinates near 12 carry ~1e-6 of error, for Embree as for
the GPU. So the distance check is the issue's 1e-4 relative on 99.9% of the rays, and for
every ray 1e-4 relative or a float32 floor (8 ulp of the largest coordinate, in t units).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import trimesh

import rfw

from .embree_ref import HIT_AGREEMENT, T_RTOL, embree_cast, flatten

METHODS = ("ray_query", "ray_pipeline")
N_RAYS = 20_000


@pytest.fixture(autouse=True)
def _needs_ray_tracing(vk_device):
    if "VK_KHR_acceleration_structure" not in vk_device.caps:
        pytest.skip("no VK_KHR_acceleration_structure")


def _method(vk_device, method: str) -> str:
    ext = {"ray_query": "VK_KHR_ray_query", "ray_pipeline": "VK_KHR_ray_tracing_pipeline"}
    if ext[method] not in vk_device.caps:
        pytest.skip(f"no {ext[method]}")
    return method


def _meshes() -> dict[str, trimesh.Trimesh]:
    rng = np.random.default_rng(3)
    noisy = trimesh.creation.icosphere(subdivisions=2)
    noisy.vertices += rng.normal(scale=0.05, size=noisy.vertices.shape)
    return {"icosphere": trimesh.creation.icosphere(subdivisions=3),
            "torus": trimesh.creation.torus(1.0, 0.3),
            "capsule": trimesh.creation.capsule(1.0, 0.4),
            "noisy_sphere": noisy,
            # overlapping, intersecting triangles: the closest of several hits must win
            # (seeded: trimesh's random_soup draws from the unseeded global generator)
            "soup": trimesh.Trimesh(rng.random((1500, 3)) - 0.5,
                                    np.arange(1500).reshape(500, 3), process=False)}


MESHES = _meshes()


def _rays_around(vertices: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Origins on a sphere twice the bounds' radius, aimed at points of the bounds grown by
    10%: a mix of hits, misses and grazing rays."""
    rng = np.random.default_rng(seed)
    lo, hi = vertices.min(0), vertices.max(0)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    o = rng.normal(size=(n, 3))
    o = c + o / np.linalg.norm(o, axis=1, keepdims=True) * 2 * r
    target = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (n, 3))
    return o.astype(np.float32), (target - o).astype(np.float32)


def _check_against(ref: dict, got: dict, origins: np.ndarray, directions: np.ndarray,
                   extent: float) -> None:
    g, r = np.isfinite(got["t"]), np.isfinite(ref["t"])
    assert (g == r).mean() >= HIT_AGREEMENT, f"hit-or-miss agreement {(g == r).mean():.5f}"
    both = g & r
    assert both.sum() > len(g) // 4  # the rays really test hits
    dt = np.abs(got["t"][both] - ref["t"][both])
    rel_ok = dt <= T_RTOL * ref["t"][both]
    assert rel_ok.mean() >= HIT_AGREEMENT, f"t within 1e-4: {rel_ok.mean():.5f}"
    # float32 coordinates bound what either tracer can resolve
    scale = np.abs(origins[both]).max(axis=1) + extent
    floor = 8 * np.finfo(np.float32).eps * scale / np.linalg.norm(directions[both], axis=1)
    worst = np.argmax(dt - np.maximum(T_RTOL * ref["t"][both], floor))
    assert (dt <= np.maximum(T_RTOL * ref["t"][both], floor)).all(), \
        f"t {got['t'][both][worst]} vs Embree {ref['t'][both][worst]}"
    # the same triangle, and the same point on it (an off-by-one shows up here)
    same = got["primitive"][both] == ref["primitive"][both]
    assert same.mean() >= 0.99
    bary = np.stack([ref["u"], ref["v"]], axis=1)[both][same]
    close = np.abs(got["barycentrics"][both][same] - bary).max(axis=1) <= 1e-3
    assert close.mean() >= HIT_AGREEMENT


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", list(MESHES))
def test_mesh_agrees_with_embree(vk_device, name, method):
    method = _method(vk_device, method)
    mesh = MESHES[name]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, N_RAYS, seed=len(name))
    got = rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=method)
    assert set(got) == {"t", "primitive", "barycentrics"}
    assert got["t"].dtype == np.float32 and got["primitive"].dtype == np.int32
    assert got["barycentrics"].shape == (N_RAYS, 2)
    assert (got["primitive"][~np.isfinite(got["t"])] == -1).all()
    ref = embree_cast(v, mesh.faces, o, d)
    _check_against(ref, got, o, d, float(np.abs(v).max()))


@pytest.mark.parametrize("method", METHODS)
def test_courtyard_agrees_with_embree(vk_device, courtyard, method):
    """Every instance of the default scene: rays from outside at the bounds, and rays from
    inside the courtyard in all directions; instance indices map back as Embree's do."""
    method = _method(vk_device, method)
    v, f, owner = flatten(courtyard)
    o1, d1 = _rays_around(v, N_RAYS // 2, seed=11)
    rng = np.random.default_rng(12)
    o2 = rng.uniform([-35, 0.5, -35], [35, 15, 35], (N_RAYS // 2, 3)).astype(np.float32)
    d2 = rng.normal(size=(N_RAYS // 2, 3)).astype(np.float32)
    o, d = np.concatenate([o1, o2]), np.concatenate([d1, d2])
    got = rfw.raycast(origins=o, directions=d, scene=courtyard, device=vk_device,
                      method=method)
    ref = embree_cast(v, f, o, d)
    hit = ref["primitive"] >= 0
    # Embree numbers the flattened triangles: map them to (instance, primitive)
    ref_instance = np.where(hit, owner[np.maximum(ref["primitive"], 0), 0], -1)
    ref["primitive"] = np.where(hit, owner[np.maximum(ref["primitive"], 0), 1], -1)
    _check_against(ref, got, o, d, float(np.abs(v).max()))
    assert (got["instance"] == ref_instance).mean() >= 0.99
    assert (got["instance"][~np.isfinite(got["t"])] == -1).all()


@pytest.mark.parametrize("method", METHODS)
def test_ray_interval_and_batches(vk_device, method):
    """Per-ray tmin/tmax bound the hit (a ray starting past the near side finds the far
    side, one ending short misses); batches of 97 rays give the answer of one batch."""
    method = _method(vk_device, method)
    mesh = MESHES["icosphere"]
    v = mesh.vertices.astype(np.float32)
    n = 1000
    rng = np.random.default_rng(5)
    xy = rng.uniform(-0.5, 0.5, (n, 2))
    o = np.c_[xy, np.full(n, -3.0)].astype(np.float32)
    d = np.tile(np.float32([0, 0, 1]), (n, 1))
    full = rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=method)
    near = full["t"]
    assert np.isfinite(near).all() and (near < 3).all()
    far = rfw.raycast(v, mesh.faces, o, d, tmin=near + 0.1, device=vk_device, method=method)
    assert (far["t"] > 3).all()  # the back of the sphere
    short = rfw.raycast(v, mesh.faces, o, d, tmax=near - 0.01, device=vk_device,
                        method=method)
    assert not np.isfinite(short["t"]).any()
    batched = rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=method, batch=97)
    for k in full:
        np.testing.assert_array_equal(batched[k], full[k])


def test_methods_give_identical_answers(vk_device):
    for m in METHODS:
        _method(vk_device, m)
    mesh = MESHES["torus"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 5000, seed=9)
    a, b = (rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=m) for m in METHODS)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


def test_no_rays_and_no_triangles(vk_device):
    tri = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    empty = rfw.raycast(tri, [[0, 1, 2]], np.zeros((0, 3)), np.zeros((0, 3)),
                        device=vk_device)
    assert empty["t"].shape == (0,) and empty["barycentrics"].shape == (0, 2)
    nothing = rfw.raycast(tri, np.zeros((0, 3), np.int32), [[0.2, 0.2, 1]], [[0, 0, -1]],
                          device=vk_device)
    assert nothing["t"][0] == np.inf and nothing["primitive"][0] == -1


_TRI = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
_FACES = np.array([[0, 1, 2]])
_O = np.float32([[0.2, 0.2, 1]])
_D = np.float32([[0, 0, -1]])


@pytest.mark.parametrize(("kwargs", "argument"), [
    ({"vertices": _TRI[:, :2]}, "vertices"),
    ({"vertices": _TRI.astype(str)}, "vertices"),
    ({"vertices": np.float32([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]])}, "vertices"),
    ({"indices": _FACES.astype(np.float32)}, "indices"),
    ({"indices": np.array([0, 1, 2])}, "indices"),
    ({"indices": np.array([[0, 1, 3]])}, "indices"),
    ({"origins": _O[:, :2]}, "origins"),
    ({"origins": np.array([[True, False, True]])}, "origins"),
    ({"directions": np.float32([[0, 0, -1], [0, 0, -1]])}, "directions"),
    ({"directions": np.float32([[0, 0, 0]])}, "directions"),
    ({"tmin": -1.0}, "tmin"),
    ({"tmax": np.float32([1, 2])}, "tmax"),
    ({"tmin": 2.0, "tmax": 1.0}, "tmax"),
    ({"method": "rasterise"}, "method"),
    ({"scene": "courtyard"}, "scene"),
])
def test_bad_input_names_the_argument(vk_device, kwargs, argument):
    args = {"vertices": _TRI, "indices": _FACES, "origins": _O, "directions": _D}
    args.update(kwargs)
    if "scene" in kwargs:
        args.pop("vertices")
        args.pop("indices")
    with pytest.raises(ValueError, match=argument):
        rfw.raycast(**args, device=vk_device)


def test_import_rfw_does_not_load_vulkan():
    code = ("import sys, rfw; f = rfw.raycast; import rfw.raycasting; "
            "assert rfw.raycast is f and callable(f); "
            "assert 'vulkan' not in sys.modules and 'vkext' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)
