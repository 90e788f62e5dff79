"""vkext.accel: BLAS reuse, compaction, refit, build plans and order, teardown, under validation.

Measured on lavapipe (Mesa 25.0.7): the courtyard's 36 meshes with triangles give 36 BLAS
(19,200 triangles) for 405 instances (164,544 triangles), 1.9 MiB of BLAS; lavapipe reports
compacted sizes equal to the built ones, so there compaction keeps the size.

Validation layer 1.3.239's synchronization validation does not track acceleration-structure
builds (a build without the BLAS -> TLAS barrier passes it silently), so the build order is
checked on the recorded command stream instead.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import vkext.commands.barriers as barriers_module
from rfw.config import apply_overrides, load_config
from rfw.graph import AccelStructure, GraphBuilder, GraphError, Step, compile
from rfw.render import render
from rfw.scene.model import Instance, Material, Scene
from vkext.accel import (
    ALPHA_MASK,
    INSTANCE_DTYPE,
    PlanRecorder,
    SceneAccel,
    build_graph,
    refit_graph,
)
from vkext.consts import const
from vkext.raycast import RAY_DTYPE, raycaster

from ..conftest import box_mesh

BUILD = {"ACCELERATION_STRUCTURE_BUILD_KHR"}
RT_PRIMARY = Path(__file__).resolve().parents[2] / "configs" / "rt_primary.toml"


@pytest.fixture(autouse=True)
def _needs_accel(vk_device):
    if "VK_KHR_acceleration_structure" not in vk_device.caps:
        pytest.skip("no VK_KHR_acceleration_structure")


def _translate(x: float, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    t = np.identity(4, np.float32)
    t[:3, 3] = x, y, z
    return t


def _row_of_boxes(n: int) -> Scene:
    """One unit box mesh placed ``n`` times along x, 3 apart."""
    s = Scene("boxes", meshes=[box_mesh(1, 1, 1)])
    s.instances = [Instance(0, _translate(3.0 * k), f"box{k}") for k in range(n)]
    return s


def _down_rays(xs, z: float = 0.0) -> np.ndarray:
    """Rays from y = 5 straight down at each x."""
    rays = np.zeros(len(xs), RAY_DTYPE)
    rays["origin"] = np.c_[xs, np.full(len(xs), 5.0), np.full(len(xs), z)]
    rays["direction"] = (0, -1, 0)
    rays["tmax"] = np.inf
    return rays


def test_one_blas_serves_every_instance_of_its_mesh(vk_device):
    scene = _row_of_boxes(5)
    with SceneAccel(vk_device, scene) as acc:
        st = acc.stats()
        assert st["blas"] == 1 and st["instances"] == 5
        assert st["triangles"] == 12 and st["instance_triangles"] == 60
        records = acc.instance_buffer.read(INSTANCE_DTYPE, 5)
        assert (records["reference"] == acc.blas[0].address).all()
        hits = raycaster(vk_device).trace(acc, _down_rays(3.0 * np.arange(5) + 0.1))
    # each ray lands on the top of its own instance (custom index = instance index)
    np.testing.assert_array_equal(hits["instance"], np.arange(5))
    np.testing.assert_allclose(hits["t"], 4.5, rtol=1e-6)


def test_courtyard_blas_per_mesh(vk_device, courtyard):
    scene = courtyard
    with SceneAccel(vk_device, scene) as acc:
        st = acc.stats()
    with_triangles = sum(1 for m in scene.meshes if len(m.indices))
    assert st["blas"] == with_triangles == 36
    assert st["instances"] == len(scene.instances) == 405
    assert st["triangles"] == sum(m.triangle_count for m in scene.meshes)
    assert st["instance_triangles"] == scene.triangle_count
    assert st["timer"] == ("gpu" if "timestamp" in vk_device.caps else "cpu")
    assert set(st["build_ms"]) == {"blas", "tlas"}
    assert all(ms > 0 for ms in st["build_ms"].values())


def test_compaction_keeps_or_shrinks_and_changes_no_answer(vk_device, courtyard):
    scene = courtyard
    rng = np.random.default_rng(1)
    rays = np.zeros(5000, RAY_DTYPE)
    rays["origin"] = rng.uniform([-35, 0.5, -35], [35, 15, 35], (5000, 3))
    rays["direction"] = rng.normal(size=(5000, 3))
    rays["tmax"] = np.inf
    rc = raycaster(vk_device)
    with SceneAccel(vk_device, scene) as plain:
        expected = rc.trace(plain, rays)
        plain_bytes = plain.stats()["blas_bytes"]
    with SceneAccel(vk_device, scene, compact=True) as small:
        st = small.stats()
        got = rc.trace(small, rays)
    assert st["blas_bytes_built"] == plain_bytes
    assert 0 < st["blas_bytes"] <= st["blas_bytes_built"]
    assert "compact" in st["build_ms"]
    assert np.isfinite(expected["t"]).mean() > 0.5
    np.testing.assert_array_equal(got, expected)


def test_refit_moves_an_instance(vk_device):
    scene = _row_of_boxes(2)
    xs = np.array([0.0, 3.0, 10.0])  # over box 0, over box 1, over where box 1 goes
    rc = raycaster(vk_device)
    with SceneAccel(vk_device, scene, allow_update=True, prefer="fast_build") as acc:
        before = rc.trace(acc, _down_rays(xs))
        tlas = acc.tlas.handle
        acc.update({1: _translate(10.0, 1.0)})  # across and up
        after = rc.trace(acc, _down_rays(xs))
        assert acc.tlas.handle == tlas  # refitted in place, not rebuilt
        assert "update" in acc.stats()["build_ms"]
        acc.update(np.stack([_translate(0.0), _translate(3.0)]))  # all of them, back
        back = rc.trace(acc, _down_rays(xs))
    np.testing.assert_array_equal(before["instance"], [0, 1, -1])
    np.testing.assert_allclose(before["t"][:2], 4.5, rtol=1e-6)
    np.testing.assert_array_equal(after["instance"], [0, -1, 1])
    np.testing.assert_allclose(after["t"][[0, 2]], [4.5, 3.5], rtol=1e-6)
    np.testing.assert_array_equal(back, before)


def test_update_needs_allow_update_and_good_transforms(vk_device):
    with SceneAccel(vk_device, _row_of_boxes(2)) as acc, \
            pytest.raises(ValueError, match="allow_update"):
        acc.update({0: np.identity(4)})
    with SceneAccel(vk_device, _row_of_boxes(2), allow_update=True) as acc:
        with pytest.raises(ValueError, match="instance 5"):
            acc.update({5: np.identity(4)})
        with pytest.raises(ValueError, match=r"\(2, 4, 4\)"):
            acc.update(np.identity(4))


def _orders_writes_before_reads(e) -> bool:
    return (e[0] == "barrier" and "ACCELERATION_STRUCTURE_BUILD_KHR" in e[1].stages
            and "ACCELERATION_STRUCTURE_WRITE_KHR" in e[1].access
            and "ACCELERATION_STRUCTURE_BUILD_KHR" in e[2].stages
            and "ACCELERATION_STRUCTURE_READ_KHR" in e[2].access)


def _unordered_builds(events) -> list[tuple]:
    """Pairs of consecutive builds with no build-stage write -> read barrier between them."""
    builds = [i for i, e in enumerate(events) if e[0] == "build"]
    return [(events[a], events[b]) for a, b in itertools.pairwise(builds)
            if not any(_orders_writes_before_reads(e) for e in events[a + 1:b])]


def _record_builds(vk_device, monkeypatch) -> list:
    """Events of the recorded stream, in order: ("barrier", src, dst) for each memory
    barrier that goes through commands.barriers.barrier, ("build", type, count) for each build."""
    events = []
    real_barrier = barriers_module.barrier
    real_build = vk_device.fn.vkCmdBuildAccelerationStructuresKHR

    def barrier(cmd, image_barriers=(), buffer_barriers=(), memory_barriers=()):
        events.extend(("barrier", s, d) for s, d in memory_barriers)
        return real_barrier(cmd, image_barriers, buffer_barriers, memory_barriers)

    def build(cmd, count, infos, ranges):
        events.append(("build", int(infos[0].type), count))
        return real_build(cmd, count, infos, ranges)

    monkeypatch.setattr(barriers_module, "barrier", barrier)
    monkeypatch.setattr(vk_device.fn, "vkCmdBuildAccelerationStructuresKHR", build)
    return events


def test_tlas_build_waits_for_the_blas_builds(vk_device, courtyard, monkeypatch):
    """In the recorded stream, a barrier from acceleration-structure writes to
    acceleration-structure reads in the build stage lies between the last BLAS build and
    the TLAS build; with several scratch batches, one also lies between batches. The
    barriers come from the build plan, recorded by ``record_barriers`` as a frame's are."""
    # the build plan's barriers go through record_barriers, as a frame's do
    events = _record_builds(vk_device, monkeypatch)
    with SceneAccel(vk_device, courtyard, scratch_budget=1) as acc:  # one BLAS per batch
        assert acc.stats()["blas_batches"] == 36
        assert acc.build_plan.order == ("blas", "tlas", "readers")
        assert acc.build_plan.steps["blas"] == tuple(f"batch{k}" for k in range(36))

    bottom = const("VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR")
    top = const("VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR")
    kinds = [e[1] for e in events if e[0] == "build"]
    assert kinds == [bottom] * 36 + [top]
    assert _unordered_builds(events) == []
    # negative control: the same stream without its barriers fails the check at every pair
    assert len(_unordered_builds([e for e in events if e[0] != "barrier"])) == 36


def test_frames_build_the_tlas_behind_the_frame_plans_barriers(vk_device, monkeypatch):
    """record_tlas records no barrier: each frame's TLAS build waits for the last one
    through the barriers the frame graph plans for accel_build's outputs, the TLAS and the
    frame scratch (a write after write in the build stage, the scratch's alone)."""
    if "VK_KHR_ray_tracing_pipeline" not in vk_device.caps:
        pytest.skip("no VK_KHR_ray_tracing_pipeline")
    events = _record_builds(vk_device, monkeypatch)
    cfg = apply_overrides(load_config(RT_PRIMARY), ["size=32x18"])
    render(cfg, scene=_row_of_boxes(3), device=vk_device, backend="vk", frames=2)

    top = const("VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR")
    tops = [i for i, e in enumerate(events) if e[:2] == ("build", top)]
    assert len(tops) == 1 + 3  # the scene's first build, then a warm-up and two frames

    def scratch_waw(e):
        return (e[0] == "barrier" and e[1].stages == BUILD
                and e[1].access == {"ACCELERATION_STRUCTURE_WRITE_KHR"}
                and e[2].stages == BUILD and "ACCELERATION_STRUCTURE_WRITE_KHR" in e[2].access)

    def unordered(stream, tops):
        return [(a, b) for a, b in itertools.pairwise(tops)
                if not any(scratch_waw(e) for e in stream[a + 1:b])]

    assert unordered(events, tops) == []
    # negative control: the stream without its barriers fails the check at every pair
    bare = [e for e in events if e[0] != "barrier"]
    assert len(unordered(bare, [i for i, e in enumerate(bare) if e[:2] == ("build", top)])) == 3


def _barrier(plan, pass_name, resource):
    return next((b for b in plan.barriers
                 if b.pass_name == pass_name and b.resource == resource), None)


def _waits_for_build_write(b) -> bool:
    return (b is not None and "ACCELERATION_STRUCTURE_BUILD_KHR" in b.src.stages
            and b.src.access == {"ACCELERATION_STRUCTURE_WRITE_KHR"})


def test_the_build_plan_orders_batches_tlas_and_readers():
    plan = compile(build_graph(3, compact=False), (1, 1))
    assert plan.order == ("blas", "tlas", "readers")
    assert plan.steps["blas"] == ("batch0", "batch1", "batch2")
    # a batch (a step of the blas pass) waits for the previous one's use of the scratch
    assert plan.barriers_before_step("blas", 0, -1) == ()
    for k in (1, 2):
        (b,) = plan.barriers_before_step("blas", k, k - 1)
        assert b.resource == "scratch" and _waits_for_build_write(b)
        assert b.dst.access == {"ACCELERATION_STRUCTURE_READ_KHR",
                                "ACCELERATION_STRUCTURE_WRITE_KHR"}
    # the TLAS build reads every batch's BLAS after its write, in the build stage
    for k in range(3):
        b = _barrier(plan, "tlas", f"blas.blas{k}")
        assert _waits_for_build_write(b)
        assert b.dst.stages == BUILD and b.dst.access == {"ACCELERATION_STRUCTURE_READ_KHR"}
    # later users of any stage see the TLAS and the BLAS
    for name in ("tlas", "blas.blas0", "blas.blas2"):
        b = _barrier(plan, "readers", name)
        assert _waits_for_build_write(b) and b.dst.stages == {"ALL_COMMANDS"}
    # negative control: batches that do not share the scratch are not ordered at all
    g = GraphBuilder("unshared", size=(1, 1))
    p = g.add_pass("blas", "compute", steps=[Step(f"batch{k}", writes=f"blas{k}")
                                             for k in range(2)])
    for k in range(2):
        p.output(f"blas{k}", AccelStructure())
    plan = compile(g.build())
    assert plan.steps["blas"] == ("batch0", "batch1")
    assert plan.barriers_before_step("blas", 1, 0) == ()


def test_the_compacting_plan_queries_before_it_copies():
    plan = compile(build_graph(2, compact=True), (1, 1))
    assert plan.order == ("blas", "compact_query", "compact", "tlas", "readers")
    assert _waits_for_build_write(_barrier(plan, "compact_query", "blas.blas1"))
    # the TLAS build reads the compacted copies, not the originals
    assert _waits_for_build_write(_barrier(plan, "tlas", "compact.blas"))
    assert _barrier(plan, "tlas", "blas.blas0") is None
    # a scene without triangles: no BLAS pass, and the TLAS build makes the scratch
    assert compile(build_graph(0, compact=True), (1, 1)).order == ("tlas", "readers")


def test_a_refit_waits_for_earlier_readers():
    plan = compile(refit_graph(), (1, 1))
    b = _barrier(plan, "refit", "tlas")  # from the last refit's readers (the plan repeats)
    assert b is not None and "ALL_COMMANDS" in b.src.stages and b.dst.stages == BUILD
    assert _waits_for_build_write(_barrier(plan, "readers", "tlas"))
    assert _waits_for_build_write(_barrier(plan, "refit", "scratch"))


def test_passes_record_in_the_plans_order():
    rec = PlanRecorder(compile(build_graph(2, compact=False), (1, 1)))
    with pytest.raises(RuntimeError, match="pass 'tlas' recorded where the plan has blas"):
        rec.enter(None, "tlas")
    with pytest.raises(GraphError, match="enters step 1 but declares no steps"):
        rec.step(None, 1)  # outside any pass; checked before anything is recorded
    assert not rec.done()


def test_instances_carry_index_mask_hit_group_and_no_culling(vk_device):
    scene = _row_of_boxes(3)
    cutout = box_mesh(1, 1, 1, "cutout")
    cutout.material = 1
    scene.meshes.append(cutout)
    scene.meshes.append(box_mesh(1, 1, 1, "empty"))
    scene.meshes[2].indices = np.zeros(0, np.uint32)
    scene.materials = [Material("solid"), Material("leaves", alpha_mode="MASK")]
    scene.instances[1] = Instance(2, _translate(3.0), "nothing")  # a mesh without triangles
    scene.instances.append(Instance(1, _translate(9.0), "cutout"))
    with SceneAccel(vk_device, scene, hit_groups={"MASK": 1}) as acc:
        assert acc.blas[2] is None and acc.hit_records == 2
        assert acc.tlas_instances == [0, 2, 3]
        rec = acc.instance_buffer.read(INSTANCE_DTYPE, 3)
        assert acc.geometry.geometry(0).flags == const("VK_GEOMETRY_OPAQUE_BIT_KHR")
        assert acc.geometry.geometry(1).flags == const(
            "VK_GEOMETRY_NO_DUPLICATE_ANY_HIT_INVOCATION_BIT_KHR")
    np.testing.assert_array_equal(rec["index_mask"] & 0xFFFFFF, [0, 2, 3])
    np.testing.assert_array_equal(rec["index_mask"] >> 24, [ALPHA_MASK["OPAQUE"],
                                                            ALPHA_MASK["OPAQUE"],
                                                            ALPHA_MASK["MASK"]])
    np.testing.assert_array_equal(rec["sbt_flags"] & 0xFFFFFF, [0, 0, 1])
    cull_off = const("VK_GEOMETRY_INSTANCE_TRIANGLE_FACING_CULL_DISABLE_BIT_KHR")
    assert ((rec["sbt_flags"] >> 24) == cull_off).all()
    np.testing.assert_array_equal(rec["transform"][2], _translate(9.0)[:3])


def test_bad_options_and_meshes_raise(vk_device):
    with pytest.raises(ValueError, match="prefer"):
        SceneAccel(vk_device, _row_of_boxes(1), prefer="fastest")
    with pytest.raises(ValueError, match="hit_groups"):
        SceneAccel(vk_device, _row_of_boxes(1), hit_groups={"GLASS": 1})
    broken = _row_of_boxes(1)
    broken.meshes[0].indices = broken.meshes[0].indices + 100
    with pytest.raises(ValueError, match="outside its 24 vertices"):
        SceneAccel(vk_device, broken)


def test_destroy_returns_every_object(vk_device, courtyard):
    # the raycaster caches its pipeline, and on the first trace its shader binding table
    # (by hit-record count) and command pool: make them outside the count. Without ray
    # queries (NVIDIA) every trace goes through that table.
    with SceneAccel(vk_device, courtyard) as warm:
        raycaster(vk_device).trace(warm, _down_rays(np.zeros(4)))
    before = vk_device.live_objects()
    for kw in ({}, {"compact": True}, {"allow_update": True}):
        acc = SceneAccel(vk_device, courtyard, **kw)
        raycaster(vk_device).trace(acc, _down_rays(np.zeros(4)))
        acc.destroy()
        acc.destroy()  # twice is harmless
    assert vk_device.live_objects() == before
