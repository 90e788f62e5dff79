"""FXAA: fast approximate anti-aliasing of the display-encoded image."""

from typing import ClassVar

from rfw.authoring import ComputePass, Settings, Slot, Tex2D, register_pass


@register_pass("fxaa")
class FXAAPass(ComputePass):
    """FXAA 3.11 quality: find edges by luma contrast, walk along them to their ends, and
    resample across the edge by how far the pixel is from the nearer end; a subpixel term
    softens single-pixel features. Luma is taken from the encoded values, as FXAA intends.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "fxaa.comp.glsl"
    inputs: ClassVar[dict[str, Slot]] = {"ldr": Tex2D(desc="display-encoded color (rgba8unorm)")}
    outputs: ClassVar[dict[str, Slot]] = {
        "color": Tex2D("rgba8unorm", size_of="ldr", desc="anti-aliased display color"),
    }

    class Params(Settings):
        edge_threshold: float = 0.125  # local contrast, relative to the brightest luma
        edge_threshold_min: float = 0.0312  # absolute contrast below which dark areas pass
        subpixel: float = 0.75  # 0 sharp, 1 soft: how much single-pixel detail is blended
        search_steps: int = 12  # edge-walk iterations per side (1-12)

    def record(self, ctx) -> None:
        # clamped bilinear reads: the edge walk samples between texels
        ctx.dispatch(threads=ctx.extent("color"), t_ldr=ctx.sampled("ldr"),
                     s_linear=ctx.sampler(filter="linear", address="clamp-to-edge"),
                     o_color=ctx.storage("color"), u_params=self.params)
