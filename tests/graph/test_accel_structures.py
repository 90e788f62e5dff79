"""Acceleration structures as frame-graph resources: barriers, culling, lifetimes, checks."""

from __future__ import annotations

import pytest

from rfw.graph import AccelStructure, DepthAttachment, GraphBuilder, GraphError, Texture, compile

BUILD = {"ACCELERATION_STRUCTURE_BUILD_KHR"}
AS_READ = {"ACCELERATION_STRUCTURE_READ_KHR"}


def _graph(reader_type: str = "compute", *, readers: int = 1, output: bool = True):
    g = GraphBuilder("rt", size=(64, 32))
    g.add_pass("gbuffer", "graphics").output("depth", DepthAttachment())
    g.add_pass("accel", "compute").output("tlas", AccelStructure())
    for k in range(readers):
        (g.add_pass(f"trace{k}", reader_type).input("depth", "gbuffer.depth")
         .input("tlas", "accel.tlas", AccelStructure()).output("vis", Texture("r32uint")))
    g.add_pass("light", "compute").input("vis", "trace0.vis").output("hdr", Texture("rgba16float"))
    if output:
        g.output("light.hdr")
    return g.build()


def _barrier(plan, pass_name, resource):
    found = [b for b in plan.barriers if b.pass_name == pass_name and b.resource == resource]
    return found[0] if found else None


@pytest.mark.parametrize(("reader_type", "stage"), [("compute", "COMPUTE_SHADER"),
                                                    ("ray_tracing", "RAY_TRACING_SHADER_KHR")])
def test_barrier_from_the_build_to_the_reader(reader_type, stage):
    plan = compile(_graph(reader_type))
    assert plan.order == ("gbuffer", "accel", "trace0", "light")
    b = _barrier(plan, "trace0", "accel.tlas")
    assert b is not None
    assert b.src.stages == BUILD and b.src.access == {"ACCELERATION_STRUCTURE_WRITE_KHR"}
    assert b.dst.stages == {stage} and b.dst.access == AS_READ
    assert b.src.layout is None and b.dst.layout is None
    # the next frame's build waits for this frame's tracing (write after read)
    first = _barrier(plan, "accel", "accel.tlas")
    assert stage in first.src.stages and first.dst.stages == BUILD
    assert "ACCELERATION_STRUCTURE_WRITE_KHR" in first.dst.access


def test_second_reader_in_the_same_stage_needs_no_barrier():
    plan = compile(_graph(readers=2, output=False))
    assert _barrier(plan, "trace0", "accel.tlas") is not None
    assert _barrier(plan, "trace1", "accel.tlas") is None


def test_the_build_is_culled_with_its_readers():
    g = GraphBuilder("rt", size=(64, 32))
    g.add_pass("gbuffer", "graphics").output("albedo", Texture("rgba8unorm"))
    g.add_pass("accel", "compute").output("tlas", AccelStructure())
    (g.add_pass("trace", "compute").input("tlas", "accel.tlas", AccelStructure())
     .output("vis", Texture("r32uint")))
    g.add_pass("light", "compute").input("a", "gbuffer.albedo").output("hdr", Texture("rgba8unorm"))
    plan = compile(g.output("light.hdr").build())
    assert set(plan.culled) == {"accel", "trace"}
    assert "accel.tlas" not in [r.name for r in plan.resources]


def test_lifetime_and_memory():
    plan = compile(_graph())
    r = plan.resource("accel.tlas")
    assert r.kind == "accel" and (r.first, r.last) == ("accel", "trace0")
    # its builder owns its memory: it is in no heap and adds nothing to the plan's bytes
    assert not r.transient and r.heap is None and r.raw_bytes == 0
    assert r.usages == {"accel_build", "accel_read"}


def test_a_texture_slot_cannot_read_it():
    g = GraphBuilder("rt", size=(64, 32))
    g.add_pass("accel", "compute").output("tlas", AccelStructure())
    g.add_pass("trace", "compute").input("tlas", "accel.tlas").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match="acceleration structure, not usable as texture"):
        compile(g.output("trace.o").build())


def test_a_missing_extension_names_the_pass():
    g = GraphBuilder("rt", size=(64, 32))
    g.add_pass("accel", "compute").output("tlas", AccelStructure())
    (g.add_pass("shadows", "compute", requires=("VK_KHR_ray_query",))
     .input("tlas", "accel.tlas", AccelStructure()).output("o", Texture("r32uint")))
    with pytest.raises(GraphError, match=r"pass 'shadows'.*VK_KHR_ray_query"):
        compile(g.output("shadows.o").build(), caps={"VK_KHR_acceleration_structure"})
