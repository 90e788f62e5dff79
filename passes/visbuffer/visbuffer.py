"""Visibility buffer: the nearest surface's instance and triangle per pixel, and depth."""

from rfw import RenderPass, register_pass
from rfw.graph import Attachment, DepthAttachment


@register_pass("visbuffer")
class VisBufferPass(RenderPass):
    """The first half of a G-buffer made in two passes: the scene rasterised into depth and
    one ``rg32uint`` target holding, per pixel, the instance (the scene's index) and the
    triangle of the mesh that is nearest. The fragment shader writes those two words and
    nothing else; alpha-masked materials still test their alpha, so coverage and depth are
    the ``gbuffer`` pass's. ``ids`` is not cleared: where ``depth`` is 1 (the background)
    it holds whatever was there, and its reader (``vis_resolve``) looks at depth first.

    Vulkan only: a fragment shader's ``gl_PrimitiveID`` needs the ``geometryShader``
    feature, and the instance comes from the draw's firstInstance.
    """

    shader = "visbuffer"
    requires = ("geometry_shader",)
    backend = "vk"
    outputs = {
        "ids": Attachment("rg32uint", desc="instance, triangle (undefined where depth is 1)"),
        "depth": DepthAttachment("depth32float", desc="0 near, 1 far"),
    }

    def record(self, ctx) -> None:
        # less-equal as the gbuffer pass draws: equal depths resolve to the same surface
        ctx.draw_scene(color=[("ids", None)], depth=("depth", 1.0), depth_compare="less-equal")
