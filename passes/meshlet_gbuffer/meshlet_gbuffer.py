"""G-buffer through task and mesh shaders: the gbuffer pass's outputs from meshlets."""

from passes.gbuffer.gbuffer import GBufferPass
from rfw import RenderPass, Settings, register_pass
from rfw.graph import History


@register_pass("meshlet_gbuffer")
class MeshletGBufferPass(RenderPass):
    """The ``gbuffer`` pass's attachments, rasterised from meshlets (64 vertices, 124
    triangles; ``vkext.meshlet``): a task shader culls 32 meshlets per workgroup (normal cone
    and bounding sphere against the frustum, both conservative), a mesh shader emits the
    survivors, and ``passes/gbuffer/gbuffer.frag.glsl`` shades them unchanged. Vulkan only
    (``VK_EXT_mesh_shader``); the culling counters are read through
    ``self.meshlets`` (a ``vkext.meshlet.MeshletScene``): ``counters()`` while the scene
    lives, ``last`` after it is destroyed.

    ``occlusion = true`` culls against the optional input ``pyramid``, the previous frame's max-depth pyramid
    (``History()`` of ``depth_pyramid.pyramid``, built from this pass's depth): meshlets whose
    bounding sphere lies behind it are culled. Single phase (last frame's pyramid only), so it
    is exact for a still camera and scene; the first frame (empty history) draws without
    it."""

    shader = "meshlet_gbuffer.mesh.glsl"
    requires = ("VK_EXT_mesh_shader",)
    backend = "vk"
    # optional: configs without a pyramid drop it (occlusion then stays off)
    inputs = {"pyramid": History(stages=("TASK_SHADER_EXT",), optional=True,
                                 desc="last frame's max-depth pyramid (depth_pyramid)")}
    outputs = dict(GBufferPass.outputs)

    class Params(Settings):
        cone: bool = True  # cull meshlets whose normal cone faces away from the camera
        frustum: bool = True  # cull meshlets whose bounding sphere is outside the frustum
        occlusion: bool = False  # cull against the previous frame's depth pyramid


    def record(self, ctx) -> None:
        from vkext.meshlet import draw_meshlets, meshlet_scene

        self.meshlets = meshlet_scene(ctx.scene) if ctx.scene is not None else None

        clear = (0.0, 0.0, 0.0, 0.0)
        color = [("albedo", clear), ("normal", clear), ("material", clear), ("emissive", clear)]
        draw_meshlets(ctx, color=color, depth=("depth", 1.0), cone=self.params.cone,
                      frustum=self.params.frustum, depth_compare="less-equal",
                      pyramid=self._pyramid(ctx))

    def _pyramid(self, ctx):
        # frame 0's history is empty (cleared to 0, nearer than everything): no occlusion
        if not self.params.occlusion or not ctx.has("pyramid") or ctx.frame == 0:
            return None
        from vkext.executor import ImageBinding

        name = ctx.resource("pyramid")  # a history slot: last frame's pyramid
        return ImageBinding(name, ctx.executor.image(name), ctx.executor.view(name))
