"""Forward PBR: each fragment shaded while the scene is rasterised."""

from rfw.authoring import (
    Attachment,
    DepthAttachment,
    DepthPrepassMixin,
    RenderPass,
    Settings,
    Texture,
    register_pass,
)

# fed by depth_prepass.depth when the prepass setting is on: tested, never written


@register_pass("forward")
class ForwardPass(DepthPrepassMixin, RenderPass):
    """The deferred pass's lighting model, evaluated per fragment while rasterising.

    With ``prepass = true`` the pass takes a ``depth`` input (``depth_prepass.depth``), tests
    against it with ``less-equal`` and writes no depth (the ``depth`` output is gone): only
    the visible fragment of each pixel is shaded. The prepass leaves alpha-masked materials
    out, so they are drawn tested but unwritten: masked surfaces that overlap each other, or
    opaque ones behind them, resolve in draw order.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "forward"
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
        prepass: bool = False  # test against a depth input instead of writing depth

    def record(self, ctx) -> None:
        defines = {"HAS_SHADOW": 1} if ctx.has("shadow") else {}
        extra = {"t_shadow": ctx.sampled("shadow"), "s_shadow": ctx.scene.shadow_sampler} \
            if ctx.has("shadow") else {}
        # less-equal with or without a prepass: where two surfaces tie in depth the last one
        # drawn wins either way, so the prepass changes no pixel
        depth = {"depth": ("depth", None), "depth_write": False} if self.params.prepass \
            else {"depth": ("depth", 1.0)}
        # alpha 0 marks the background: tonemap paints the sky there, as after deferred
        ctx.draw_scene(color=[("hdr", (0.0, 0.0, 0.0, 0.0))], defines=defines,
                       depth_compare="less-equal", u_params=self.params, **depth, **extra)
