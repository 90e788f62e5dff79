"""configs/meshlet.toml: the deferred pipeline on Vulkan with a meshlet/vertex G-buffer
variant and the culling switches ``culling.cone``, ``culling.frustum``, ``culling.occlusion``
(two-phase: cull and gbuffer early, hiz, cull_late and gbuffer_late) and
``culling.triangles``; the meshlet buffers (indirect commands, counters, visibility) are
graph resources whose barriers the compiler plans and ``rfw graph plan`` prints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.graph import Buffer, GraphBuilder, GraphError, Storage, Texture, compile

from .cli.warm import warm_cli
from .conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "meshlet.toml"
SLOTS = ("albedo", "normal", "material", "emissive", "depth")
MESHLET_ORDER = ("cull", "gbuffer", "hiz", "cull_late", "gbuffer_late", "lighting", "tonemap")


def _config(*sets: str):
    return apply_overrides(load_config(CONFIG), list(sets))


def _order(cfg) -> tuple[str, ...]:
    return compile(build(cfg).graph, cfg.size, backend="vk").order


def _params(cfg, name: str) -> dict:
    return build(cfg).passes[name].params.as_dict()


def test_every_pass_is_pinned_to_vk_and_defaults_cull_everything():
    cfg = load_config(CONFIG)
    assert all(p.backend == "vk" for p in cfg.passes)
    assert cfg.chosen == {"culling.cone": "true", "culling.frustum": "true",
                          "culling.occlusion": "true", "culling.triangles": "false",
                          "debug": "none", "geometry": "meshlet"}
    assert _order(cfg) == MESHLET_ORDER
    for early, late in (("cull", "cull_late"), ("gbuffer", "gbuffer_late")):
        assert _params(cfg, early)["phase"] == "early"
        assert _params(cfg, late)["phase"] == "late"


def test_vertex_geometry_wires_lighting_to_the_vertex_gbuffer():
    cfg = _config("geometry=vertex")
    built = build(cfg)
    assert {s: built.slots["lighting"][s] for s in SLOTS} == \
        {s: f"gbuffer_vertex.{s}" for s in SLOTS}
    assert _order(cfg) == ("gbuffer_vertex", "lighting", "tonemap")


@pytest.mark.parametrize("sets", [
    ["geometry=vertex", "culling.occlusion=true"],  # geometry wins in any --set order
    ["culling.occlusion=true", "geometry=vertex"],
])
def test_geometry_wins_over_the_culling_switches(sets):
    assert _order(_config(*sets)) == ("gbuffer_vertex", "lighting", "tonemap")


def test_occlusion_off_is_one_pass_without_a_pyramid():
    cfg = _config("culling.occlusion=false")
    assert _order(cfg) == ("cull", "gbuffer", "lighting", "tonemap")
    assert _params(cfg, "gbuffer")["phase"] == _params(cfg, "cull")["phase"] == "single"
    back = apply_overrides(cfg, ["geometry=vertex", "geometry=meshlet", "culling.occlusion=on"])
    assert back.passes == load_config(CONFIG).passes


@pytest.mark.parametrize("spelling", ["false", "off", "0", "no", "False"])
def test_switches_take_any_boolean_spelling(spelling):
    cfg = _config(f"culling.cone={spelling}", f"culling.frustum={spelling}")
    for name in ("gbuffer", "gbuffer_late"):
        p = _params(cfg, name)
        assert (p["cone"], p["frustum"]) == (False, False)
    for name in ("cull", "cull_late"):  # instance culling follows the frustum switch
        assert _params(cfg, name)["frustum"] is False


def test_triangles_and_debug_colors_reach_both_phases():
    cfg = _config("culling.triangles=true", "debug=meshlets")
    for name in ("gbuffer", "gbuffer_late"):
        p = _params(cfg, name)
        assert p["triangles"] and p["colors"]


def test_explicit_settings_apply_after_the_variants():
    cfg = _config("gbuffer.cone=false", "culling.cone=true")
    assert not _params(cfg, "gbuffer")["cone"]  # the explicit --set stays in force
    assert _params(cfg, "gbuffer_late")["cone"]


def test_bad_switch_value_names_the_variant():
    with pytest.raises(GraphError, match=r"culling.occlusion.*maybe"):
        _config("culling.occlusion=maybe")


def test_bad_phase_names_the_pass():
    with pytest.raises(GraphError, match=r"gbuffer.*phase"):
        build(_config("gbuffer.phase=middle"))


def test_both_geometries_render_the_same_image():
    pytest.importorskip("vkext")
    from vkext import VkDevice, VkUnavailableError
    from vkext.backend import render_vk

    try:
        device = VkDevice(validation=True, label="rfw-tests-meshlet-config")
    except VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")
    try:
        if "VK_EXT_mesh_shader" not in device.caps:
            pytest.skip("no VK_EXT_mesh_shader")
        images = {}
        for geometry in ("meshlet", "vertex"):
            r = render_vk(_config(f"geometry={geometry}", "size=96x54"), scene=tiny_scene(),
                          device=device, frames=2)
            assert r.timings["validation"]["messages"] == 0
            images[geometry] = r.images["tonemap.ldr"].astype(np.int16)
            assert ("culling" in r.timings) == (geometry == "meshlet")
        assert images["vertex"].shape[:2] == (54, 96)
        assert images["vertex"][..., :3].std() > 5  # a real picture, not a cleared target
        assert np.abs(images["meshlet"] - images["vertex"]).max() <= 1
    finally:
        device.destroy()
    device.check_validation()


def _plan_barriers(*args: str) -> list[str]:
    out = warm_cli("graph", "plan", CONFIG, *args, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("barriers ("))
    return [line.strip() for line in lines[start + 1:] if line.startswith("  ")]


def test_graph_plan_prints_the_meshlet_buffer_barriers():
    barriers = _plan_barriers()

    def one(pass_: str, resource: str) -> str:
        found = [b for b in barriers if b.startswith(f"{pass_} / {resource}:")]
        assert len(found) == 1, f"{pass_} / {resource}: {found}"
        return found[0]
    # the culling pass's commands become indirect draws
    for cull, draw in (("cull", "gbuffer"), ("cull_late", "gbuffer_late")):
        assert one(draw, f"{cull}.commands").endswith(
            "COMPUTE_SHADER:SHADER_STORAGE_WRITE -> DRAW_INDIRECT:INDIRECT_COMMAND_READ")
    # counters and visibility: compute writes -> task/mesh read-writes -> compute, and the
    # next frame's clear waits for the last frame's shaders (persistent buffers)
    for resource in ("cull.counters", "cull.visibility"):
        assert "COMPUTE_SHADER:SHADER_STORAGE_WRITE -> " \
            "FRAGMENT_SHADER|MESH_SHADER_EXT|TASK_SHADER_EXT:SHADER_STORAGE_READ|" \
            "SHADER_STORAGE_WRITE" in one("gbuffer", resource)
        assert "TASK_SHADER_EXT:SHADER_STORAGE_WRITE -> COMPUTE_SHADER:" in \
            one("cull_late", resource)
        assert "TASK_SHADER_EXT:SHADER_STORAGE_WRITE -> COMPUTE_SHADER:" in one("cull", resource)
        assert one("gbuffer_late", resource)
        # inside the culling pass: its culling dispatch waits for its clear (steps)
        assert one("cull step 1 (cull)", resource).endswith(
            "COMPUTE_SHADER:SHADER_STORAGE_WRITE -> COMPUTE_SHADER:SHADER_STORAGE_" +
            ("READ|SHADER_STORAGE_WRITE" if resource == "cull.counters" else "WRITE"))
    # negative control: a graph that keeps only the culling pass plans no indirect read
    only_cull = _plan_barriers("--output", "cull.commands")
    assert only_cull and not any("INDIRECT_COMMAND_READ" in b for b in only_cull)


def _buffer_plan(slot):
    g = GraphBuilder("buffers", size=(8, 8))
    g.add_pass("make", "compute").output("buf", Buffer(64))
    g.add_pass("rw", "compute").input("buf", "make.buf", slot)
    (g.add_pass("read", "compute").input("buf", "make.buf", Buffer())
     .output("out", Texture("r32float")))
    g.output("read.out")
    return compile(g.build(), size=(8, 8))


def test_a_storage_input_writes_a_buffer_in_place():
    # how meshlet_gbuffer adds to the counters and records visibility: a read-write access,
    # and the next reader waits for its writes
    plan = _buffer_plan(Storage())
    (rw,) = plan.accesses["rw"]
    assert rw.role == "modify" and rw.state.writes
    assert [b.src.stages for b in plan.barriers if (b.pass_name, b.resource) ==
            ("read", "make.buf")] == [frozenset({"COMPUTE_SHADER"})]
    # negative control: a plain buffer input only reads, and the reader waits for nothing
    plan = _buffer_plan(Buffer())
    (r,) = plan.accesses["rw"]
    assert r.role == "read" and not r.state.writes
    assert not [b for b in plan.barriers if (b.pass_name, b.resource) == ("read", "make.buf")]
