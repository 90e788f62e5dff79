"""Single-phase occlusion culling (meshlet_gbuffer ``occlusion``) against the previous frame's
max-depth pyramid (passes/depth_pyramid). Validation on, zero messages.

Measured on lavapipe, courtyard 192x108, 5 frames after a warmup: culling off draws 2025
meshlets; cone + frustum culls 30 + 447; with occlusion 4 more are culled (1544 drawn) and the
image equals the culling-off image exactly (max diff 0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, load_config
from rfw.scene import default_scene
from vkext.backend import render_vk

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "deferred_meshlet_occlusion.toml"


def _render(vk_device, scene, *sets: str, size: str = "192x108"):
    cfg = apply_overrides(load_config(CONFIG), [f"size={size}", *sets])
    r = render_vk(cfg, scene=scene, device=vk_device, frames=3)
    assert r.timings["validation"]["messages"] == 0
    return r.images["tonemap.ldr"].astype(np.int16), r


@pytest.fixture(scope="module")
def courtyard():
    return default_scene()


def test_config_wires_the_pyramid_through_history():
    cfg = load_config(CONFIG)
    assert cfg.entry("hiz").use == "depth_pyramid"
    assert all(p.backend == "vk" for p in cfg.passes)


def test_occlusion_is_conservative_and_culls(vk_device, courtyard):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    off, _ = _render(vk_device, courtyard, "gbuffer.cone=false", "gbuffer.frustum=false",
                     "gbuffer.occlusion=false")
    on, r = _render(vk_device, courtyard)
    assert off[..., :3].std() > 10
    assert np.array_equal(on, off)  # measured: identical
    c = r.executor.passes["gbuffer"].meshlets.last
    assert c["considered"] == c["meshlets_total"]
    assert c["drawn"] + c["cone_culled"] + c["frustum_culled"] + c["occlusion_culled"] == \
        c["considered"]
    assert c["occlusion_culled"] > 0  # measured: 4
    t = r.timings["culling"]
    assert t["culled_occlusion"] == c["occlusion_culled"]
    assert t["meshlets_total"] == t["meshlets_drawn"] + t["culled_cone"] + \
        t["culled_frustum"] + t["culled_occlusion"]


def test_occlusion_off_reports_none(vk_device, courtyard):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    _, r = _render(vk_device, courtyard, "gbuffer.occlusion=false", size="96x54")
    assert r.timings["culling"]["culled_occlusion"] is None
    assert r.executor.passes["gbuffer"].meshlets.last["occlusion_culled"] == 0
