"""Meshlets: partition, limits, bounds, cone culling, GPU packing and the disk cache."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("meshoptimizer", reason="rfw.meshlets needs the meshoptimizer package")

import rfw.meshlets as ml
from rfw.meshlets import Meshlets, build_meshlets, cached_meshlets, pack_for_gpu
from tests.conftest import box_mesh

# ---------------------------------------------------------------------------------------------
# test meshes, built in code


def _grid_faces(nu: int, nv: int, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Two CCW triangles per cell of an nu x nv vertex grid, optionally wrapping around."""
    cu, cv = (nu if wrap_u else nu - 1), (nv if wrap_v else nv - 1)
    i, j = np.meshgrid(np.arange(cu), np.arange(cv), indexing="ij")
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    return np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], 2).reshape(-1, 3)


def _bumpy_plane(n: int = 48, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    z = 0.02 * rng.standard_normal((n, n))
    return np.stack([x, y, z], -1).reshape(-1, 3), _grid_faces(n, n, False, False)


def _torus(major: float = 1.0, minor: float = 0.35, nu: int = 64, nv: int = 32):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False),
                       np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")  # fmt: skip
    r = major + minor * np.cos(v)
    pos = np.stack([r * np.cos(u), r * np.sin(u), minor * np.sin(v)], -1).reshape(-1, 3)
    return pos, _grid_faces(nu, nv, True, True)


@functools.cache
def _meshes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    from rfw.scene.courtyard import courtyard

    sphere = trimesh.creation.uv_sphere(radius=1.0, count=[36, 36])  # ~5k triangles
    cube = box_mesh(1.0, 1.0, 1.0)
    out = {
        "uv_sphere": (sphere.vertices, sphere.faces),
        "torus": _torus(),
        "bumpy_plane": _bumpy_plane(),
        "cube": (cube.positions, cube.indices.reshape(-1, 3)),
    }
    scene = courtyard()
    for mesh in scene.meshes:
        if mesh.name in ("column", "fountain"):
            out[f"courtyard_{mesh.name}"] = (mesh.positions, mesh.indices.reshape(-1, 3))
    return {
        k: (np.asarray(p, np.float32), np.asarray(f, np.uint32).reshape(-1, 3))
        for k, (p, f) in out.items()
    }


MESH_NAMES = ["uv_sphere", "torus", "bumpy_plane", "cube", "courtyard_column", "courtyard_fountain"]


@functools.cache
def _built(
    name: str, max_vertices: int = 64, max_triangles: int = 124, cone_weight: float = 0.25
) -> Meshlets:
    pos, faces = _meshes()[name]
    return build_meshlets(pos, faces, max_vertices=max_vertices, max_triangles=max_triangles,
                          cone_weight=cone_weight)  # fmt: skip


def _sorted_rows(tris: np.ndarray) -> np.ndarray:
    tris = np.asarray(tris, np.int64).reshape(-1, 3)
    return tris[np.lexsort(tris.T[::-1])]


def _canonical(tris: np.ndarray) -> np.ndarray:
    """Rotate each triangle so its smallest index comes first (keeps winding), then sort rows."""
    tris = np.asarray(tris, np.int64).reshape(-1, 3)
    k = np.argmin(tris, axis=1)
    rolled = np.stack([tris[np.arange(len(tris)), (k + s) % 3] for s in range(3)], 1)
    return _sorted_rows(rolled)


# ---------------------------------------------------------------------------------------------
# partition and limits


@pytest.mark.parametrize("name", MESH_NAMES)
def test_every_triangle_in_exactly_one_meshlet(name):
    _, faces = _meshes()[name]
    m = _built(name)
    got = m.triangle_indices()
    assert len(got) == len(faces)
    # winding is kept, so compare rotated-canonical triangles as sorted multisets
    np.testing.assert_array_equal(_canonical(got), _canonical(faces))
    assert m.meshlets[:, 3].sum() == len(faces)


@pytest.mark.parametrize("limits", [(64, 124), (32, 64), (128, 256), (255, 512), (16, 8), (3, 4)])
@pytest.mark.parametrize("name", ["uv_sphere", "torus", "bumpy_plane", "courtyard_fountain"])
def test_limits_and_layout(name, limits):
    max_v, max_t = limits
    m = _built(name, max_v, max_t)
    v_off, t_off, v_count, t_count = m.meshlets.T.astype(np.int64)
    assert (
        m.meshlets.dtype == np.uint32
        and m.vertices.dtype == np.uint32
        and m.triangles.dtype == np.uint8
    )
    assert (v_count >= 3).all() and (v_count <= max_v).all()
    assert (t_count >= 1).all() and (t_count <= max_t).all()
    # runs are consecutive; triangle runs start on 4-byte boundaries and are zero-padded
    np.testing.assert_array_equal(v_off, np.concatenate([[0], np.cumsum(v_count)[:-1]]))
    padded = (3 * t_count + 3) & ~3
    np.testing.assert_array_equal(t_off, np.concatenate([[0], np.cumsum(padded)[:-1]]))
    assert len(m.triangles) == padded.sum() and len(m.vertices) == v_count.sum()
    for vo, to, vc, tc in zip(v_off, t_off, v_count, t_count, strict=True):
        local = m.triangles[to : to + 3 * tc]
        assert local.max() < vc
        assert not m.triangles[to + 3 * tc : to + ((3 * tc + 3) & ~3)].any()
        # every meshlet vertex is used, and used once in the vertex list
        assert len(np.unique(m.vertices[vo : vo + vc])) == vc
        assert len(np.unique(local)) == vc


def test_bad_input_is_refused():
    pos, faces = _meshes()["cube"]
    for max_v, max_t in [(2, 124), (256, 124), (64, 0), (64, 126), (64, 516)]:
        with pytest.raises(ValueError, match="max_"):
            build_meshlets(pos, faces, max_vertices=max_v, max_triangles=max_t)
    with pytest.raises(ValueError, match="indices"):
        build_meshlets(pos, np.array([0, 1, 24], np.uint32))
    with pytest.raises(ValueError, match="multiple of 3"):
        build_meshlets(pos, np.array([0, 1], np.uint32))


def test_empty_mesh():
    m = build_meshlets(np.zeros((0, 3), np.float32), np.zeros(0, np.uint32))
    assert m.meshlets.shape == (0, 4) and len(m.vertices) == 0 and len(m.triangles) == 0
    assert m.bounds.center.shape == (0, 3) and m.bounds.cone_cutoff_s8.shape == (0,)
    packed = pack_for_gpu(m)
    assert packed["meshlets"].shape == (0, 4) and packed["cones"].shape == (0,)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    tri_count=st.integers(1, 400),
    vert_count=st.integers(3, 300),
    max_v=st.integers(3, 80),
    max_t=st.sampled_from([4, 8, 64, 124]),
)
def test_random_soups_partition(seed, tri_count, vert_count, max_v, max_t):
    rng = np.random.default_rng(seed)
    pos = rng.standard_normal((vert_count, 3)).astype(np.float32)
    faces = np.stack([rng.choice(vert_count, 3, replace=False) for _ in range(tri_count)]).astype(
        np.uint32
    )
    m = build_meshlets(pos, faces, max_vertices=max_v, max_triangles=max_t)
    np.testing.assert_array_equal(_canonical(m.triangle_indices()), _canonical(faces))
    assert (m.meshlets[:, 2] <= max_v).all() and (m.meshlets[:, 3] <= max_t).all()


# ---------------------------------------------------------------------------------------------
# bounds and cone culling


def _meshlet_of_triangle(m: Meshlets) -> np.ndarray:
    return np.repeat(np.arange(len(m)), m.meshlets[:, 3].astype(np.int64))


@pytest.mark.parametrize("name", MESH_NAMES)
def test_vertices_inside_sphere(name):
    pos, _ = _meshes()[name]
    m = _built(name)
    b = m.bounds
    scale = np.abs(pos).max()
    for i, (vo, _, vc, _) in enumerate(m.meshlets):
        p = pos[m.vertices[vo : vo + vc]].astype(np.float64)
        d = np.linalg.norm(p - b.center[i], axis=1)
        assert d.max() <= b.radius[i] * (1 + 1e-5) + 1e-6 * scale, (i, d.max(), b.radius[i])


def _views(pos: np.ndarray, count: int, seed: int, near: float, far: float) -> np.ndarray:
    """Camera positions at random directions, between near and far times the mesh radius."""
    rng = np.random.default_rng(seed)
    center = (pos.min(0) + pos.max(0)) / 2
    radius = np.linalg.norm(pos - center, axis=1).max()
    d = rng.standard_normal((count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return center + d * radius * rng.uniform(near, far, (count, 1))


def _cone_culled(m: Meshlets, cams: np.ndarray) -> dict[str, np.ndarray]:
    """(C, M) masks of meshlets rejected by meshoptimizer's documented cone tests."""
    b = m.bounds
    apex, center = b.cone_apex.astype(np.float64), b.center.astype(np.float64)
    to_apex = apex[None] - cams[:, None]
    to_apex /= np.maximum(np.linalg.norm(to_apex, axis=2, keepdims=True), 1e-30)
    to_center = center[None] - cams[:, None]
    axis_s8 = b.cone_axis_s8.astype(np.float64) / 127.0
    cutoff_s8 = b.cone_cutoff_s8.astype(np.float64) / 127.0
    return {
        # perspective test with the apex: dot(normalize(apex - camera), axis) >= cutoff
        "apex": np.einsum("cmk,mk->cm", to_apex, b.cone_axis) >= b.cone_cutoff,
        # the same with the 8-bit axis and cutoff, decoded as x / 127
        "apex_s8": np.einsum("cmk,mk->cm", to_apex, axis_s8) >= cutoff_s8,
        # the apex-free form with the bounding sphere
        "sphere": np.einsum("cmk,mk->cm", to_center, b.cone_axis)
        >= b.cone_cutoff * np.linalg.norm(to_center, axis=2) + b.radius,
    }


def _front_facing(
    pos: np.ndarray, tris: np.ndarray, cams: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(C, T) front-facing mask for CCW triangles, and the mask of non-degenerate triangles."""
    p = pos.astype(np.float64)[tris.astype(np.int64)]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    solid = area2 > 1e-12 * np.abs(p).max() ** 2
    n = n / np.maximum(area2, 1e-300)[:, None]
    view = p.mean(1)[None] - cams[:, None]
    view /= np.linalg.norm(view, axis=2, keepdims=True)
    # a small margin: edge-on triangles cover no pixels, and the bounds are float32
    return np.einsum("ctk,tk->ct", view, n) < -1e-4, solid


@pytest.mark.parametrize("name", MESH_NAMES)
def test_cone_never_culls_a_front_facing_triangle(name):
    pos, _ = _meshes()[name]
    m = _built(name)
    tris = m.triangle_indices()
    owner = _meshlet_of_triangle(m)
    # cameras anywhere: outside, close, and inside the mesh's bounding sphere
    cams = np.concatenate([_views(pos, 200, 1, 1.05, 6.0), _views(pos, 100, 2, 0.0, 1.05)])
    front, solid = _front_facing(pos, tris, cams)
    for test, culled in _cone_culled(m, cams).items():
        wrong = culled[:, owner] & front & solid[None]
        assert not wrong.any(), f"{test}: {wrong.sum()} front-facing triangles culled"


def test_flat_patch_cone_is_tight():
    # a flat grid facing +z: the axis is the common normal, the cutoff sin(0); seen from
    # below (apex - camera along +z) it is culled, from above it is not
    pos, faces = _bumpy_plane(n=8)
    pos[:, 2] = 0
    m = build_meshlets(pos, faces)
    np.testing.assert_allclose(m.bounds.cone_axis, [[0, 0, 1]] * len(m), atol=1e-6)
    assert (m.bounds.cone_cutoff < 1e-3).all()
    cams = np.array([[0.1, 0.2, 5.0], [0.1, 0.2, -5.0]])
    culled = _cone_culled(m, cams)["apex"]
    assert not culled[0].any() and culled[1].all()
    assert (m.bounds.cone_cutoff_s8 <= 3).all()  # the 8-bit cutoff is rounded up, a little


def _quality(name: str, cone_weight: float = 0.25) -> dict[str, float]:
    pos, faces = _meshes()[name]
    m = _built(name, cone_weight=cone_weight)
    cams = _views(pos, 256, 3, 2.0, 4.0)
    culled = _cone_culled(m, cams)
    tris = m.meshlets[:, 3].astype(np.float64)
    return {
        "triangles": len(faces),
        "meshlets": len(m),
        "tris_per_meshlet": tris.mean(),
        "verts_per_meshlet": m.meshlets[:, 2].mean(),
        # triangle-weighted: the share of triangles that never reach the mesh shader
        **{
            f"culled_{k}": float((v * tris).sum() / (tris.sum() * len(cams)))
            for k, v in culled.items()
        },
        "backfacing": float(1 - _front_facing(pos, m.triangle_indices(), cams)[0].mean()),
    }


@pytest.mark.parametrize("name", MESH_NAMES)
def test_quality_report(name):
    # measured, not asserted (run with -s to read); sanity only
    for cw in (0.0, 0.25, 0.5):
        q = _quality(name, cw)
        print(f"{name:20s} cone_weight={cw:4.2f} " + " ".join(
            f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in q.items()))  # fmt: skip
        assert q["culled_apex"] <= q["backfacing"] + 1e-9


# ---------------------------------------------------------------------------------------------
# GPU packing


@pytest.mark.parametrize("name", ["uv_sphere", "bumpy_plane", "cube"])
def test_pack_for_gpu_round_trips(name):
    m = _built(name)
    g = pack_for_gpu(m)
    assert all(a.flags.c_contiguous for a in g.values())
    assert g["meshlets"].dtype == np.uint32 and g["triangles"].dtype == np.uint32
    assert g["spheres"].shape == (len(m), 4) and g["cone_apex"].shape == (len(m), 4)
    words = g["triangles"]
    decoded = []
    for vo, wo, vc, tc in g["meshlets"].astype(np.int64):
        i = np.arange(3 * tc)
        # as a shader reads it: byte i of the run is bits 8 * (i % 4) of word i / 4
        local = (words[wo + i // 4] >> (8 * (i % 4)).astype(np.uint32)) & 0xFF
        assert local.max() < vc
        decoded.append(g["vertices"][vo + local.astype(np.int64)].reshape(-1, 3))
    np.testing.assert_array_equal(np.concatenate(decoded), m.triangle_indices())
    np.testing.assert_array_equal(g["spheres"][:, :3], m.bounds.center)
    np.testing.assert_array_equal(g["spheres"][:, 3], m.bounds.radius)
    cone_bytes = g["cones"].view(np.uint8).reshape(-1, 4).view(np.int8)
    np.testing.assert_array_equal(cone_bytes[:, :3], m.bounds.cone_axis_s8)
    np.testing.assert_array_equal(cone_bytes[:, 3], m.bounds.cone_cutoff_s8)
    np.testing.assert_array_equal(g["cone_apex"][:, :3], m.bounds.cone_apex)


# ---------------------------------------------------------------------------------------------
# disk cache


def _assert_same(a: Meshlets, b: Meshlets) -> None:
    for field in ("meshlets", "vertices", "triangles"):
        x, y = getattr(a, field), getattr(b, field)
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)
    for field in vars(a.bounds):
        x, y = getattr(a.bounds, field), getattr(b.bounds, field)
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)


def test_cache_hit_returns_equal_arrays(tmp_path, monkeypatch):
    pos, faces = _meshes()["torus"]
    first = cached_meshlets(pos, faces, cache_dir=tmp_path)
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and files[0].suffix == ml.CACHE_SUFFIX
    key = ml.meshlet_cache_key(pos, faces, max_vertices=64, max_triangles=124, cone_weight=0.25)
    assert files[0].stem == key and len(key) == 64

    def no_build(*args, **kwargs):
        raise AssertionError("cache miss")

    monkeypatch.setattr(ml, "build_meshlets", no_build)
    second = cached_meshlets(pos, faces, cache_dir=tmp_path)
    _assert_same(first, second)
    _assert_same(first, _built("torus"))

    # other parameters, other entry; the environment variable picks the folder
    monkeypatch.undo()
    monkeypatch.setenv("RFW_CACHE_MESHLETS", str(tmp_path / "env"))
    other = cached_meshlets(pos, faces, cone_weight=0.5)
    assert len(list((tmp_path / "env").iterdir())) == 1
    assert not (tmp_path / "env" / f"{key}{ml.CACHE_SUFFIX}").exists()
    _assert_same(other, _built("torus", cone_weight=0.5))


DAMAGES = {
    "not a zip": lambda good: b"not a zip",
    "empty": lambda good: b"",
    "header only": lambda good: good[:40],
    "truncated": lambda good: good[: len(good) // 2],
    "one byte flipped": lambda good: good[:-7] + bytes([good[-7] ^ 0x20]) + good[-6:],
    "bare npz of old": lambda good: good[40:],  # the payload without magic and checksum
}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_cache_rebuilds_a_damaged_entry(tmp_path, capfd, damage):
    pos, faces = _meshes()["cube"]
    key = ml.meshlet_cache_key(pos, faces, max_vertices=64, max_triangles=124, cone_weight=0.25)
    entry = tmp_path / f"{key}{ml.CACHE_SUFFIX}"
    cached_meshlets(pos, faces, cache_dir=tmp_path)
    good = entry.read_bytes()
    entry.write_bytes(DAMAGES[damage](good))
    assert entry.read_bytes() != good  # the damage is real
    capfd.readouterr()
    _assert_same(cached_meshlets(pos, faces, cache_dir=tmp_path), _built("cube"))
    err = capfd.readouterr().err.splitlines()
    assert err == [f"rfw: warning: {entry}: corrupt cache entry, rebuilt"]
    assert entry.read_bytes() == good  # healed
    _assert_same(cached_meshlets(pos, faces, cache_dir=tmp_path), _built("cube"))
    assert capfd.readouterr().err == ""  # the healed entry is a hit, without a warning
    assert [p.name for p in tmp_path.iterdir()] == [entry.name]  # no temporary left behind


def test_cache_hit_reads_the_entry_not_a_rebuild(tmp_path, monkeypatch):
    # negative control of the checks above: a good entry is used as it is, with no warning
    pos, faces = _meshes()["cube"]
    cached_meshlets(pos, faces, cache_dir=tmp_path)
    monkeypatch.setattr(ml, "build_meshlets", lambda *a, **k: pytest.fail("rebuilt"))
    _assert_same(cached_meshlets(pos, faces, cache_dir=tmp_path), _built("cube"))


def test_unwritable_cache_folder_warns_and_still_builds(tmp_path, capfd):
    pos, faces = _meshes()["cube"]
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder would be")
    _assert_same(cached_meshlets(pos, faces, cache_dir=blocker / "meshlets"), _built("cube"))
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"rfw: warning: {blocker / 'meshlets'}: cannot "
                                                "write the meshlet cache")
