"""Acceleration structures as frame-graph resources: barriers, culling, lifetimes, checks."""

from __future__ import annotations

from pathlib import Path

import pytest

from rfw.graph import AccelStructure, DepthAttachment, GraphBuilder, GraphError, Texture, compile

from ..cli.warm import warm_cli

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


# `rfw graph plan` on the ray-tracing configs, through the real CLI ---------------------------

ROOT = Path(__file__).resolve().parents[2]
RT_CAPS = "VK_KHR_acceleration_structure,VK_KHR_ray_query,VK_KHR_ray_tracing_pipeline"
BUILD_WRITE = "ACCELERATION_STRUCTURE_BUILD_KHR:ACCELERATION_STRUCTURE_WRITE_KHR"
BUILD_RW = ("ACCELERATION_STRUCTURE_BUILD_KHR:ACCELERATION_STRUCTURE_READ_KHR|"
            "ACCELERATION_STRUCTURE_WRITE_KHR")


def _plan(*args: str) -> list[str]:
    done = warm_cli("graph", "plan", *args, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def _barrier_line(lines: list[str], pass_name: str, resource: str) -> str | None:
    head = f"  {pass_name} / {resource}: "
    return next((line for line in lines if line.startswith(head)), None)


def _accel_barriers(lines: list[str], tracer: str, stage: str) -> None:
    # the build waits for the last frame's traces (the TLAS) and builds (its scratch) ...
    build = _barrier_line(lines, "accel", "accel.tlas")
    assert build is not None and f"|{stage}:" in build and build.endswith(f"-> {BUILD_RW}")
    assert _barrier_line(lines, "accel", "accel.scratch") == \
        f"  accel / accel.scratch: - -> -; {BUILD_WRITE} -> {BUILD_RW}"
    # ... and the tracer waits for the build
    assert _barrier_line(lines, tracer, "accel.tlas") == \
        f"  {tracer} / accel.tlas: - -> -; {BUILD_WRITE} -> {stage}:ACCELERATION_STRUCTURE_READ_KHR"


def test_plan_prints_rt_primary_acceleration_structure_barriers():
    _accel_barriers(_plan("configs/rt_primary.toml"), "primary", "RAY_TRACING_SHADER_KHR")


def test_plan_prints_rt_shadows_acceleration_structure_barriers_for_a_ray_tracing_device():
    lines = _plan("configs/rt_shadows.toml", "--caps", RT_CAPS)
    _accel_barriers(lines, "rt_shadows", "COMPUTE_SHADER")  # auto: ray queries first
    # rt_ao traces in the same stage after rt_shadows: the TLAS is already visible to it
    assert _barrier_line(lines, "rt_ao", "accel.tlas") is None
    # negative control: without those capabilities auto means the raster techniques, and
    # the plan has no acceleration structure at all
    raster = _plan("configs/rt_shadows.toml")
    assert not any("accel" in line for line in raster if " / " in line)
    with pytest.raises(AssertionError):
        _accel_barriers(raster, "rt_shadows", "COMPUTE_SHADER")


def test_plan_with_caps_a_pass_lacks_is_one_error_line():
    done = warm_cli("graph", "plan", "configs/rt_primary.toml", "--caps", "VK_KHR_ray_query",
                    cwd=ROOT)
    assert done.returncode == 2 and done.stderr.startswith("rfw: error: ")
    assert len(done.stderr.splitlines()) == 1 and "accel" in done.stderr
