"""rfw.RayScene: built once, cast many times, the same hits as rfw.raycast and Embree.

Reuse is counted, not timed: the acceleration-structure builds (SceneAccel._build) and the
buffers created (vkext.buffers.Buffer) while casting; a second scene is the negative control
(it builds again). Bad rays are refused in one line naming the argument and the first bad
row, the non-finite and zero ones by the shaders as they read them (a bad ray is never
traced), with clean rays as the negative control.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import rfw
from rfw.errors import RfwError
from vkext import buffers as vk_buffers
from vkext.accel import scene_accel

from .embree_ref import embree_cast, flatten
from .test_raycast import MESHES, METHODS, _check_against, _method, _rays_around


@pytest.fixture(autouse=True)
def _needs_ray_tracing(vk_device):
    if "VK_KHR_acceleration_structure" not in vk_device.caps:
        pytest.skip("no VK_KHR_acceleration_structure")


@pytest.fixture
def counts(monkeypatch):
    """How many acceleration-structure builds and buffers were made (live counters)."""
    made = {"builds": 0, "buffers": 0}
    build, init = scene_accel.SceneAccel._build, vk_buffers.Buffer.__init__

    def counted_build(self, *a, **k):
        made["builds"] += 1
        return build(self, *a, **k)

    def counted_init(self, *a, **k):
        made["buffers"] += 1
        return init(self, *a, **k)

    monkeypatch.setattr(scene_accel.SceneAccel, "_build", counted_build)
    monkeypatch.setattr(vk_buffers.Buffer, "__init__", counted_init)
    return made


def _same(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("method", METHODS)
def test_casts_equal_raycast_and_embree(vk_device, method):
    """Three casts of one scene: each equals rfw.raycast's answer bit for bit and agrees
    with Embree as tests/vkext/test_raycast.py requires."""
    method = _method(vk_device, method)
    mesh = MESHES["torus"]
    v = mesh.vertices.astype(np.float32)
    with rfw.RayScene(v, mesh.faces, device=vk_device, method=method) as scene:
        for seed in (1, 2, 1):
            o, d = _rays_around(v, 4000, seed=seed)
            got = scene.cast(o, d)
            _same(got, rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=method))
            ref = embree_cast(v, mesh.faces, o, d)
            _check_against(ref, got, o, d, float(np.abs(v).max()))


def test_from_scene_equals_raycast_of_the_scene(vk_device, courtyard):
    scene = courtyard
    v, f, owner = flatten(scene)
    o, d = _rays_around(v, 6000, seed=21)
    with rfw.RayScene.from_scene(scene, device=vk_device) as rs:
        got = rs.cast(o, d)
    _same(got, rfw.raycast(origins=o, directions=d, scene=scene, device=vk_device))
    hit = got["primitive"] >= 0
    assert hit.sum() > len(o) // 4
    ref = embree_cast(v, f, o, d)
    # Embree numbers the flattened triangles: (instance, primitive) of the same triangle
    ref_owner = owner[np.maximum(ref["primitive"], 0)]
    same = (got["instance"] == ref_owner[:, 0]) & (got["primitive"] == ref_owner[:, 1])
    assert same[hit].mean() >= 0.99


def test_intervals_as_numbers_and_as_arrays_agree(vk_device):
    """t_min/t_max as numbers (push constants) and as per-ray arrays (streams) give the
    same hits; a t_max short of the hit misses (the interval really reaches the GPU)."""
    mesh = MESHES["icosphere"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 3000, seed=4)
    n = len(o)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as scene:
        full = scene.cast(o, d)
        hit = np.isfinite(full["t"])
        assert hit.mean() > 0.25
        _same(scene.cast(o, d, t_min=0.0, t_max=np.inf),
              scene.cast(o, d, t_min=np.zeros(n), t_max=np.full(n, np.inf)))
        _same(scene.cast(o, d, t_max=0.05), scene.cast(o, d, t_max=np.full(n, 0.05)))
        short = scene.cast(o, d, t_max=np.where(hit, full["t"] * 0.99, np.inf))
        assert not np.isfinite(short["t"][hit]).any()


def test_one_build_for_many_casts(vk_device, counts):
    mesh = MESHES["capsule"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 2000, seed=6)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as scene:
        assert counts["builds"] == 1
        first = scene.cast(o, d)
        after_first = counts["buffers"]
        assert after_first > 0  # the ray and hit buffers are made by the first cast
        for _ in range(4):
            _same(scene.cast(o, d), first)
            scene.cast(o[:500], d[:500])  # a smaller batch fits in them
        assert counts == {"builds": 1, "buffers": after_first}
        # a larger batch grows them once, and that size is kept
        big_o, big_d = np.concatenate([o, o]), np.concatenate([d, d])
        scene.cast(big_o, big_d)
        grown = counts["buffers"]
        assert grown > after_first
        scene.cast(big_o, big_d)
        scene.cast(o, d)
        assert counts == {"builds": 1, "buffers": grown}
    # negative control: another scene builds (and allocates) again
    with rfw.RayScene(v, mesh.faces, device=vk_device) as other:
        other.cast(o, d)
    assert counts["builds"] == 2 and counts["buffers"] > grown


def test_batches_reuse_the_buffers(vk_device, counts):
    """With batch=97 the buffers hold 97 rays and every batch goes through them."""
    mesh = MESHES["icosphere"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 1000, seed=8)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as whole:
        ref = whole.cast(o, d)
    before = counts["buffers"]
    with rfw.RayScene(v, mesh.faces, device=vk_device, batch=97) as scene:
        _same(scene.cast(o, d), ref)
        assert scene.last["batches"] == 11
        made = counts["buffers"] - before
        _same(scene.cast(o, d), ref)
        assert counts["buffers"] - before == made


_TRI = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
_FACES = np.array([[0, 1, 2]])


def _rays(n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    o = np.c_[rng.uniform(0, 0.4, (n, 2)), np.ones(n)].astype(np.float32)
    return o, np.tile(np.float32([0, 0, -1]), (n, 1))


def _spoiled(what: str, row: int) -> tuple[np.ndarray, np.ndarray]:
    o, d = _rays()
    if what == "nan origin":
        o[row, 1] = np.nan
    elif what == "inf direction":
        d[row, 2] = -np.inf
    elif what == "zero direction":
        d[row] = 0.0
    return o, d


@pytest.mark.parametrize(("what", "message"), [
    ("nan origin", "origins has non-finite values (first in row 250)"),
    ("inf direction", "directions has non-finite values (first in row 250)"),
    ("zero direction", "directions has zero-length rows (first: 250)"),
])
@pytest.mark.parametrize("batch", [None, 97])
def test_bad_rays_are_refused_by_the_gpu(vk_device, what, message, batch):
    """The shaders check the rays (batch 97: row 250 is in the third batch), and the scene
    goes on casting afterwards; clean rays are the negative control."""
    with rfw.RayScene(_TRI, _FACES, device=vk_device, batch=batch) as scene:
        o, d = _spoiled(what, 250)
        with pytest.raises(RfwError) as err:
            scene.cast(o, d)
        assert str(err.value) == f"RayScene.cast: {message}"
        o, d = _rays()
        assert np.isfinite(scene.cast(o, d)["t"]).all()
        with pytest.raises(RfwError, match=r"(row|first:) 0\)$"):  # a bad first row too
            scene.cast(*_spoiled(what, 0))


def test_bad_rays_without_triangles_are_refused_too(vk_device):
    """A scene with no triangles traces nothing: the host checks the rays instead."""
    with rfw.RayScene(_TRI, np.zeros((0, 3), np.int32), device=vk_device) as scene:
        o, d = _rays()
        assert (scene.cast(o, d)["primitive"] == -1).all()
        with pytest.raises(RfwError, match=r"^RayScene.cast: directions has zero-length rows "
                                            r"\(first: 250\)$"):
            scene.cast(*_spoiled("zero direction", 250))


@pytest.mark.parametrize(("make", "args", "argument"), [
    ("scene", {"vertices": _TRI[:, :2]}, "vertices must have shape"),
    ("scene", {"vertices": np.zeros((0, 3), np.float32), "indices": np.zeros((0, 3), int)},
     "vertices is empty"),
    ("scene", {"vertices": np.float32([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]])},
     "vertices has non-finite values"),
    ("scene", {"indices": np.array([[0, 1, 3]])}, "indices must lie in"),
    ("scene", {"method": "rasterise"}, "method is"),
    ("scene", {"batch": 0}, "batch must be"),
    ("cast", {"origins": _rays()[0][:, :2]}, "origins must have shape"),
    ("cast", {"origins": _rays()[0].astype(str)}, "origins must be a real-valued"),
    ("cast", {"directions": _rays()[1][:5]}, "origins has 300 rows, directions 5"),
    ("cast", {"t_min": -1.0}, "t_min must be non-negative"),
    ("cast", {"t_max": np.float32([1, 2])}, "t_max must be a number or have shape"),
    ("cast", {"t_min": 2.0, "t_max": 1.0}, "t_max is below t_min"),
    ("cast", {"t_max": np.nan}, "t_max must be non-negative and not NaN"),
])
def test_bad_input_is_one_line(vk_device, make, args, argument):
    scene_args = {"vertices": _TRI, "indices": _FACES, "device": vk_device}
    o, d = _rays()
    cast_args = {"origins": o, "directions": d}
    (scene_args if make == "scene" else cast_args).update(args)
    with pytest.raises(RfwError) as err, rfw.RayScene(**scene_args) as scene:
        scene.cast(**cast_args)
    text = str(err.value)
    assert argument in text and "\n" not in text
    assert text.startswith("rfw.RayScene: " if make == "scene" else "RayScene.cast: ")


def test_from_scene_takes_a_scene(vk_device):
    with pytest.raises(RfwError,
                       match=r"^RayScene\.from_scene: scene must be an rfw\.scene\.Scene"):
        rfw.RayScene.from_scene("courtyard", device=vk_device)


def test_a_closed_scene_refuses(vk_device):
    from vkext import VkDevice

    o, d = _rays()
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        assert not scene.closed
        scene.cast(o, d)
    assert scene.closed
    scene.close()  # twice is fine
    with pytest.raises(RfwError, match=r"^RayScene.cast: the ray scene is closed: make a new "
                                        r"rfw.RayScene$"):
        scene.cast(o, d)
    # its device destroyed, a scene is closed as well (and nothing is left to free)
    device = VkDevice(label="rfw-tests-ray-scene")
    try:
        scene = rfw.RayScene(_TRI, _FACES, device=device)
        scene.cast(o, d)
    finally:
        device.destroy()
    assert scene.closed
    with pytest.raises(RfwError, match="closed"):
        scene.cast(o, d)
    scene.close()


def test_closing_frees_what_it_built(vk_device):
    """Leak check: live vkext objects return to the baseline after close."""
    o, d = _rays()
    # the device's raycaster (its pipeline) is made on first use and kept for every scene:
    # made here, whichever test ran first on this worker
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        scene.cast(o, d)
    before = vk_device.live_objects()
    for _ in range(3):
        with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
            scene.cast(o, d)
            assert vk_device.live_objects() != before  # negative control: it holds objects
    assert vk_device.live_objects() == before


def test_import_rfw_does_not_load_vulkan_for_ray_scene():
    code = ("import sys, rfw; c = rfw.RayScene; import rfw.raycasting; "
            "assert rfw.RayScene is c and c.__name__ == 'RayScene'; "
            "assert 'vulkan' not in sys.modules and 'vkext' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_split_copies_give_the_same_hits(vk_device, monkeypatch):
    """Host copies split among threads (forced here on small casts) give the hits of whole
    copies; the parts really went through the copy (counted), with tmin/tmax streams too,
    and the pool was asked for its threads."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from vkext.raycast import copies as rc

    mesh = MESHES["noisy_sphere"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 5001, seed=13)
    t_max = np.full(len(o), 50.0)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as scene:
        whole, whole_arrays = scene.cast(o, d), scene.cast(o, d, t_max=t_max)
        parts, threads, submits = [], set(), []
        copy = rc._copy

        def counting(dst, src):
            parts.append(dst.nbytes)
            threads.add(threading.get_ident())
            copy(dst, src)

        class Counting(ThreadPoolExecutor):
            def submit(self, fn, *args):
                submits.append(fn)
                return super().submit(fn, *args)

        pool = Counting(2)
        monkeypatch.setattr(rc, "_copy_pool", pool)
        monkeypatch.setattr(rc, "_copy", counting)
        monkeypatch.setattr(rc, "COPY_THREADS", 3)
        monkeypatch.setattr(rc, "COPY_SPLIT", 1024)
        try:
            _same(scene.cast(o, d), whole)
            # rays: 2 streams, hits: 3 (no instance), 2 * 3 parts each, of uneven sizes;
            # 2 pool threads asked to help per copy (one batch: one copy in, one out)
            assert len(parts) == 5 * 6 and len(set(parts)) > 1 and len(submits) == 2 * 2
            _same(scene.cast(o, d, t_max=t_max), whole_arrays)
            assert len(parts) == 5 * 6 + 7 * 6 and len(submits) == 4 * 2
            assert threading.get_ident() in threads  # this thread copies its share
        finally:
            pool.shutdown()


def test_parallel_copy_needs_no_pool_thread(monkeypatch):
    """The calling thread takes parts too, so a copy ends even if no pool thread ever
    starts (a late one finds nothing left): here the pool runs nothing at all."""
    from vkext.raycast import copies as rc

    class Idle:
        def submit(self, fn, *args):
            self.asked = getattr(self, "asked", 0) + 1

    idle = Idle()
    monkeypatch.setattr(rc, "_copy_pool", idle)
    monkeypatch.setattr(rc, "COPY_THREADS", 4)
    src = np.arange(1 << 18, dtype=np.float32)
    dst = np.zeros_like(src)
    assert rc.parallel_copy([(dst, src)]) is False
    np.testing.assert_array_equal(dst, src)
    assert idle.asked == 3  # control: the pool was asked, and did nothing


@pytest.mark.parametrize("split", [False, True])
def test_parallel_copy_finds_nan_in_the_checked_job(monkeypatch, split):
    """``check`` names the job whose copy is scanned for NaN (whole or in parts); a NaN in
    another job is not its business (negative control)."""
    from vkext.raycast import copies as rc

    if split:
        monkeypatch.setattr(rc, "COPY_THREADS", 3)
        monkeypatch.setattr(rc, "COPY_SPLIT", 1024)
    t = np.ones(50_000, np.float32)
    other = np.ones(50_000, np.float32)
    jobs = lambda: [(np.empty_like(other), other), (np.empty_like(t), t)]  # noqa: E731
    assert rc.parallel_copy(jobs(), check=1) is False
    other[40_000] = np.nan
    assert rc.parallel_copy(jobs(), check=1) is False
    assert rc.parallel_copy(jobs(), check=0) is True
    t[49_999] = np.nan  # in the last part
    assert rc.parallel_copy(jobs(), check=1) is True
    assert rc.parallel_copy(jobs()) is False


def test_parallel_copy_copies_every_element():
    from vkext.raycast import parallel_copy

    rng = np.random.default_rng(1)
    src = [rng.random(n).astype(np.float32) for n in (0, 1, 5, 1 << 19, (1 << 19) + 7)]
    dst = [np.zeros_like(s) for s in src]
    parallel_copy(list(zip(dst, src, strict=True)))
    for a, b in zip(dst, src, strict=True):
        np.testing.assert_array_equal(a, b)
    dst[3][123] = -1.0  # negative control: the comparison sees one element off
    assert not np.array_equal(dst[3], src[3])


@pytest.mark.parametrize("cached", [True, False])
def test_parallel_copy_converts_any_layout(cached):
    """Rows of rays in Fortran order, float64 or strided views land in C-order float32 as
    astype would round them, column by column (cached) or in order (write-combined)."""
    from vkext.raycast import parallel_copy

    rng = np.random.default_rng(2)
    base = rng.normal(size=((1 << 17) + 3, 3)) * 1e3
    wide = np.zeros((len(base), 5))
    wide[:, 1:4] = base
    for src in (np.asfortranarray(base), np.asfortranarray(base.astype(np.float32)),
                wide[:, 1:4], base[::-1]):
        dst = np.zeros(src.shape, np.float32)
        parallel_copy([(dst, src)], cached=cached)
        np.testing.assert_array_equal(dst, src.astype(np.float32))
        assert not np.array_equal(dst, src.astype(np.float16))  # control: rounding shows


PLACEMENTS = {"staged": "0", "mapped": "1", "rays mapped": "rays", "hits mapped": "hits",
              "host": "host"}


def _placed(monkeypatch, placement: str) -> None:
    monkeypatch.setenv("RFW_RAYCAST_MAPPED", PLACEMENTS[placement])


@pytest.mark.parametrize("placement", list(PLACEMENTS))
@pytest.mark.parametrize("method", METHODS)
def test_repeated_casts_of_changing_sizes(vk_device, monkeypatch, counts, method, placement):
    """One scene casts 300, 3000, 40, 3000, 12000 and 300 rays (batch 4096: the largest in
    three batches, two in flight): the buffers grow twice, never shrink, and every cast equals staged
    rfw.raycast's hits bit for bit, so no cast reads another's rays or hits. Negative
    control: one ray turned gives different hits."""
    method = _method(vk_device, method)
    mesh = MESHES["noisy_sphere"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 12000, seed=17)
    _placed(monkeypatch, "staged")
    ref = rfw.raycast(v, mesh.faces, o, d, device=vk_device, method=method)
    _placed(monkeypatch, placement)
    with rfw.RayScene(v, mesh.faces, device=vk_device, method=method, batch=4096) as scene:
        assert scene._scene.buffers.placement == placement
        made = []
        for n in (300, 3000, 40, 3000, 12000, 300):
            got = scene.cast(o[:n], d[:n])
            _same(got, {k: a[:n] for k, a in ref.items()})
            made.append(scene._scene.allocations)
        assert made == [1, 2, 2, 2, 3, 3]
        turned = d.copy()
        turned[123] = -turned[123]
        assert not np.array_equal(scene.cast(o, turned)["t"], ref["t"])


def test_staged_and_mapped_give_the_same_hits(vk_device, courtyard, monkeypatch):
    """On the courtyard (every instance), casts through copies and through mapped memory
    (both streams or one) agree bit for bit; per-ray intervals go through all too."""
    scene = courtyard
    v, _, _ = flatten(scene)
    o, d = _rays_around(v, 7000, seed=31)
    t_max = np.random.default_rng(3).uniform(1.0, 40.0, len(o))
    got = {}
    for placement in PLACEMENTS:
        _placed(monkeypatch, placement)
        with rfw.RayScene.from_scene(scene, device=vk_device, batch=3000) as rs:
            got[placement] = (rs.cast(o, d), rs.cast(o, d, t_max=t_max))
            assert rs.last["batches"] == 3
    for placement in PLACEMENTS:
        for a, b in zip(got["staged"], got[placement], strict=True):
            _same(a, b)
    # t_max acts: a ray whose nearest hit lies past its t_max misses, every other keeps its
    # hit (measured: 9 of the 7000 rays hit past theirs)
    full, capped = got["staged"]
    past = np.isfinite(full["t"]) & (full["t"] > t_max.astype(np.float32))
    assert past.sum() >= 5 and np.isinf(capped["t"][past]).all()
    assert np.array_equal(capped["t"][~past], full["t"][~past])


def test_ray_layouts_and_dtypes_give_the_same_hits(vk_device):
    """Rays as float64, Fortran-ordered or strided views are converted while they are
    copied: the hits equal those of float32 C-contiguous rays bit for bit. Negative
    control: rays rounded to float16 first give other hits."""
    mesh = MESHES["torus"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 3000, seed=5)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as scene:
        ref = scene.cast(o, d)
        wide = np.zeros((len(o), 8), np.float32)
        wide[:, 1:4], wide[:, 4:7] = o, d
        for oo, dd in ((o.astype(np.float64), d.astype(np.float64)),
                       (np.asfortranarray(o), np.asfortranarray(d)),
                       (wide[:, 1:4], wide[:, 4:7]),
                       (o[::-1][::-1], np.asfortranarray(d.astype(np.float64)))):
            _same(scene.cast(oo, dd), ref)
        rounded = scene.cast(o.astype(np.float16), d.astype(np.float16))
        assert not np.array_equal(rounded["t"], ref["t"])


def test_out_arrays_are_filled_and_returned(vk_device, monkeypatch):
    """Casts into given arrays return those very arrays with the hits of a plain cast, for
    every key or some; a larger cast into the same arrays is refused (their shape)."""
    mesh = MESHES["icosphere"]
    v = mesh.vertices.astype(np.float32)
    o, d = _rays_around(v, 2500, seed=9)
    with rfw.RayScene(v, mesh.faces, device=vk_device) as scene:
        ref = scene.cast(o, d)
        out = {k: np.full_like(a, 7) for k, a in ref.items()}
        for _ in range(2):
            got = scene.cast(o, d, out=out)
            assert all(got[k] is out[k] for k in out)
            _same(got, ref)
        only_t = {"t": np.empty(len(o), np.float32)}
        got = scene.cast(o, d, out=only_t)
        assert got["t"] is only_t["t"] and got["primitive"] is not out["primitive"]
        _same(got, ref)
        # negative control: the arrays really are written (a stale one would not match)
        out["t"][:] = 0
        assert not np.array_equal(out["t"], ref["t"])
        scene.cast(o, d, out=out)
        _same(out, ref)
    # a scene without triangles fills them with misses
    with rfw.RayScene(_TRI, np.zeros((0, 3), np.int32), device=vk_device) as empty:
        got = empty.cast(o, d, out=out)
        assert got["t"] is out["t"] and np.isinf(out["t"]).all()
        assert (out["primitive"] == -1).all() and not out["barycentrics"].any()


def _bad_out(n: int) -> list[tuple[object, str]]:
    t = np.empty(n, np.float32)
    ro = np.empty(n, np.float32)
    ro.flags.writeable = False
    return [
        ({"t": np.empty(n, np.float64)}, "out['t'] must be a writable C-contiguous float32 "
                                         f"array of shape ({n},), got float64 ({n},)"),
        ({"t": t[:-1]}, f"got float32 ({n - 1},)"),
        ({"barycentrics": np.empty((2, n), np.float32).T}, "not C-contiguous"),
        ({"t": ro}, "read-only"),
        ({"primitive": [0] * n}, "got list"),
        ({"instance": np.empty(n, np.int32)}, "out has 'instance', which this scene does "
                                              "not return (it returns t, primitive, "
                                              "barycentrics)"),
        ([t], "out must be a dict of arrays by name, got list"),
    ]


@pytest.mark.parametrize("case", range(7))
def test_bad_out_is_one_line(vk_device, case):
    o, d = _rays()
    out, message = _bad_out(len(o))[case]
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        with pytest.raises(RfwError) as err:
            scene.cast(o, d, out=out)
        text = str(err.value)
        assert text.startswith("RayScene.cast: ") and message in text and "\n" not in text
        assert np.isfinite(scene.cast(o, d)["t"]).all()  # the scene goes on casting


def test_a_bad_placement_setting_is_one_line(vk_device, monkeypatch):
    monkeypatch.setenv("RFW_RAYCAST_MAPPED", "yes")
    with pytest.raises(RfwError, match=r"^RFW_RAYCAST_MAPPED: expected 0, 1, rays, "
                                        r"hits, host or auto, not 'yes'$"):
        rfw.RayScene(_TRI, _FACES, device=vk_device)
    monkeypatch.setenv("RFW_RAYCAST_MAPPED", "auto")  # control: the documented values pass
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        assert np.isfinite(scene.cast(*_rays())["t"]).all()


def test_last_breaks_the_cast_down(vk_device):
    """``last`` names where a cast's time went: the host's parts and, with timestamps, the
    GPU's (each batch's queries read once after the cast)."""
    from vkext.raycast import GPU_PARTS, HOST_PARTS

    o, d = _rays()
    with rfw.RayScene(_TRI, _FACES, device=vk_device, batch=97) as scene:
        scene.cast(o, d)
        last = scene.last
    assert last["batches"] == 4
    keys = HOST_PARTS + (GPU_PARTS if "timestamp" in vk_device.caps else ())
    assert all(last[k] >= 0 for k in keys)
    assert sum(last[k] for k in HOST_PARTS) <= last["wall_ms"]


def test_a_cast_like_the_last_records_nothing(vk_device):
    """Each batch's command buffer is kept: a cast like the last one only submits (counted
    recordings), with the same hits; another interval or ray count records again (negative
    controls), and its hits show the new commands really ran."""
    o, d = _rays()
    with rfw.RayScene(_TRI, _FACES, device=vk_device, batch=97) as scene:
        caster = scene._scene.caster
        first = scene.cast(o, d)
        recorded = caster.recorded
        for _ in range(3):
            _same(scene.cast(o, d), first)
        assert caster.recorded == recorded
        short = scene.cast(o, d, t_max=0.5)  # every ray's hit is at t = 1
        assert caster.recorded == recorded + 4 and np.isinf(short["t"]).all()
        _same(scene.cast(o, d), first)
        assert caster.recorded == recorded + 8
        _same(scene.cast(o[:150], d[:150]), {k: a[:150] for k, a in first.items()})
        assert caster.recorded == recorded + 8 + 1  # batch 1 of 2 has fewer rays


@pytest.mark.parametrize("placement", list(PLACEMENTS))
def test_mapped_batches_copy_nothing(vk_device, monkeypatch, placement):
    """Mapped hits are not copied out (the trace writes the host's memory), mapped rays
    have no device buffer to be copied into; staged hits are copied out once per batch
    (the control that the count sees them)."""
    from vkext.raycast import caster as rc

    copies = []
    copy_to_host = rc.copy_to_host
    monkeypatch.setattr(rc, "copy_to_host", lambda *a, **k: (copies.append(1),
                                                              copy_to_host(*a, **k)))
    _placed(monkeypatch, placement)
    o, d = _rays()
    with rfw.RayScene(_TRI, _FACES, device=vk_device, batch=97) as scene:
        assert np.isfinite(scene.cast(o, d)["t"]).all()
        buffers = scene._scene.buffers
        assert (buffers.rays is None) is (placement in ("mapped", "rays mapped", "host"))
    assert len(copies) == (0 if placement in ("mapped", "hits mapped", "host") else 4)
