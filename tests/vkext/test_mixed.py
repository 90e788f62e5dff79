"""Frames that mix backends: configs/deferred_mixed.toml draws the shadow map and G-buffer on
wgpu and lights and tonemaps on raw Vulkan, with bridge passes copying through host memory.

The Vulkan side runs on the module's validated device (tests/vkext/conftest.py) and leaves
the layer silent, synchronization validation included. Numbers measured on lavapipe (Mesa
25.0.7, LLVM 15) are stated where they are asserted.
"""

from __future__ import annotations

import gc
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import wgpu

from rfw import ComputePass
from rfw.cli import main
from rfw.config import Built, apply_overrides, build, load_config
from rfw.frame import open_frame
from rfw.graph import Buffer, GraphBuilder, compile
from rfw.mixed import split
from rfw.render import render
from rfw.shaders import ShaderError
from vkext.commands import one_time
from vkext.fitting import check_passes, fit_graph, fit_plan

from ..conftest import tiny_scene
from ..golden_util import assert_similar, mismatch

ROOT = Path(__file__).resolve().parents[2]
MIXED = ROOT / "configs" / "deferred_mixed.toml"
BRIDGES = ("bridge.shadow.depth.wgpu-vk", "bridge.gbuffer.albedo.wgpu-vk",
           "bridge.gbuffer.normal.wgpu-vk", "bridge.gbuffer.material.wgpu-vk",
           "bridge.gbuffer.emissive.wgpu-vk", "bridge.gbuffer.depth.wgpu-vk")
ORDER = ("shadow", BRIDGES[0], "gbuffer", *BRIDGES[1:], "lighting", "tonemap")


def mixed(size: str, *sets: str):
    return apply_overrides(load_config(MIXED), [f"size={size}", *sets])


def unpinned(cfg):
    """The same config with every pass on the run's backend."""
    return replace(cfg, passes=[replace(p, backend=None) for p in cfg.passes])


def pinned(cfg, **backends: str):
    return replace(cfg, passes=[replace(p, backend=backends.get(p.name, p.backend))
                                for p in cfg.passes])


def live_vk(device) -> dict[str, int]:
    with one_time(device):  # the device's shared one-time pool exists from here on
        pass
    return device.live_objects()


def live_wgpu() -> dict[str, int]:
    gc.collect()
    counts = wgpu.diagnostics.object_counts.get_dict()
    return {k: v["count"] for k, v in counts.items() if k != "total"}


@pytest.fixture(scope="module")
def tiny_mixed(vk_device, device):
    return render(mixed("160x90"), scene=tiny_scene(), devices=(vk_device, device))


# ---------------------------------------------------------------------------------------------
# the plan: bridges where the config crosses backends


def test_the_plan_shows_the_bridges():
    graph = build(mixed("160x90")).graph
    for backend in ("wgpu", "vk"):  # every pass is pinned: the run's backend changes nothing
        plan = compile(graph, backend=backend)
        assert plan.order == ORDER
        for name in BRIDGES:
            (src, dst) = plan.accesses[name]
            assert src.usages == {"transfer_src"} and dst.usages == {"transfer_dst"}
            assert dst.resource == f"{src.resource}@vk"
        assert {a.resource for a in plan.accesses["lighting"]} >= {
            "gbuffer.albedo@vk", "gbuffer.depth@vk", "shadow.depth@vk"}


def test_each_backend_owns_its_passes_and_their_resources(vk_device):
    m = split(build(mixed("160x90")), "wgpu")
    assert m.sides == ("wgpu", "vk")
    assert m.passes_of("wgpu") == ("shadow", *BRIDGES[:1], "gbuffer", *BRIDGES[1:])
    assert m.passes_of("vk") == (*BRIDGES, "lighting", "tonemap")
    wplan = compile(m.graphs["wgpu"])
    vplan, _ = fit_graph(m.graphs["vk"], vk_device)
    m.check("wgpu", wplan)
    m.check("vk", vplan)
    # the originals stay on wgpu, the copies and what lighting makes live on Vulkan
    assert {r.name for r in wplan.resources} == {
        "shadow.depth", "gbuffer.albedo", "gbuffer.normal", "gbuffer.material",
        "gbuffer.emissive", "gbuffer.depth"}
    assert {r.name for r in vplan.resources} == {
        "shadow.depth@vk", "gbuffer.albedo@vk", "gbuffer.normal@vk", "gbuffer.material@vk",
        "gbuffer.emissive@vk", "gbuffer.depth@vk", "lighting.hdr", "tonemap.ldr"}
    # the Vulkan side's barriers: each copy goes to TRANSFER_DST at its bridge, and lighting
    # takes it from there to a shader read
    into = {b.resource: b for b in vplan.barriers if b.pass_name in BRIDGES}
    assert set(into) == {r for r in m.owner if r.endswith("@vk")}
    assert all(b.dst.layout == "TRANSFER_DST_OPTIMAL" for b in into.values())
    reads = {b.resource: b for b in vplan.barriers if b.pass_name == "lighting"}
    assert all(reads[r].src.layout == "TRANSFER_DST_OPTIMAL" for r in into)
    assert reads["shadow.depth@vk"].dst.layout == "DEPTH_READ_ONLY_OPTIMAL"
    # consumers read the copies
    assert m.slots["lighting"]["albedo"] == "gbuffer.albedo@vk"
    assert m.slots["tonemap"] == {"hdr": "lighting.hdr", "ldr": "tonemap.ldr"}


def test_one_backend_refuses_the_whole_mixed_plan(device, vk_device):
    # a single-backend executor given the full plan (rfw view compiles one) says so, rather
    # than running the vk passes on wgpu or failing on a bridge mid-frame
    from rfw.backends.wgpu import Executor

    built = build(mixed("64x36", "shadow.resolution=256"))
    plan = compile(built.graph, backend="wgpu")
    with pytest.raises(ShaderError, match=r"pass 'bridge.shadow.depth.wgpu-vk' copies between "
                                          r"backends"):
        Executor(device, plan, built.passes, built.slots)
    with pytest.raises(ShaderError, match=r"copies between backends"):
        check_passes(plan, built.passes)
    with pytest.raises(ShaderError, match=r"pinned to backend 'wgpu'.*rfw.render.render"):
        fit_plan(built.graph, vk_device)


# ---------------------------------------------------------------------------------------------
# the image is the single-backend one


def test_tiny_scene_matches_all_wgpu(tiny_mixed, device):
    wg = render(unpinned(mixed("160x90")), scene=tiny_scene(), device=device)
    a, b = tiny_mixed.images["tonemap.ldr"], wg.images["tonemap.ldr"]
    assert a.shape == b.shape == (90, 160, 4) and a.dtype == np.uint8
    assert a[..., :3].std() > 10  # a picture: lit geometry, sky, the cube's shadow
    # measured on lavapipe: identical (max difference 0 of 255); compared like goldens
    # (golden_util.Bounds) for drivers whose two shader compilers round differently
    assert_similar(a, b, "mixed against all-wgpu, tiny")
    # negative control: the same comparison rejects the frame without the sun's shadow
    # (measured: 130 pixels over 2 levels of 14400, FLIP 0.012)
    no_shadow = render(unpinned(mixed("160x90", "shadow.enabled=false")), scene=tiny_scene(),
                       device=device)
    assert mismatch(no_shadow.images["tonemap.ldr"], a)


def test_courtyard_matches_all_wgpu(vk_device, device, courtyard):
    cfg = mixed("192x108")
    mx = render(cfg, scene=courtyard, devices=(vk_device, device))
    wg = render(unpinned(cfg), scene=courtyard, device=device)
    a, b = mx.images["tonemap.ldr"], wg.images["tonemap.ldr"]
    assert a.shape == b.shape == (108, 192, 4)
    assert a[..., :3].std() > 10
    # measured on lavapipe: identical (max difference 0)
    assert_similar(a, b, "mixed against all-wgpu, courtyard")


def test_the_other_direction_vk_to_wgpu(vk_device, device):
    # tonemap back on wgpu: lighting.hdr leaves Vulkan from GENERAL through TRANSFER_SRC
    cfg = pinned(mixed("160x90", "shadow.resolution=512"), tonemap="wgpu")
    plan = compile(build(cfg).graph, backend="wgpu")
    assert plan.order[-3:] == ("lighting", "bridge.lighting.hdr.vk-wgpu", "tonemap")
    mx = render(cfg, scene=tiny_scene(), devices=(vk_device, device))
    wg = render(unpinned(cfg), scene=tiny_scene(), device=device)
    assert [p["backend"] for p in mx.timings["passes"]][-3:] == ["vk", "vk>wgpu", "wgpu"]
    assert_similar(mx.images["tonemap.ldr"], wg.images["tonemap.ldr"],
                   "vk-to-wgpu mixed against all-wgpu")  # measured: identical


def test_render_vk_runs_a_mixed_config_mixed(vk_device, device):
    from vkext.backend import render_vk

    r = render_vk(mixed("64x36", "shadow.resolution=256"), scene=tiny_scene(),
                  device=vk_device)
    assert r.timings["backend"] == "wgpu+vk" and r.timings["bridges"] == list(BRIDGES)


def test_all_passes_pinned_elsewhere_run_there_alone(vk_device):
    # every pass on Vulkan, run as a wgpu frame: no bridge, no wgpu executor
    cfg = pinned(mixed("64x36", "shadow.resolution=256"), shadow="vk", gbuffer="vk")
    r = render(cfg, scene=tiny_scene(), device=vk_device)
    assert r.timings["backend"] == "vk" and r.timings["bridges"] == []
    assert [p["name"] for p in r.timings["passes"]] == ["shadow", "gbuffer", "lighting",
                                                        "tonemap"]


N = 256  # uints in each buffer of the chain below

FILL_GLSL = """#version 460
layout(local_size_x = 64) in;
layout(set = 0, binding = 0, std430) buffer Out { uint v[]; } o_data;
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < o_data.v.length()) o_data.v[i] = 3u * i + 1u;
}
"""
TWICE_WGSL = """@group(0) @binding(0) var<storage, read> a: array<u32>;
@group(0) @binding(1) var<storage, read_write> b: array<u32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x < arrayLength(&a)) { b[id.x] = 2u * a[id.x]; }
}
"""
INC_GLSL = """#version 460
layout(local_size_x = 64) in;
layout(set = 0, binding = 0, std430) readonly buffer In { uint v[]; } i_data;
layout(set = 0, binding = 1, std430) buffer Out { uint v[]; } o_data;
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < o_data.v.length()) o_data.v[i] = i_data.v[i] + 1u;
}
"""


class _Tmp(ComputePass):
    folder_path: Path = Path()

    @classmethod
    def folder(cls) -> Path:
        return cls.folder_path


class _Fill(_Tmp):
    shader = "fill.comp.glsl"

    def record(self, ctx) -> None:
        ctx.dispatch(threads=(N,), o_data=ctx.buffer("data"))


class _Twice(_Tmp):
    shader = "twice.comp.wgsl"

    def record(self, ctx) -> None:
        ctx.dispatch(threads=(N,), a=ctx.buffer("a"), b=ctx.buffer("b"))


class _Inc(_Tmp):
    shader = "inc.comp.glsl"

    def record(self, ctx) -> None:
        ctx.dispatch(threads=(N,), i_data=ctx.buffer("b"), o_data=ctx.buffer("c"))


def test_buffers_cross_both_ways(vk_device, device, tmp_path, monkeypatch):
    # vk -> wgpu -> vk with buffers: read_buffer / write_buffer, then upload_buffer
    for name, text in (("fill.comp.glsl", FILL_GLSL), ("twice.comp.wgsl", TWICE_WGSL),
                       ("inc.comp.glsl", INC_GLSL)):
        (tmp_path / name).write_text(text)
    monkeypatch.setattr(_Tmp, "folder_path", tmp_path)
    g = GraphBuilder("buffers", size=(16, 16))
    g.add_pass("fill", "compute", backend="vk").output("data", Buffer(4 * N))
    g.add_pass("twice", "compute", backend="wgpu").input("a", "fill.data", Buffer()) \
        .output("b", Buffer(4 * N))
    g.add_pass("inc", "compute", backend="vk").input("b", "twice.b", Buffer()) \
        .output("c", Buffer(4 * N))
    built = Built(g.output("inc.c").build(),
                  {"fill": _Fill("fill"), "twice": _Twice("twice"), "inc": _Inc("inc")},
                  {"fill": {"data": "fill.data"}, "twice": {"a": "fill.data", "b": "twice.b"},
                   "inc": {"b": "twice.b", "c": "inc.c"}})
    before = live_vk(vk_device)
    frame = open_frame(built, "wgpu", devices=(device, vk_device))
    try:
        assert frame.plan.order == ("fill", "bridge.fill.data.vk-wgpu", "twice",
                                    "bridge.twice.b.wgpu-vk", "inc")
        frame.run(2)
        out = frame.read("inc.c").view(np.uint32)
        bridges = {p["name"]: p for p in frame.pass_timings() if p["gpu_ms"] is None}
    finally:
        frame.destroy()
    assert np.array_equal(out, 2 * (3 * np.arange(N, dtype=np.uint32) + 1) + 1)
    assert {p["bytes"] for p in bridges.values()} == {4 * N}
    assert vk_device.live_objects() == before


# ---------------------------------------------------------------------------------------------
# timings: a bridge is a pass of its own


def test_timings_have_an_entry_per_bridge(tiny_mixed, vk_device):
    t = tiny_mixed.timings
    assert [p["name"] for p in t["passes"]] == list(ORDER)
    assert t["bridges"] == list(BRIDGES)
    by_name = {p["name"]: p for p in t["passes"]}
    for name in BRIDGES:
        p = by_name[name]
        # wall time of the readback and the upload; no GPU timestamp brackets a host copy
        assert p["backend"] == "wgpu>vk" and p["gpu_ms"] is None and p["cpu_ms"] > 0
    assert by_name[BRIDGES[0]]["bytes"] == 2048 * 2048 * 4  # the shadow map, depth32float
    assert by_name["bridge.gbuffer.normal.wgpu-vk"]["bytes"] == 160 * 90 * 8
    for name, side in (("shadow", "wgpu"), ("gbuffer", "wgpu"), ("lighting", "vk"),
                       ("tonemap", "vk")):
        assert by_name[name]["backend"] == side and by_name[name]["gpu_ms"] > 0
    assert t["bridge_ms_total"] == pytest.approx(sum(by_name[n]["cpu_ms"] for n in BRIDGES))
    assert t["gpu_ms_total"] == pytest.approx(sum(by_name[n]["gpu_ms"] for n in ORDER
                                                  if n not in BRIDGES))
    assert set(t["backends"]) == {"wgpu", "vk"} and t["timestamps"] is True
    # the Vulkan side's transients: the copies, lighting.hdr and tonemap.ldr in one heap
    assert t["memory"]["transient_allocated_bytes"] == t["memory"]["plan_transient_bytes"]
    json.dumps(t)  # timings.json as written


def test_validation_sees_a_missing_bridge_barrier(vk_device, device, monkeypatch):
    # the negative control of the silent runs: without the plan's barriers at the bridges
    # (the copies UNDEFINED -> TRANSFER_DST_OPTIMAL) the uploads find the wrong layout
    import vkext.executor

    real = vkext.executor.record_barriers

    def without_bridges(cmd, barriers, resources):
        return real(cmd, [b for b in barriers if not b.pass_name.startswith("bridge.")],
                    resources)

    monkeypatch.setattr(vkext.executor, "record_barriers", without_bridges)
    try:
        render(mixed("64x36", "shadow.resolution=256"), scene=tiny_scene(),
               devices=(vk_device, device))
        texts = [m.text for m in vk_device.messages]
        assert any("@vk" in t and "layout" in t.lower() for t in texts), texts
    finally:
        vk_device.messages.clear()


# ---------------------------------------------------------------------------------------------
# the command line, and dropping renders


def test_rfw_run_renders_the_mixed_config(capsys, tmp_path):
    out_dir = tmp_path / "out"
    rc = main(["run", str(MIXED), "--size", "160x90", "--out", str(out_dir)])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert sorted(p.name for p in out_dir.iterdir()) == ["timings.json", "tonemap.ldr.png"]
    timings = json.loads((out_dir / "timings.json").read_text())
    assert timings["config"] == "deferred_mixed" and timings["size"] == [160, 90]
    assert [p["name"] for p in timings["passes"]] == list(ORDER)
    assert all(p["cpu_ms"] > 0 for p in timings["passes"] if p["name"] in BRIDGES)
    for word in ("bridge.gbuffer.albedo.wgpu-vk", "lighting", "transient memory", "wrote"):
        assert word in out


def test_rfw_run_validated(capsys, tmp_path):
    rc = main(["run", str(MIXED), "--size", "64x36", "--set", "shadow.resolution=256",
               "--backend", "vk", "--validate", "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "validation: 0 message(s)" in out


def test_render_and_drop_returns_to_baseline(vk_device, device):
    cfg = mixed("64x36", "shadow.resolution=256")
    render(cfg, scene=tiny_scene(), devices=(vk_device, device))
    vk_before, wgpu_before = live_vk(vk_device), live_wgpu()
    for _ in range(3):
        result = render(cfg, scene=tiny_scene(), devices=(vk_device, device), frames=2)
        del result
    assert vk_device.live_objects() == vk_before
    wgpu_after = live_wgpu()
    grown = {k: (wgpu_before[k], wgpu_after[k]) for k in wgpu_before
             if wgpu_after[k] > wgpu_before[k]}
    assert not grown, f"wgpu objects still alive after dropping the renders: {grown}"


def test_a_frame_on_one_side_runs_its_second_queue_order():
    # meshlet pins every pass to vk: no bridges, so the vk plan's own order (the async
    # compute culling put first, as on a device with a second queue) is the frame's
    cfg = apply_overrides(load_config(ROOT / "configs" / "meshlet.toml"),
                          ["shadow.enabled=true"])
    m = split(build(cfg), "wgpu")
    caps = ("VK_EXT_mesh_shader", "timestamp", "timeline_semaphore", "compute_queue")
    sub = compile(m.graphs["vk"], size=(64, 36), caps=caps)
    assert not m.bridges and tuple(sub.order) != m.passes_of("vk")
    m.check("vk", sub)
    # negative control: with a bridge between sides, the full plan's order is the law
    two = split(build(mixed("160x90")), "wgpu")
    vk = compile(two.graphs["vk"], size=(160, 90))
    swapped = replace(vk, order=tuple(reversed(vk.order)))
    with pytest.raises(ShaderError, match="the mixed plan needs"):
        two.check("vk", swapped)
    # and one side running other passes than the plan's is refused too
    with pytest.raises(ShaderError, match="the mixed plan needs"):
        m.check("vk", replace(sub, order=sub.order[1:]))
