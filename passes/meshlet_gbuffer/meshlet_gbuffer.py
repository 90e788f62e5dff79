"""G-buffer through task and mesh shaders: the gbuffer pass's outputs from meshlets."""

from passes.gbuffer.gbuffer import GBufferPass
from rfw import RenderPass, Settings, register_pass


@register_pass("meshlet_gbuffer")
class MeshletGBufferPass(RenderPass):
    """The ``gbuffer`` pass's attachments, rasterised from meshlets (64 vertices, 124
    triangles; ``vkext.meshlet``): a task shader culls 32 meshlets per workgroup (normal cone
    and bounding sphere against the frustum, both conservative), a mesh shader emits the
    survivors, and ``passes/gbuffer/gbuffer.frag.glsl`` shades them unchanged. Vulkan only
    (``VK_EXT_mesh_shader``); the culling counters are read through
    ``self.meshlets`` (a ``vkext.meshlet.MeshletScene``): ``counters()`` while the scene
    lives, ``last`` after it is destroyed."""

    shader = "meshlet_gbuffer.mesh.glsl"
    requires = ("VK_EXT_mesh_shader",)
    backend = "vk"
    outputs = dict(GBufferPass.outputs)

    class Params(Settings):
        cone: bool = True  # cull meshlets whose normal cone faces away from the camera
        frustum: bool = True  # cull meshlets whose bounding sphere is outside the frustum

    def record(self, ctx) -> None:
        from vkext.meshlet import draw_meshlets, meshlet_scene

        self.meshlets = meshlet_scene(ctx.scene) if ctx.scene is not None else None

        clear = (0.0, 0.0, 0.0, 0.0)
        color = [("albedo", clear), ("normal", clear), ("material", clear), ("emissive", clear)]
        draw_meshlets(ctx, color=color, depth=("depth", 1.0), cone=self.params.cone,
                      frustum=self.params.frustum, depth_compare="less-equal")
