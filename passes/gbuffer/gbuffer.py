"""G-buffer: the scene's materials rasterised into screen-space attributes."""

from rfw import RenderPass, register_pass
from rfw.graph import Attachment, DepthAttachment


@register_pass("gbuffer")
class GBufferPass(RenderPass):
    """Base color, world normal, occlusion/roughness/metallic, emissive and depth."""

    shader = "gbuffer.wgsl"
    outputs = {
        "albedo": Attachment("rgba8unorm-srgb", desc="base color (alpha: coverage)"),
        "normal": Attachment("rgba16float", desc="world-space normal"),
        "material": Attachment("rgba8unorm", desc="occlusion, roughness, metallic"),
        "emissive": Attachment("rgba16float", desc="emitted radiance"),
        "depth": DepthAttachment("depth32float", desc="0 near, 1 far"),
    }

    def record(self, ctx) -> None:
        clear = (0.0, 0.0, 0.0, 0.0)
        ctx.draw_scene(color=[("albedo", clear), ("normal", clear), ("material", clear),
                              ("emissive", clear)], depth=("depth", 1.0))
