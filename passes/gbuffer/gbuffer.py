"""G-buffer: the scene's materials rasterised into screen-space attributes."""

from rfw.authoring import (
    GBUFFER,
    Attachment,
    DepthPrepassMixin,
    RenderPass,
    Settings,
    register_pass,
)

VELOCITY = Attachment("rg16float", desc="pixels from this frame's position to the last "
                                        "frame's (x right, y down), without the jitter")


@register_pass("gbuffer")
class GBufferPass(DepthPrepassMixin, RenderPass):
    """Base color, world normal, occlusion/roughness/metallic, emissive and depth.

    With ``prepass = true`` the pass takes a ``depth`` input (``depth_prepass.depth``), tests
    against it with ``less-equal`` and writes no depth: the ``depth`` output is gone, so
    readers of scene depth wire ``depth_prepass.depth`` instead. The prepass leaves
    alpha-masked materials out, so they are drawn tested but unwritten: masked surfaces that
    overlap each other, or opaque ones behind them, resolve in draw order.

    With ``velocity = true`` it also writes motion vectors (``velocity``): where each
    pixel's surface was on screen last frame, from the camera's last view-projection and
    each instance's last transform (``motion.glsl``), in pixels; zero on the first frame
    and where nothing is drawn.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "gbuffer"
    outputs = dict(GBUFFER)

    class Params(Settings):
        prepass: bool = False  # test against a depth input instead of writing depth
        velocity: bool = False  # also write motion vectors, for temporal passes

    def declare(self):
        ins, outs = super().declare()
        if self.params.velocity:
            outs["velocity"] = VELOCITY
        return ins, outs

    def record(self, ctx) -> None:
        clear = (0.0, 0.0, 0.0, 0.0)
        color = [("albedo", clear), ("normal", clear), ("material", clear), ("emissive", clear)]
        # less-equal with or without a prepass: where two surfaces tie in depth the last one
        # drawn wins either way, so the prepass changes no pixel
        depth = {"depth": ("depth", None), "depth_write": False} if self.params.prepass \
            else {"depth": ("depth", 1.0)}
        if not self.params.velocity:
            ctx.draw_scene(color=color, depth_compare="less-equal", **depth)
            return
        scene = ctx.scene.bindings() if ctx.scene is not None else {}  # none: draw_scene says
        ctx.draw_scene(color=[*color, ("velocity", clear)], depth_compare="less-equal",
                       defines={"VELOCITY": 1}, motion=scene.get("motion"),
                       prev_instances=scene.get("prev_instances"), **depth)
