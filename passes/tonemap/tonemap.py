"""Tonemap: linear HDR scene color to display-encoded LDR."""

from rfw.authoring import ComputePass, Settings, Tex2D, register_pass


@register_pass("tonemap")
class TonemapPass(ComputePass):
    """Exposure, then a filmic curve (ACES fit), then sRGB encoding.

    Where the HDR alpha is 0 (nothing drawn) the sky color is shown; an alpha between 0 and
    1 is coverage (a temporal resolve's edges), the color premultiplied by it and
    composited over the sky.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "tonemap.comp.glsl"
    inputs = {"hdr": Tex2D(desc="linear HDR scene color")}
    outputs = {"ldr": Tex2D("rgba8unorm", size_of="hdr", desc="display color")}

    class Params(Settings):
        exposure: float = 1.0  # linear multiplier before the curve
        curve: int = 1  # 0: clamp only, 1: ACES fit
        sky: tuple[float, float, float] = (0.55, 0.7, 0.95)  # where hdr alpha is 0 (or < 1)

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("ldr"), t_hdr=ctx.sampled("hdr"),
                     o_ldr=ctx.storage("ldr"), u_params=self.params)
