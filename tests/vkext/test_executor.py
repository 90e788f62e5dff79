"""The Vulkan executor against the wgpu one: same configs, same scenes, the same image.

One validated VkDevice per module (tests/vkext/conftest.py); every test leaves the validation
layer silent, synchronization validation included. Numbers measured on lavapipe (Mesa
25.0.7, LLVM 15) are stated where they are asserted.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from passes.fxaa.fxaa import FXAAPass
from passes.tonemap.tonemap import TonemapPass
from rfw import ComputePass, Settings
from rfw.config import apply_overrides, load_config
from rfw.graph import GraphBuilder, History, Texture
from rfw.render import render
from rfw.shaders import ShaderError
from rfw.spirv import ShaderCompileError
from vkext.backend import render_vk
from vkext.commands import one_time
from vkext.executor import VkExecutor
from vkext.fitting import fit_graph, fit_plan

from ..conftest import tiny_scene
from ..golden_util import assert_similar, mismatch

ROOT = Path(__file__).resolve().parents[2]
DEFERRED = ROOT / "configs" / "deferred.toml"


def deferred(size: str, *sets: str):
    return apply_overrides(load_config(DEFERRED), ["shadow.enabled=true", f"size={size}",
                                                   *sets])


@pytest.fixture(scope="module")
def courtyard_vk(vk_device, courtyard):
    """The courtyard at 192x108 on Vulkan, with and without aliasing (shared by tests)."""
    cfg = deferred("192x108")
    return (render_vk(cfg, scene=courtyard, device=vk_device),
            render_vk(cfg, scene=courtyard, device=vk_device, alias=False))


def live(device) -> dict[str, int]:
    """Live vkext objects, once the device's shared one-time command pool exists (the first
    upload anywhere in the process makes it, and it lives as long as the device)."""
    with one_time(device):
        pass
    return device.live_objects()


def _assert_plausible(img: np.ndarray) -> None:
    # not a blank or single-color frame: lit geometry, sky and shadow all leave a range
    assert img.shape[2] == 4 and img.dtype == np.uint8
    assert img[..., :3].std() > 10


# ---------------------------------------------------------------------------------------------
# the image matches the wgpu backend's


def test_tiny_scene_matches_wgpu(vk_device, device):
    cfg = deferred("160x90")
    vk = render_vk(cfg, scene=tiny_scene(), device=vk_device)
    wg = render(cfg, scene=tiny_scene(), device=device)
    a, b = vk.images["tonemap.ldr"], wg.images["tonemap.ldr"]
    assert a.shape == b.shape == (90, 160, 4)
    _assert_plausible(a)
    # measured on lavapipe: identical images; compared like goldens (golden_util.Bounds)
    # for drivers whose two compilers round differently
    assert_similar(a, b, "vk against wgpu, tiny")
    # negative control: the sun's shadow reaches the frame, and the same comparison rejects
    # the image without it (measured: 130 pixels over 2 levels of 14400, FLIP 0.012)
    no_shadow = render_vk(deferred("160x90", "shadow.enabled=false"), scene=tiny_scene(),
                          device=vk_device)
    assert mismatch(no_shadow.images["tonemap.ldr"], a)


def test_courtyard_matches_wgpu(courtyard_vk, device, courtyard):
    vk, _ = courtyard_vk
    wg = render(deferred("192x108"), scene=courtyard, device=device)
    a, b = vk.images["tonemap.ldr"], wg.images["tonemap.ldr"]
    assert a.shape == b.shape == (108, 192, 4)
    _assert_plausible(a)
    # measured on lavapipe: identical (405 instances, 8 mipmapped textures, sRGB albedo
    # target, PCF shadows)
    assert_similar(a, b, "vk against wgpu, courtyard")


def test_timings_json_fields(courtyard_vk, vk_device):
    t = courtyard_vk[0].timings
    assert t["backend"] == "vk" and t["device"] == vk_device.name and t["driver"]
    assert t["size"] == [192, 108] and t["frames"] == 1
    assert [p["name"] for p in t["passes"]] == ["shadow", "gbuffer", "lighting", "tonemap"]
    assert all(p["gpu_ms"] > 0 and p["cpu_ms"] > 0 for p in t["passes"])
    assert set(t["memory"]) >= {"transient_allocated_bytes", "plan_transient_bytes",
                                "unaliased_bytes", "alias"}


# ---------------------------------------------------------------------------------------------
# memory: real aliasing, exactly the plan's bytes


def test_memory_report_aliased_and_not(courtyard_vk):
    aliased, separate = courtyard_vk
    m, n = aliased.timings["memory"], separate.timings["memory"]
    assert m["alias"] is True and n["alias"] is False
    # one heap of exactly the plan's aliased size
    assert m["transient_allocated_bytes"] == m["plan_transient_bytes"]
    # one allocation per transient, of the driver's size: the plan's unaliased total, since
    # the plan was fitted to the device's exact sizes
    assert n["transient_allocated_bytes"] == n["unaliased_bytes"] == m["unaliased_bytes"]
    # tonemap.ldr takes over the dead shadow map's bytes: measured on lavapipe at 192x108,
    # 17,523,712 B aliased against 17,606,656 B unaliased (82,944 B, the ldr image, saved)
    assert m["transient_allocated_bytes"] < n["transient_allocated_bytes"]
    # the 64 KiB default alignment over-reserves (lavapipe asks 64 B and exact sizes)
    assert m["recompiled"] is True and "re-compiled" in m["reason"]
    # aliasing changes no pixel
    assert np.array_equal(aliased.images["tonemap.ldr"], separate.images["tonemap.ldr"])


def test_render_and_drop_returns_to_baseline(vk_device):
    cfg = deferred("64x36")
    before = live(vk_device)
    for _ in range(3):
        render_vk(cfg, scene=tiny_scene(), device=vk_device, frames=2)
    assert vk_device.live_objects() == before


def test_validation_sees_a_missing_planned_barrier(vk_device, monkeypatch):
    # the negative control of the silent runs above: without the plan's barriers for tonemap
    # (lighting.hdr GENERAL -> SHADER_READ_ONLY_OPTIMAL, tonemap.ldr taking over the shadow
    # map's bytes) the layer reports wrong layouts and hazards; the executor adds none itself
    import vkext.executor

    real = vkext.executor.record_barriers

    def without_tonemap(cmd, barriers, resources):
        return real(cmd, [b for b in barriers if b.pass_name != "tonemap"], resources)

    monkeypatch.setattr(vkext.executor, "record_barriers", without_tonemap)
    try:
        render_vk(deferred("64x36"), scene=tiny_scene(), device=vk_device)
        texts = [m.text for m in vk_device.messages]
        assert any("lighting.hdr" in t and "layout" in t for t in texts), texts
        assert any("SYNC-HAZARD" in t for t in texts), texts
    finally:
        vk_device.messages.clear()


# ---------------------------------------------------------------------------------------------
# errors name the pass, the file and the line


def test_glsl_compile_error_names_file_and_line(vk_device, tmp_path, monkeypatch):
    folder = tmp_path / "tonemap"
    shutil.copytree(ROOT / "passes" / "tonemap", folder)
    glsl = folder / "tonemap.comp.glsl"
    lines = glsl.read_text().splitlines()
    broken = next(i for i, line in enumerate(lines) if "imageStore" in line)
    lines[broken] = "    imageStore(o_ldr, ivec2(id), vec4(srgb_encode(c), 1.0)) + ;"
    glsl.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(TonemapPass, "folder", classmethod(lambda cls: folder))
    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    before = live(vk_device)
    with pytest.raises(ShaderCompileError) as e:
        render_vk(deferred("64x36"), scene=tiny_scene(), device=vk_device)
    assert f"{glsl}:{broken + 1}" in str(e.value) and "pass 'tonemap'" in str(e.value)
    assert vk_device.live_objects() == before  # the half-built frame was torn down


def test_missing_shader_is_a_clear_error(vk_device, tmp_path, monkeypatch):
    # a copy of fxaa's folder without its shader stands in
    folder = tmp_path / "fxaa"
    shutil.copytree(ROOT / "passes" / "fxaa", folder)
    (folder / "fxaa.comp.glsl").unlink()
    monkeypatch.setattr(FXAAPass, "folder", classmethod(lambda cls: folder))
    cfg = apply_overrides(load_config(ROOT / "configs" / "deferred_ssao_shadows.toml"),
                          ["ao=off", "size=64x36"])
    before = live(vk_device)
    with pytest.raises(ShaderError, match=r"pass 'fxaa': shader .*fxaa\.comp\.glsl not found"):
        render_vk(cfg, scene=tiny_scene(), device=vk_device)
    assert vk_device.live_objects() == before


@pytest.mark.parametrize("extra, message", [
    ({"t_bogus": 1.0}, r"pass 'tonemap': .*tonemap\.comp\.glsl has no binding named t_bogus"),
    ({}, r"pass 'tonemap': shader .*tonemap\.comp\.glsl binds u_params but the pass gives"),
])
def test_binding_mismatch_names_pass_binding_and_file(vk_device, monkeypatch, extra, message):
    # the wgpu PassContext raises the same ShaderError wording for its WGSL
    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("ldr"), t_hdr=ctx.sampled("hdr"),
                     o_ldr=ctx.storage("ldr"), **extra)

    monkeypatch.setattr(TonemapPass, "record", record)
    before = live(vk_device)
    with pytest.raises(ShaderError, match=message):
        render_vk(deferred("64x36"), scene=tiny_scene(), device=vk_device)
    assert vk_device.live_objects() == before


# ---------------------------------------------------------------------------------------------
# persistent images: history ping-pong, initial states from the plan


class _Accumulate(ComputePass):
    """out = previous frame's out + step (history starts cleared to zero)."""

    shader = "accumulate.comp.glsl"
    folder_path: Path = Path()

    class Params(Settings):
        step: float = 0.125

    @classmethod
    def folder(cls) -> Path:
        return cls.folder_path

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("out"), t_prev=ctx.sampled("history"),
                     o_out=ctx.storage("out"), u_params=self.params)


ACCUMULATE_GLSL = """#version 460
#extension GL_EXT_samplerless_texture_functions : require
layout(local_size_x = 8, local_size_y = 8) in;
layout(set = 0, binding = 0) uniform texture2D t_prev;
layout(set = 0, binding = 1, rgba16f) uniform writeonly image2D o_out;
layout(set = 0, binding = 2, std140) uniform Params { float step; } u_params;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_out)))) return;
    imageStore(o_out, p, texelFetch(t_prev, p, 0) + vec4(u_params.step));
}
"""


def test_history_images_start_in_the_planned_layout(vk_device, tmp_path, monkeypatch):
    (tmp_path / "accumulate.comp.glsl").write_text(ACCUMULATE_GLSL)
    monkeypatch.setattr(_Accumulate, "folder_path", tmp_path)
    g = GraphBuilder("history", size=(16, 8))
    g.add_pass("acc", "compute").input("history", "acc.out", History()) \
        .output("out", Texture("rgba16float"))
    plan, _ = fit_plan(g.output("acc.out").build(), vk_device)
    persistent = {r.name for r in plan.resources if not r.transient}
    assert persistent == {"acc.out", "acc.out@prev"}
    # the first barriers start from the steady state, not UNDEFINED: the executor puts the
    # images there before the first frame (validation would flag a wrong old layout)
    assert all(b.src.layout != "UNDEFINED" for b in plan.barriers)
    ex = VkExecutor(vk_device, plan, {"acc": _Accumulate("acc")},
                    {"acc": {"history": "acc.out@prev", "out": "acc.out"}},
                    readback=("acc.out",))
    try:
        ex.run(5)
        out = ex.read("acc.out").astype(np.float32)
    finally:
        ex.destroy()
    assert np.all(out == 5 * 0.125)  # cleared, then one step per frame through the swap


def test_a_pass_needing_a_missing_feature_is_refused_by_name(vk_device):
    from rfw.graph import Attachment, GraphBuilder, GraphError

    g = GraphBuilder("needs", size=(8, 8))
    g.add_pass("cull", "compute", requires=["VK_NV_imaginary_feature"]) \
        .output("o", Attachment("rgba8unorm"))
    with pytest.raises(GraphError, match=r"pass 'cull' needs VK_NV_imaginary_feature, which "
                                         r"the device lacks"):
        fit_graph(g.output("cull.o").build(), vk_device)
