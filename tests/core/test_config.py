"""Configs: passes wired into a graph, settings, variants and --set overrides."""

import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.errors import RfwError
from rfw.graph import GraphError, compile

from ..conftest import ROOT

CONFIGS = sorted((ROOT / "configs").glob("*.toml"))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_every_config_builds_and_compiles(path):
    plan = compile(build(load_config(path)).graph)
    assert plan.order and plan.outputs


def test_set_toggles_passes_and_settings():
    cfg = load_config(ROOT / "configs" / "deferred.toml")
    assert "shadow" in compile(build(cfg).graph).disabled
    on = apply_overrides(cfg, ["shadow.enabled=true", "lighting.ambient=0.25",
                               "size=320x200"])
    built = build(on)
    plan = compile(built.graph)
    assert plan.order == ("shadow", "gbuffer", "lighting", "points_lines", "tonemap")
    assert built.passes["lighting"].params.ambient == 0.25
    assert built.slots["lighting"]["shadow"] == "shadow.depth"
    assert plan.size == (320, 200)
    off = build(cfg)  # the optional shadow input drops out when its pass is disabled
    assert "shadow" not in off.slots["lighting"]


@pytest.mark.parametrize("sets, message", [
    (["lighting.ambeint=2"], r"unknown setting 'ambeint' \(did you mean 'ambient'\?\)"),
    (["lightning.ambient=2"], r"no pass or variant 'lightning' \(did you mean 'lighting'"),
    (["shadow.enabled=maybe"], r"'shadow.enabled' must be true or false"),
    (["size=12"], r"--set size=12: expected WxH"),
    (["novalue"], r"expected key=value"),
])
def test_bad_overrides_are_one_clear_line(sets, message):
    cfg = load_config(ROOT / "configs" / "deferred.toml")
    with pytest.raises(GraphError, match=message) as e:
        build(apply_overrides(cfg, sets))
    assert "deferred.toml" in str(e.value) and "\n" not in str(e.value)


def test_variants_switch_and_undo(tmp_path):
    path = tmp_path / "v.toml"
    path.write_text("""
name = "v"
outputs = ["tonemap.ldr"]
[[pass]]
name = "shadow"
use = "shadow_map"
[[pass]]
name = "gbuffer"
[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", emissive = "gbuffer.emissive", depth = "gbuffer.depth", shadow = "shadow.depth" }
[[pass]]
name = "tonemap"
inputs = { hdr = "lighting.hdr" }
[variants.shadows]
default = "on"
on = {}
off = { "shadow.enabled" = false }
[variants.look]
default = "normal"
normal = {}
bright = { "tonemap.exposure" = 2.0 }
""")
    cfg = load_config(path)
    assert cfg.chosen == {"shadows": "on", "look": "normal"}
    off = apply_overrides(cfg, ["shadows=off", "look=bright"])
    assert "shadow" in compile(build(off).graph).disabled
    assert build(off).passes["tonemap"].params.exposure == 2.0
    back = apply_overrides(off, ["shadows=on", "look=normal"])
    assert compile(build(back).graph).disabled == ()
    assert build(back).passes["tonemap"].params.exposure == 1.0
    with pytest.raises(GraphError, match=r"variant 'shadows' has no option 'of' \(did you mean "
                                         r"'off'"):
        apply_overrides(cfg, ["shadows=of"])


def test_unconnected_required_input_is_an_error(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[[pass]]\nname = "tonemap"\n')
    with pytest.raises(GraphError, match=r"pass 'tonemap' \(tonemap\): input 'hdr' is not "
                                         r"connected"):
        build(load_config(path))
    path.write_text('[[pass]]\nname = "tonemap"\ninputs = { hrd = "x.y" }\n')
    with pytest.raises(GraphError, match=r"no input slot 'hrd' \(did you mean 'hdr'"):
        build(load_config(path))


def test_history_slots_map_to_last_frames_copy(tmp_path):
    from rfw import ComputePass, Tex2D
    from rfw.graph import History
    from rfw.registry import register_pass

    @register_pass("test_history_reader")
    class Reader(ComputePass):
        inputs = {"depth": Tex2D(), "pyramid": History(stages=("COMPUTE_SHADER",))}
        outputs = {"out": Tex2D("r32float", size_of="depth")}

    path = tmp_path / "h.toml"
    path.write_text("""
outputs = ["reader.out"]
[[pass]]
name = "gbuffer"
[[pass]]
name = "hiz"
use = "depth_pyramid"
inputs = { depth = "gbuffer.depth" }
[[pass]]
name = "reader"
use = "test_history_reader"
inputs = { depth = "gbuffer.depth", pyramid = "hiz.pyramid" }
""")
    built = build(load_config(path))
    pyramid = built.slots["reader"]["pyramid"]
    assert pyramid == "hiz.pyramid@prev"  # the plan's ping-pong copy, not this frame's
    plan = compile(built.graph)
    assert {a.resource: a.role for a in plan.accesses["reader"]}[pyramid] == "history"



_MINIMAL = '[[pass]]\nname = "tonemap"\ninputs = { hdr = "x.hdr" }\n'


def test_config_scene_is_relative_to_the_config(tmp_path):
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "c.toml").write_text('scene = "meshes/a.glb"\n' + _MINIMAL)
    (sub / "d.toml").write_text('scene = "default"\n' + _MINIMAL)
    assert load_config(sub / "c.toml").scene == str(sub / "meshes" / "a.glb")
    assert load_config(sub / "d.toml").scene == "default"  # the embedded scene stays a name


@pytest.mark.parametrize("head,needle", [
    ("frames = 0", "frames: 'frames' must be between 1 and"),
    ("frames = 100001", "frames: 'frames' must be between 1 and 100000"),
    ("frames = 2.0", "'frames' must be an integer"),
    ("size = [64, true]", "size: 'size' must be an integer"),
    ("size = [16385, 8]", "between 1 and 16384"),
    ("outputs = \"tonemap.ldr\"", "outputs: must be a list"),
    ("scene = []", "scene: must be a string"),
    ("camera = { znear = 2.0, zfar = 1.0 }", "camera: 'znear' must be smaller than 'zfar'"),
    ("camera = { position = [0, inf, 0] }", "camera.position: 'camera.position' must be finite"),
])
def test_bad_config_values_name_file_and_key(tmp_path, head, needle):
    path = tmp_path / "c.toml"
    path.write_text(head + "\n" + _MINIMAL)
    with pytest.raises(RfwError) as e:
        load_config(path)
    assert str(e.value).startswith(f"{path}: ") and needle in str(e.value)


@pytest.mark.parametrize("head", ["frames = 100000", "size = [16384, 1]",
                                  "camera = { znear = 0.5, zfar = 1.0, yfov = 179 }"])
def test_config_values_at_the_bounds_are_kept(tmp_path, head):
    # control for the test above: the same keys at their limits load
    path = tmp_path / "c.toml"
    path.write_text(head + "\n" + _MINIMAL)
    load_config(path)


def test_run_configs_and_graph_files_are_told_apart(tmp_path):
    from rfw.config import is_run_config

    assert all(is_run_config(p) for p in CONFIGS)
    assert not is_run_config(ROOT / "tests" / "data" / "default_graph.toml")
    assert not is_run_config(ROOT / "tests" / "data" / "three_ways" / "deferred.toml")
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff")
    assert not is_run_config(bad)  # left to the loader, which names the problem
