"""One plan type for every frame (rfw.mixed.FramePlan): a frame on one backend is one side
without bridges, a mixed one is cut into sides joined by typed bridges (rfw.graph.Bridge),
and every compiled plan lists its bridge passes (CompiledGraph.bridges) so nothing finds them
by name. Each side's graph is compiled once (vk's device placement is
rfw.graph.compile.place on that plan), and a Result holds the run's Frame."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.errors import RfwError
from rfw.frame import Frame
from rfw.graph import GraphBuilder, MemoryOptions, Texture, compile
from rfw.graph.compile import STATS, place
from rfw.graph.graph import Bridge
from rfw.mixed import FramePlan, split
from rfw.render import render

from ..conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[2]
MIXED = ROOT / "configs" / "deferred_mixed.toml"
DEFERRED = ROOT / "configs" / "deferred.toml"


def _config(path: Path, size: str = "32x18"):
    return apply_overrides(load_config(path), [f"size={size}", "shadow.resolution=256"])


def test_bridges_are_typed_and_every_plan_lists_its_own():
    fp = split(build(_config(MIXED)), "wgpu")
    assert isinstance(fp, FramePlan) and fp.sides == ("wgpu", "vk") and not fp.single
    assert fp.bridges and all(isinstance(b, Bridge) for b in fp.bridges.values())
    for name, b in fp.bridges.items():
        assert (b.name, b.src, b.dst) == (name, "wgpu", "vk")
        assert b.copy == f"{b.resource}@vk" and fp.owner[b.copy] == "vk"
        assert fp.owner[b.resource] == "wgpu" and fp.backend_of(name) == "wgpu>vk"
    assert not any(">" in s for s in fp.side.values())  # passes only, bridges apart
    assert set(fp.plan.bridges) == set(fp.bridges)  # the full plan names them
    for s in fp.sides:  # each side's plan names its halves of them
        sub = compile(fp.graphs[s])
        assert set(sub.bridges) == {n for n in fp.passes_of(s) if n in fp.bridges}


def test_a_pass_named_like_a_bridge_is_no_bridge():
    # negative control of the old name test: only what insert_bridges made is a bridge
    g = GraphBuilder("fake", size=(8, 8))
    g.add_pass("copy", "transfer").output("dst", Texture("rgba8unorm"))
    g.output("copy.dst")
    graph = g.build()
    named = replace(graph, passes=(replace(graph.passes[0], name="bridge.copy.vk-wgpu"),))
    plan = compile(named)
    assert plan.order == ("bridge.copy.vk-wgpu",) and plan.bridges == ()
    # ... while one insert_bridges made is, under any name
    decl = replace(named.passes[0], bridge=Bridge("copy", "vk", "wgpu", "a", "a@wgpu"))
    assert compile(replace(graph, passes=(decl,))).bridges == ("bridge.copy.vk-wgpu",)


def test_place_is_compile_with_other_memory_rules():
    graph = build(_config(DEFERRED, "64x36")).graph
    plan = compile(graph, backend="vk")
    rules = MemoryOptions(image_alignment=256, buffer_alignment=64)
    placed = place(plan, rules)
    assert placed == compile(graph, backend="vk", memory=rules)
    assert placed != plan  # the rules changed the placement (negative control)
    assert place(plan, MemoryOptions()) is plan  # compile's own rules: its memo


def _counted(monkeypatch, run):
    compile_module = sys.modules["rfw.graph.compile"]
    monkeypatch.setattr(compile_module, "_CACHE", type(compile_module._CACHE)())
    before = STATS.copy()
    result = run()
    return result, STATS["compile"] - before["compile"], STATS["place"] - before["place"]


def test_each_side_is_compiled_once(monkeypatch):
    # a mixed vk run: the frame's plan once, then each side's graph once (before: the vk side
    # twice, the second time with the device's memory rules; now place() on the first plan)
    mixed, compiles, placed = _counted(
        monkeypatch, lambda: render(_config(MIXED), scene=tiny_scene(), frames=1, backend="vk"))
    assert mixed.frame.frame_plan.sides == ("wgpu", "vk")
    assert (compiles, placed) == (1 + 2, 1)
    # one backend: one side, compiled once (vk placed once more, wgpu not at all)
    one, compiles, placed = _counted(
        monkeypatch, lambda: render(_config(DEFERRED), scene=tiny_scene(), frames=1,
                                    backend="vk"))
    assert one.frame.frame_plan.single and (compiles, placed) == (1, 1)
    _, compiles, placed = _counted(
        monkeypatch, lambda: render(_config(DEFERRED), scene=tiny_scene(), frames=1))
    assert (compiles, placed) == (1, 0)


def test_a_result_holds_its_frame(monkeypatch):
    one = render(_config(DEFERRED), scene=tiny_scene(), frames=1, backend="vk")
    assert isinstance(one.frame, Frame) and one.frame.frame_plan.single
    assert one.executor is one.frame.executors["vk"]  # the one side's executor
    assert one.frame.plan.order == one.executor.plan.order
    mixed = render(_config(MIXED), scene=tiny_scene(), frames=1)
    assert isinstance(mixed.frame, Frame) and set(mixed.frame.executors) == {"wgpu", "vk"}
    assert set(mixed.formats) == set(mixed.images)  # read from the frame's plan
    with pytest.raises(RfwError, match=r"mixes backends \(wgpu, vk\).*frame\.executors"):
        _ = mixed.executor


def test_a_frame_on_one_backend_is_one_side():
    fp = FramePlan.whole(compile(build(_config(DEFERRED)).graph), "wgpu",
                         build(_config(DEFERRED)).graph, {})
    assert fp.single and fp.sides == ("wgpu",) and fp.bridges == {}
    assert fp.passes_of("wgpu") == fp.plan.order
    # a frame of one side that came through split (every pass pinned elsewhere) is one too
    pinned = replace(_config(MIXED), passes=[replace(e, backend="vk")
                                             for e in _config(MIXED).passes])
    assert split(build(pinned), "wgpu").single
