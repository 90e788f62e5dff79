"""G-buffer: the scene's materials rasterised into screen-space attributes."""

from rfw.authoring import (
    GBUFFER,
    DepthPrepassMixin,
    RenderPass,
    Settings,
    register_pass,
)

# fed by depth_prepass.depth when the prepass setting is on: tested, never written


@register_pass("gbuffer")
class GBufferPass(DepthPrepassMixin, RenderPass):
    """Base color, world normal, occlusion/roughness/metallic, emissive and depth.

    With ``prepass = true`` the pass takes a ``depth`` input (``depth_prepass.depth``), tests
    against it with ``less-equal`` and writes no depth: the ``depth`` output is gone, so
    readers of scene depth wire ``depth_prepass.depth`` instead. The prepass leaves
    alpha-masked materials out, so they are drawn tested but unwritten: masked surfaces that
    overlap each other, or opaque ones behind them, resolve in draw order.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "gbuffer"
    outputs = dict(GBUFFER)

    class Params(Settings):
        prepass: bool = False  # test against a depth input instead of writing depth

    def record(self, ctx) -> None:
        clear = (0.0, 0.0, 0.0, 0.0)
        color = [("albedo", clear), ("normal", clear), ("material", clear), ("emissive", clear)]
        # less-equal with or without a prepass: where two surfaces tie in depth the last one
        # drawn wins either way, so the prepass changes no pixel
        depth = {"depth": ("depth", None), "depth_write": False} if self.params.prepass \
            else {"depth": ("depth", 1.0)}
        ctx.draw_scene(color=color, depth_compare="less-equal", **depth)
