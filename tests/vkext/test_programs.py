"""vkext.programs: one program and pipeline cache for compute, render, mesh and ray-tracing
programs; passes reach mesh pipelines through ``ctx.program("mesh")`` and
``ctx.render_pass``. Every run here leaves the validation layer silent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw import RenderPass
from rfw.context import PassContext, RayTracingContext
from rfw.graph import Attachment, GraphBuilder
from rfw.shaders import ShaderError
from vkext.commands import one_time
from vkext.executor import VkExecutor
from vkext.fitting import fit_plan

ROOT = Path(__file__).resolve().parents[2]
RAYCAST = ROOT / "vkext" / "shaders" / "raycast"

# one workgroup emits a triangle covering the left half of the target: x in -1..0 for every
# y in -1..1 (its long edge runs from (-2, -1) to (0, 3))
MESH_GLSL = """#version 460
#extension GL_EXT_mesh_shader : require
layout(local_size_x = 1) in;
layout(triangles, max_vertices = 3, max_primitives = 1) out;
layout(push_constant) uniform Push { vec4 shift; } u_push;
void main() {
    SetMeshOutputsEXT(3, 1);
    gl_MeshVerticesEXT[0].gl_Position = vec4(-2.0, -1.0, 0.5, 1.0) + u_push.shift;
    gl_MeshVerticesEXT[1].gl_Position = vec4(0.0, -1.0, 0.5, 1.0) + u_push.shift;
    gl_MeshVerticesEXT[2].gl_Position = vec4(0.0, 3.0, 0.5, 1.0) + u_push.shift;
    gl_PrimitiveTriangleIndicesEXT[0] = uvec3(0, 1, 2);
}
"""
TASK_GLSL = """#version 460
#extension GL_EXT_mesh_shader : require
layout(local_size_x = 1) in;
void main() { EmitMeshTasksEXT(1, 1, 1); }
"""
FRAG_GLSL = """#version 460
layout(location = 0) out vec4 o_color;
layout(set = 0, binding = 0, std140) uniform Color { vec4 value; } u_color;
void main() { o_color = u_color.value; }
"""
VERT_GLSL = """#version 460
void main() { gl_Position = vec4(0.0); }
"""


class _MeshPass(RenderPass):
    """Draws MESH_GLSL's triangle in u_color over a cleared target."""

    shader = "tri.mesh.glsl"
    folder_path: Path = Path()
    stages: tuple[str, ...] = ("tri.frag.glsl",)
    shift = 0.0
    cull = "none"

    @classmethod
    def folder(cls) -> Path:
        return cls.folder_path

    def record(self, ctx) -> None:
        # what a vk pass is handed implements the protocols (checked at run time too)
        assert isinstance(ctx, PassContext) and isinstance(ctx, RayTracingContext)
        prog = ctx.program("mesh", stages=self.stages)
        with ctx.render_pass(color=[("color", (0.0, 0.0, 0.0, 0.0))]) as rp:
            rp.use(prog, cull=self.cull)
            # whole multiples of 1/255: 0.5 is a rounding tie (lavapipe 128, NVIDIA 127)
            rp.bind(u_color=np.array([1.0, 128 / 255, 64 / 255, 1.0], np.float32).tobytes())
            rp.push(np.array([self.shift, 0, 0, 0], np.float32).tobytes())
            rp.draw_mesh_tasks(1)


def _folder(tmp_path: Path) -> Path:
    for name, text in (("tri.mesh.glsl", MESH_GLSL), ("tri.task.glsl", TASK_GLSL),
                       ("tri.frag.glsl", FRAG_GLSL), ("tri.vert.glsl", VERT_GLSL)):
        (tmp_path / name).write_text(text)
    return tmp_path


def _draw(vk_device, pass_: RenderPass) -> np.ndarray:
    g = GraphBuilder("mesh", size=(16, 8))
    g.add_pass("tri", "graphics").output("color", Attachment("rgba8unorm"))
    plan, _ = fit_plan(g.output("tri.color").build(), vk_device)
    ex = VkExecutor(vk_device, plan, {"tri": pass_}, {"tri": {"color": "tri.color"}},
                    readback=("tri.color",))
    try:
        ex.run(1)
        return ex.read("tri.color")
    finally:
        ex.destroy()


@pytest.fixture
def mesh_pass(vk_device, tmp_path, monkeypatch, private_spirv_cache):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip(f"{vk_device.name} has no VK_EXT_mesh_shader")
    monkeypatch.setattr(_MeshPass, "folder_path", _folder(tmp_path))
    return _MeshPass


@pytest.mark.parametrize("stages", [("tri.frag.glsl",), ("tri.task.glsl", "tri.frag.glsl")])
def test_a_mesh_program_draws_through_the_render_pass(vk_device, mesh_pass, monkeypatch,
                                                       stages):
    monkeypatch.setattr(mesh_pass, "stages", stages)
    img = _draw(vk_device, mesh_pass("tri"))
    # the left half is the triangle's color (rgba8unorm of 1, 128/255, 64/255), the right cleared
    assert np.all(img[:, :8] == [255, 128, 64, 255])
    assert np.all(img[:, 8:] == 0)
    # negative control: the pushed shift moves the triangle into the right half, and the
    # check above fails
    monkeypatch.setattr(mesh_pass, "shift", 2.0)
    moved = _draw(vk_device, mesh_pass("tri"))
    assert not np.all(moved[:, :8] == [255, 128, 64, 255])
    assert np.all(moved[:, :8] == 0) and np.any(moved[:, 8:] == [255, 128, 64, 255])


def test_mesh_programs_share_the_cache(vk_device, mesh_pass):
    # two frames, two executors' worth of passes: one program, one pipeline per executor
    g = GraphBuilder("mesh", size=(16, 8))
    g.add_pass("tri", "graphics").output("color", Attachment("rgba8unorm"))
    plan, _ = fit_plan(g.output("tri.color").build(), vk_device)
    ex = VkExecutor(vk_device, plan, {"tri": mesh_pass("tri")}, {"tri": {"color": "tri.color"}})
    try:
        ex.run(3)
        progs = list(ex.programs.programs.values())
        assert [p.kind for p in progs] == ["mesh"]
        assert sorted(progs[0].modules) == ["frag", "mesh"]
        assert len(progs[0].pipelines) == 1
    finally:
        ex.destroy()


@pytest.mark.parametrize("stages, message", [
    (("tri.task.glsl", "tri.frag.glsl"), None),  # the positive control of the two below
    (("tri.vert.glsl",),
     r".*tri\.vert\.glsl has vert shader\(s\), which a mesh program does not run"),
    (("tri.nothing.glsl",), r"shader .*tri\.nothing\.glsl not found"),
])
def test_mesh_program_stages_are_checked(vk_device, mesh_pass, monkeypatch, stages, message):
    monkeypatch.setattr(mesh_pass, "stages", stages)
    if message is None:
        _draw(vk_device, mesh_pass("tri"))
        return
    with pytest.raises(ShaderError, match=r"pass 'tri': " + message):
        _draw(vk_device, mesh_pass("tri"))


def test_a_mesh_program_needs_a_mesh_shader(vk_device, mesh_pass, monkeypatch):
    monkeypatch.setattr(mesh_pass, "shader", "tri.task.glsl")
    with pytest.raises(ShaderError, match=r"pass 'tri': .*tri\.task\.glsl .* has no mesh "
                                          r"shader"):
        _draw(vk_device, mesh_pass("tri"))


def test_a_render_pass_left_open_is_an_error(vk_device, mesh_pass, monkeypatch):
    def record(self, ctx) -> None:
        rp = ctx.render_pass(color=[("color", None)])
        rp.use(ctx.program("mesh", stages=self.stages), cull="none")

    monkeypatch.setattr(mesh_pass, "record", record)
    with pytest.raises(ShaderError, match=r"pass 'tri' left a render pass open"):
        _draw(vk_device, mesh_pass("tri"))


# ---------------------------------------------------------------------------------------------
# ray tracing outside a frame graph (vkext.rt) builds through the same cache


def test_standalone_ray_pipelines_are_programs(vk_device):
    from vkext.programs import ShaderModule
    from vkext.rt import ComputePipeline, HitGroup, RayTracingPipeline

    for cap in ("VK_KHR_ray_tracing_pipeline", "VK_KHR_ray_query"):
        if cap not in vk_device.caps:
            pytest.skip(f"{vk_device.name} has no {cap}")
    with one_time(vk_device):  # the device's shared upload pool lives as long as it
        pass
    before = vk_device.live_objects()
    rt = RayTracingPipeline(vk_device, RAYCAST / "raycast.rgen.glsl",
                            [RAYCAST / "raycast.rmiss.glsl"],
                            [HitGroup(closest=RAYCAST / "raycast.rchit.glsl")])
    rq = ComputePipeline(vk_device, RAYCAST / "raycast.comp.glsl")
    try:
        assert rt.layout.kind == "ray_tracing" and rq.layout.kind == "compute"
        assert sorted(rt.layout.modules) == ["rchit", "rgen", "rmiss"]
        # one ShaderModule class for every kind of program
        assert {type(m) for p in (rt, rq) for m in p.layout.modules.values()} == {ShaderModule}
        assert rt.counts == {"raygen": 1, "miss": 1, "hit": 1}
        assert len(rt.group_handles()) == 3
        assert set(rt.layout.descriptors) == set(rq.layout.descriptors) >= {"tlas", "rays",
                                                                              "hits"}
    finally:
        rt.destroy()
        rq.destroy()
    assert vk_device.live_objects() == before
    # negative control: a miss shader given as the raygen is refused by name
    with pytest.raises(ValueError, match=r"raycast\.rmiss\.glsl is a rmiss shader, used as "
                                         r"rgen"):
        RayTracingPipeline(vk_device, RAYCAST / "raycast.rmiss.glsl",
                           [RAYCAST / "raycast.rgen.glsl"])
    assert vk_device.live_objects() == before


def test_a_mesh_program_needs_mesh_shaders(vk_device, mesh_pass, monkeypatch):
    _draw(vk_device, mesh_pass("tri"))  # the positive control: the device has them
    monkeypatch.setattr(vk_device, "caps", vk_device.caps - {"VK_EXT_mesh_shader"})
    with pytest.raises(ShaderError, match=r"pass 'tri': a mesh program needs "
                                          r"VK_EXT_mesh_shader, which .* lacks"):
        _draw(vk_device, mesh_pass("tri"))
