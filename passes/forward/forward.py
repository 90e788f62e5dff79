"""Forward PBR: each fragment shaded while the scene is rasterised."""

from rfw import RenderPass, Settings, register_pass
from rfw.graph import Attachment, DepthAttachment, Texture


@register_pass("forward")
class ForwardPass(RenderPass):
    """The deferred pass's lighting model, evaluated per fragment while rasterising."""

    shader = "forward.wgsl"
    inputs = {
        "shadow": Texture(optional=True, desc="sun shadow map"),
    }
    outputs = {
        "hdr": Attachment("rgba16float", desc="linear scene radiance"),
        "depth": DepthAttachment("depth32float", desc="scene depth"),
    }

    class Params(Settings):
        shadow_bias: float = 0.0015
        ambient: float = 1.0

    def record(self, ctx) -> None:
        defines = {"HAS_SHADOW": 1} if ctx.has("shadow") else {}
        extra = {"t_shadow": ctx.sampled("shadow"), "s_shadow": ctx.scene.shadow_sampler} \
            if ctx.has("shadow") else {}
        # alpha 0 marks the background: tonemap paints the sky there, as after deferred
        ctx.draw_scene(color=[("hdr", (0.0, 0.0, 0.0, 0.0))], depth=("depth", 1.0),
                       defines=defines, u_params=self.params, **extra)
