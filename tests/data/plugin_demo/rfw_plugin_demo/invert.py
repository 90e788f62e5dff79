"""Invert: 1 - color, a third-party pass found through the rfw.passes entry points."""

from rfw import ComputePass, Tex2D, register_pass


@register_pass("invert")
class InvertPass(ComputePass):
    """Replaces each channel c of an rgba8unorm image by 1 - c."""

    shader = "invert.comp.wgsl"
    inputs = {"src": Tex2D(desc="image to invert")}
    outputs = {"dst": Tex2D("rgba8unorm", size_of="src", desc="inverted image")}

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("dst"), t_src=ctx.sampled("src"), o_dst=ctx.storage("dst"))
