"""The meshlet G-buffer (task + mesh shaders, vkext.meshlet) against the vertex path.

Validation on, zero messages (tests/vkext/conftest.py). Measured on lavapipe (Mesa 25.0.7,
LLVM 15, subgroup size 8), 192x108:

- tiny scene: 2 meshlets, the meshlet path's image equals the vertex path's bit for bit;
- courtyard: 2025 meshlets over the instances; with culling off the image matches the
  vertex path's (18 pixels differ by 1: rasterisation of the same positions computed in
  another stage); with cone + frustum culling on, 30 meshlets are cone-culled, 447
  frustum-culled, 1548 drawn, and the image equals the culling-off image exactly.

The two paths are compared like goldens (``golden_util.assert_similar``): on another CPU
llvmpipe rounds the two stages' positions differently (this test failed on an AMD EPYC
with the old bound of 1 level). Culling on against off stays exact: the same shaders
compute every surviving pixel, whichever meshlets are skipped.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, load_config
from rfw.meshlets import cached_meshlets
from vkext.backend import render_vk
from vkext.meshlet import MAX_TRIANGLES, MAX_VERTICES

from ..cli.warm import warm_cli
from ..conftest import tiny_scene
from ..golden_util import assert_similar, mismatch

ROOT = Path(__file__).resolve().parents[2]
OFF = ["culling.cone=false", "culling.frustum=false"]
ON = ["culling.cone=true", "culling.frustum=true"]


def _config(name: str, size: str, *sets: str):
    return apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [f"size={size}", *sets])


def _render(vk_device, scene, name: str, size: str, *sets: str):
    r = render_vk(_config(name, size, *sets), scene=scene, device=vk_device)
    assert r.timings["validation"]["messages"] == 0
    return r.images["tonemap.ldr"].astype(np.int16), r.timings.get("culling")


def _expected_total(scene) -> int:
    counts = [len(cached_meshlets(m.positions, m.indices, max_vertices=MAX_VERTICES,
                                  max_triangles=MAX_TRIANGLES)) if len(m.indices) else 0
              for m in scene.meshes]
    return sum(counts[i.mesh] for i in scene.instances
               if scene.materials[scene.meshes[i.mesh].material].alpha_mode != "BLEND")


def _check_counters(c: dict[str, int], scene) -> None:
    assert c["meshlets_total"] == _expected_total(scene)
    assert c["meshlets_considered"] == c["meshlets_total"]
    assert c["meshlets_drawn"] + c["culled_cone"] + c["culled_frustum"] == \
        c["meshlets_considered"]


def test_config_runs_every_pass_on_vk_with_mesh_shaders():
    cfg = load_config(ROOT / "configs" / "deferred_meshlet.toml")
    assert cfg.entry("gbuffer").use == "meshlet_gbuffer"
    assert cfg.entry("cull").use == "meshlet_cull"
    assert not cfg.entry("shadow").enabled
    assert all(p.backend == "vk" for p in cfg.passes)
    from passes.gbuffer.gbuffer import GBufferPass
    from passes.meshlet_gbuffer.meshlet_gbuffer import MeshletGBufferPass

    assert MeshletGBufferPass.outputs.keys() == GBufferPass.outputs.keys()
    assert MeshletGBufferPass.requires == ("VK_EXT_mesh_shader",)


def test_tiny_scene_matches_the_vertex_path(vk_device):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    scene = tiny_scene()
    vertex, _ = _render(vk_device, tiny_scene(), "deferred", "192x108")
    off, c_off = _render(vk_device, tiny_scene(), "deferred_meshlet", "192x108", *OFF)
    on, c_on = _render(vk_device, tiny_scene(), "deferred_meshlet", "192x108", *ON)
    assert_similar(off, vertex, "meshlet path against vertex path, tiny")  # measured: identical
    assert np.array_equal(on, off)
    for c in (c_off, c_on):
        _check_counters(c, scene)
    assert c_off["meshlets_drawn"] == c_off["meshlets_total"] == 2


def test_courtyard_matches_the_vertex_path_and_culls(vk_device, courtyard):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    vertex, _ = _render(vk_device, courtyard, "deferred", "192x108")
    off, c_off = _render(vk_device, courtyard, "deferred_meshlet", "192x108", *OFF)
    on, c_on = _render(vk_device, courtyard, "deferred_meshlet", "192x108", *ON)
    assert vertex[..., :3].std() > 10
    # culling off: the same triangles, positions computed by the mesh shader; measured: 18
    # of 20736 pixels differ by 1, FLIP 0.0001 (the bounds: golden_util.Bounds)
    assert_similar(off, vertex, "meshlet path against vertex path, courtyard")
    # negative control: the same comparison rejects the meshlet path 3 % brighter (FLIP 0.047,
    # a channel's mean 1.49 levels up, 1005 pixels over 2 levels)
    brighter, _ = _render(vk_device, courtyard, "deferred_meshlet", "192x108", *OFF,
                          "tonemap.exposure=1.03")
    assert mismatch(brighter, vertex)
    # culling is conservative: no pixel changes
    assert np.array_equal(on, off)
    _check_counters(c_off, courtyard)
    _check_counters(c_on, courtyard)
    assert c_off["meshlets_drawn"] == c_off["meshlets_total"] and c_off["culled_cone"] == 0
    assert c_on["culled_cone"] > 0 and c_on["culled_frustum"] > 0  # measured: 30 and 447
    assert c_on["meshlets_drawn"] < c_on["meshlets_total"]


@pytest.mark.parametrize("cone, frustum", [(True, False), (False, True)])
def test_each_test_alone_is_conservative(vk_device, courtyard, cone, frustum):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    off, _ = _render(vk_device, courtyard, "deferred_meshlet", "96x54", *OFF)
    one, c = _render(vk_device, courtyard, "deferred_meshlet", "96x54",
                     f"culling.cone={str(cone).lower()}", f"culling.frustum={str(frustum).lower()}")
    assert np.array_equal(one, off)
    _check_counters(c, courtyard)
    assert (c["culled_cone"] > 0) == cone and (c["culled_frustum"] > 0) == frustum


def test_render_and_drop_leaves_no_objects(vk_device):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")
    from vkext.commands import one_time

    with one_time(vk_device):
        pass
    before = vk_device.live_objects()
    for _ in range(2):
        _render(vk_device, tiny_scene(), "deferred_meshlet", "64x36")
    assert vk_device.live_objects() == before


def test_timings_json_reports_the_culling_counters(vk_device, courtyard):
    r = render_vk(_config("deferred_meshlet", "96x54"), scene=courtyard, device=vk_device)
    c = r.timings["culling"]
    assert c["meshlets_total"] == c["meshlets_drawn"] + c["culled_cone"] + c["culled_frustum"]
    assert c["culled_frustum"] > 0 and c["meshlets_drawn"] > 0
    assert c["culled_occlusion"] is None  # no late phase here: reported as such, not as 0
    assert c["triangles_drawn"] > 0 and c["triangles_culled_backface"] is None
    vertex = render_vk(_config("deferred", "96x54"), scene=courtyard, device=vk_device)
    assert "culling" not in vertex.timings


@pytest.mark.parametrize("setting", ["max_meshlets", "max_draws"])
def test_too_small_meshlet_buffers_fail_in_one_line(vk_device, tmp_path, setting):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip("no VK_EXT_mesh_shader")

    def run(value: int):
        return warm_cli("run", ROOT / "configs" / "deferred_meshlet.toml", "--size", "32x18",
                        "--frames", "1", "--set", f"cull.{setting}={value}", "--out",
                        tmp_path / str(value), cwd=tmp_path)

    small = run(1)
    assert small.returncode == 2 and "Traceback" not in small.stderr
    (line,) = small.stderr.strip().splitlines()
    assert line.startswith("rfw: error: pass 'cull'") and f"'{setting}'" in line
    # negative control: the size the message asks for is enough
    need = int(re.search(r"at least (\d+)", line).group(1))
    assert run(need).returncode == 0
