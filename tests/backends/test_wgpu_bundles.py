"""The wgpu backend records a pass's scene draws once into a render bundle and replays it.

Counted, not timed: bundle encoders made and scene draws encoded over several frames. A
setting that changes the pipeline, or another scene, records again (negative controls); a
setting that only changes uniform bytes does not, and still reaches the image.
"""

from __future__ import annotations

import numpy as np
import pytest

from rfw.backends.wgpu.scene import GpuScene
from rfw.config import apply_overrides, build, load_config
from rfw.frame import open_frame

from ..conftest import ROOT, tiny_scene
from ..golden_util import changed_share

SIZE = "size=96x64"


@pytest.fixture
def counted(monkeypatch):
    """Counts of bundle encoders made and instances encoded (GpuScene.draw's return)."""
    import wgpu

    counts = {"encoders": 0, "draws": 0}
    device_cls = wgpu.backends.wgpu_native.GPUDevice
    make = device_cls.create_render_bundle_encoder
    draw = GpuScene.draw

    def counting_make(self, **kw):
        counts["encoders"] += 1
        return make(self, **kw)

    def counting_draw(self, *a, **kw):
        n = draw(self, *a, **kw)
        counts["draws"] += n
        return n

    monkeypatch.setattr(device_cls, "create_render_bundle_encoder", counting_make)
    monkeypatch.setattr(GpuScene, "draw", counting_draw)
    return counts


def _frame(device, name: str, *sets: str, scene=None):
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [SIZE, *sets])
    return open_frame(build(cfg), "wgpu", devices=(device,), scene=scene or tiny_scene())


def _image(frame, output: str) -> np.ndarray:
    return frame.read(output).copy()


def test_scene_draws_are_recorded_once_and_replayed(device, counted):
    # shadow and gbuffer draw the scene: two bundles, encoded in the first frame only
    frame = _frame(device, "deferred_ssao_shadows")
    try:
        ex = frame.executors["wgpu"]
        frame.run(1)
        first = dict(counted)
        image = _image(frame, "fxaa.color")
        frame.run(3)
        assert first == {"encoders": 2, "draws": 2 * len(ex.scene.scene.instances)}
        assert counted == first  # three more frames: replayed, nothing encoded
        assert ex.bundles_recorded == 2
        assert np.array_equal(_image(frame, "fxaa.color"), image)
    finally:
        frame.destroy()


def test_a_pipeline_setting_records_again(device, counted):
    # negative control: the overdraw pass's cull mode is part of its pipeline
    frame = _frame(device, "deferred_ssao_shadows", "view=overdraw")
    try:
        ex = frame.executors["wgpu"]
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "fxaa.color")
        frame.run(1)
        assert np.array_equal(_image(frame, "fxaa.color"), image)  # control: unchanged
        ex.passes["overdraw"].params.cull = "none"
        frame.run(2)
        assert counted["encoders"] == before + 1  # overdraw alone, and once
        assert changed_share(_image(frame, "fxaa.color"), image) > 0.2  # back faces: 61 %
    finally:
        frame.destroy()


def test_another_scene_records_again(device, counted):
    # negative control: the bundles name the scene's buffers and bind groups
    frame = _frame(device, "deferred")
    try:
        ex = frame.executors["wgpu"]
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "tonemap.ldr")
        frame.run(1)
        assert np.array_equal(_image(frame, "tonemap.ldr"), image)  # control: unchanged
        moved = tiny_scene()
        moved.instances[1].transform[0, 3] = 1.5  # the cube steps aside
        old = ex.scene
        ex.scene = GpuScene(device.device, moved)
        ex.scene.set_viewport(old.size)
        try:
            frame.run(2)
            assert counted["encoders"] == before + 1
            assert changed_share(_image(frame, "tonemap.ldr"), image) > 0.02  # 6.8 %
        finally:
            ex.scene.destroy()
            ex.scene = old
    finally:
        frame.destroy()


def test_a_uniform_setting_reaches_the_replayed_draws(device, counted):
    # forward's ambient is bytes in its u_params buffer, written every frame: no new bundle,
    # and the image is the one a frame built with that setting gives
    frame = _frame(device, "forward")
    fresh = _frame(device, "forward", "forward.ambient=0.25")
    try:
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "tonemap.ldr")
        frame.executors["wgpu"].passes["forward"].params.ambient = 0.25
        frame.run(1)
        assert counted["encoders"] == before
        changed = _image(frame, "tonemap.ldr")
        assert changed_share(changed, image) > 0.05  # 23 % of the pixels
        fresh.run(1)
        assert np.array_equal(changed, _image(fresh, "tonemap.ldr"))
    finally:
        frame.destroy()
        fresh.destroy()


def test_replayed_frames_touch_no_shader_file(device, monkeypatch):
    # a pass's program is looked up from memory between looks at its sources (RECHECK_S)
    from pathlib import Path

    from rfw.backends.wgpu import context, programs

    frame = _frame(device, "deferred_ssao_shadows")
    try:
        frame.run(1)
        stats = []
        real = Path.stat

        def counting_stat(self, *a, **kw):
            stats.append(self)
            return real(self, *a, **kw)

        monkeypatch.setattr(Path, "stat", counting_stat)
        for module in (programs, context):  # however slow the frames are
            monkeypatch.setattr(module, "RECHECK_S", 1e9)
        frame.run(2)
        assert stats == []
        for module in (programs, context):  # negative control: look always
            monkeypatch.setattr(module, "RECHECK_S", 0.0)
        frame.run(1)
        assert any(p.suffix == ".glsl" for p in stats)
    finally:
        frame.destroy()


def test_a_cleared_program_cache_is_not_bypassed(device):
    # rfw view's R clears ShaderCache.programs: the next lookup makes the program again
    from rfw.backends.wgpu.programs import ShaderCache
    from rfw.shaders import program_files

    cache = ShaderCache(device)
    paths = program_files(ROOT / "passes" / "tonemap", "tonemap.comp.glsl")
    made = []

    def make():
        made.append(1)
        return cache.program(paths, {}, "compute", {})

    first = cache.recent(("k",), make)
    assert cache.recent(("k",), make) is first and len(made) == 1
    cache.programs.clear()
    again = cache.recent(("k",), make)
    assert len(made) == 2 and again is not first


_WGSL_SCENE = """
struct Camera { view: mat4x4f, proj: mat4x4f, view_proj: mat4x4f, inv_view_proj: mat4x4f,
                position: vec4f, viewport: vec4f, near_far: vec4f };
struct Lights { data: array<vec4f, 70> };
struct Material { base_color: vec4f, emissive: vec4f, params: vec4f, flags: vec4u };
struct Instance { model: mat4x4f, normal: mat4x4f };
@group(1) @binding(0) var<uniform> camera: Camera;
@group(1) @binding(1) var<uniform> lights: Lights;
@group(2) @binding(0) var<uniform> material: Material;
@group(2) @binding(1) var base_color_tex: texture_2d<f32>;
@group(2) @binding(2) var metal_rough_tex: texture_2d<f32>;
@group(2) @binding(3) var normal_tex: texture_2d<f32>;
@group(2) @binding(4) var occlusion_tex: texture_2d<f32>;
@group(2) @binding(5) var emissive_tex: texture_2d<f32>;
@group(2) @binding(6) var material_sampler: sampler;
@group(3) @binding(0) var<uniform> instance: Instance;
struct VOut { @builtin(position) pos: vec4f, @location(0) world: vec3f };
@vertex fn vs_main(@location(0) p: vec3f) -> VOut {
    let w = instance.model * vec4f(p, 1.0);
    return VOut(camera.view_proj * w, w.xyz);
}
@fragment fn fs_main(v: VOut) -> @location(0) vec4f { return vec4f(v.world, 1.0); }
"""

_GLSL_VERT = """#version 460
#define MESH_VERTEX_INPUT
#include "mesh.glsl"
layout(location = 0) out vec3 f_world;
void main() {
    vec4 w = instance.model * vec4(v_position, 1.0);
    f_world = w.xyz;
    gl_Position = camera.view_proj * w;
}
"""

_GLSL_FRAG = """#version 460
layout(location = 0) in vec3 f_world;
layout(location = 0) out vec4 o_world;
void main() { o_world = vec4(f_world, 1.0); }
"""


def _world_pass(folder, shader: str) -> type:
    from rfw import RenderPass
    from rfw.graph import Attachment, DepthAttachment

    class WorldPass(RenderPass):
        """World position of the nearest surface."""

        outputs = {"world": Attachment("rgba32float"), "depth": DepthAttachment("depth32float")}

        @classmethod
        def folder(cls):
            return folder

        def record(self, ctx) -> None:
            ctx.draw_scene(color=[("world", (0.0, 0.0, 0.0, 0.0))], depth=("depth", 1.0))

    WorldPass.shader = shader
    return WorldPass


def test_a_wgsl_scene_pass_binds_each_instance(device, tmp_path, monkeypatch):
    # the scene's own layout moves one instance group by dynamic offsets; a WGSL pass's
    # reflected layout has none, so it gets a group per instance: both place every instance
    from rfw.testing import run_pass

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    (tmp_path / "world.wgsl").write_text(_WGSL_SCENE)
    (tmp_path / "world.vert.glsl").write_text(_GLSL_VERT)
    (tmp_path / "world.frag.glsl").write_text(_GLSL_FRAG)
    moved = tiny_scene()
    moved.instances[1].transform[0, 3] = 0.5

    def world(shader, scene):
        out = run_pass(_world_pass(tmp_path, shader), {}, scene=scene, device=device,
                       size=(96, 64))
        return out["world"][..., :3]

    glsl, wgsl = world("world", tiny_scene()), world("world.wgsl", tiny_scene())
    covered = glsl[..., 0] != 0
    assert covered.mean() > 0.3  # the floor and the cube
    assert np.abs(glsl - wgsl).max() < 1e-3
    # negative control: the cube half a unit aside is far outside that
    assert np.abs(world("world.wgsl", moved) - glsl).max() > 0.2


def test_a_scene_pass_with_a_fifth_group_is_one_line(device, tmp_path, monkeypatch):
    # a group the draw never sets would abort wgpu-native when the bundle is finished
    from rfw.shaders import ShaderError
    from rfw.testing import run_pass

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    extra = "@group(4) @binding(0) var<uniform> extra: vec4f;\n"
    (tmp_path / "world.wgsl").write_text(_WGSL_SCENE.replace(
        "return vec4f(v.world, 1.0);", "return vec4f(v.world, extra.x);") + extra)
    with pytest.raises(ShaderError, match=r"pass 'WorldPass': .*world\.wgsl declares "
                                          r"groups 0-4: a scene draw binds groups 0"):
        run_pass(_world_pass(tmp_path, "world.wgsl"), {}, scene=tiny_scene(), device=device,
                 size=(32, 32))


def test_an_unchanged_frame_writes_no_uniform(device, monkeypatch):
    # settings are packed and written when their values change, not every frame
    import wgpu

    frame = _frame(device, "deferred_ssao_shadows")
    try:
        frame.run(1)
        writes = []
        queue_cls = wgpu.backends.wgpu_native.GPUQueue
        real = queue_cls.write_buffer

        def counting_write(self, buffer, *a, **kw):
            writes.append(buffer.label)
            return real(self, buffer, *a, **kw)

        monkeypatch.setattr(queue_cls, "write_buffer", counting_write)
        frame.run(2)
        assert writes == []
        # negative control: one changed value is one write, of that pass's buffer
        frame.executors["wgpu"].passes["tonemap"].params.exposure = 2.0
        frame.run(2)
        assert writes == ["tonemap.u_params"]
    finally:
        frame.destroy()
