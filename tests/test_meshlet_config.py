"""configs/meshlet.toml: the deferred pipeline on Vulkan with a meshlet/vertex G-buffer variant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.graph import compile

from .conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "meshlet.toml"
SLOTS = ("albedo", "normal", "material", "emissive", "depth")
GBUFFER = {"meshlet": "gbuffer_meshlet", "vertex": "gbuffer_vertex"}
USE = {"gbuffer_meshlet": "meshlet_gbuffer", "gbuffer_vertex": "gbuffer"}


def _config(*sets: str):
    return apply_overrides(load_config(CONFIG), list(sets))


def _check(cfg, geometry: str) -> None:
    on = GBUFFER[geometry]
    off = next(v for v in GBUFFER.values() if v != on)
    assert cfg.chosen["geometry"] == geometry
    assert cfg.entry(on).enabled and not cfg.entry(off).enabled
    assert cfg.entry(on).use == USE[on] and cfg.entry(off).use == USE[off]
    lighting = cfg.entry("lighting")
    assert {s: lighting.inputs[s] for s in SLOTS} == {s: f"{on}.{s}" for s in SLOTS}
    assert lighting.inputs["shadow"] == "shadow.depth"
    built = build(cfg)
    assert off not in built.passes and on in built.passes
    assert {s: built.slots["lighting"][s] for s in SLOTS} == {s: f"{on}.{s}" for s in SLOTS}
    compiled = compile(built.graph, cfg.size, backend="vk")
    assert compiled.order == (on, "lighting", "tonemap")
    assert off in compiled.disabled


def test_every_pass_is_pinned_to_vk():
    cfg = load_config(CONFIG)
    assert all(p.backend == "vk" for p in cfg.passes)
    assert cfg.chosen == {"geometry": "meshlet", "cone": "on", "frustum": "on"}


@pytest.mark.parametrize("geometry", ["meshlet", "vertex"])
def test_builds_and_compiles(geometry):
    _check(_config(f"geometry={geometry}"), geometry)


def test_default_is_meshlet():
    _check(load_config(CONFIG), "meshlet")


def test_geometry_round_trips():
    cfg = _config("geometry=vertex")
    _check(cfg, "vertex")
    back = apply_overrides(cfg, ["geometry=meshlet"])
    _check(back, "meshlet")
    assert back.passes == load_config(CONFIG).passes
    again = apply_overrides(back, ["geometry=vertex"])
    assert again.passes == cfg.passes


def test_culling_switches():
    cfg = _config("cone=off")
    assert cfg.entry("gbuffer_meshlet").settings == {"cone": False, "frustum": True}
    cfg = apply_overrides(cfg, ["frustum=off", "cone=on"])
    assert cfg.entry("gbuffer_meshlet").settings == {"cone": True, "frustum": False}
    assert _culling(cfg) == (True, False)
    cfg = apply_overrides(cfg, ["gbuffer_meshlet.cone=false"])  # the direct spelling
    assert _culling(cfg) == (False, False)


def _culling(cfg) -> tuple[bool, bool]:
    params = build(cfg).passes["gbuffer_meshlet"].params.as_dict()
    return params["cone"], params["frustum"]


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
                          device=device)
            assert r.timings["validation"]["messages"] == 0
            images[geometry] = r.images["tonemap.ldr"].astype(np.int16)
        assert images["vertex"].shape[:2] == (54, 96)
        assert images["vertex"][..., :3].std() > 5  # a real picture, not a cleared target
        assert np.abs(images["meshlet"] - images["vertex"]).max() <= 1
    finally:
        device.destroy()
    device.check_validation()
