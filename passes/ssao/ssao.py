"""Screen-space ambient occlusion from the G-buffer's depth and normals, at half resolution."""

from typing import ClassVar

from rfw.authoring import ComputePass, Settings, Slot, Step, Tex2D, format_info, register_pass


@register_pass("ssao")
class SSAOPass(ComputePass):
    """Normal-oriented hemisphere SSAO in view space, then a depth-aware blur.

    Each half-resolution texel reconstructs the view-space point of the top-left full-resolution
    pixel it covers, and tests ``samples`` points of a cosine-weighted hemisphere of ``radius``
    world units around its normal against the depth buffer (rotated per pixel by interleaved
    gradient noise, so the result is deterministic). Occluders more than a radius nearer than
    the point fade out by two radii, so silhouettes leave no halo on what lies far behind them.
    A second dispatch blurs the noise away with weights that drop to zero across depth
    discontinuities. 1 means unoccluded.

    The two dispatches are declared steps (the blur reads the occlusion the first writes):
    the compiled graph plans the barrier on ``ao_raw`` between them.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "ssao.comp.glsl"
    inputs: ClassVar[dict[str, Slot]] = {
        "depth": Tex2D(desc="scene depth, 0 near 1 far (a depth format, or r32float)"),
        "normal": Tex2D(desc="world-space normal (xyz)"),
    }
    outputs: ClassVar[dict[str, Slot]] = {
        # rgba16float, not r32float: lighting passes upsample it with a filtering sampler,
        # and r32float is filterable only with the float32-filterable feature
        "ao": Tex2D("rgba16float", size_of="depth", scale=0.5,
                    desc="ambient occlusion, blurred, in every channel (1 = open)"),
        "ao_raw": Tex2D("r32float", size_of="depth", scale=0.5,
                        desc="internal: occlusion before the blur"),
    }

    class Params(Settings):
        radius: float = 0.5  # hemisphere radius, world units
        samples: int = 16  # points per pixel (1-64)
        intensity: float = 1.0  # occlusion multiplier before the power curve
        power: float = 1.5  # contrast: ao = (1 - intensity * occlusion) ** power
        bias: float = 0.025  # view-space depth a sample must be behind to count, world units
        blur_radius: int = 2  # blur kernel half-width in half-resolution texels (0: off)
        blur_depth: float = 0.05  # relative depth difference at which blur weights reach 0

    def steps(self) -> tuple[Step, ...]:
        return (Step("occlusion", writes="ao_raw"),
                Step("blur", reads="ao_raw", writes="ao"))

    def record(self, ctx) -> None:
        # depth buffers bind as texture_depth_2d, copies (tests, readbacks) as plain floats
        defines = {"DEPTH_TEXTURE": 1} if format_info(ctx.format("depth")).depth else {}
        depth = ctx.sampled("depth")
        ctx.step(0)
        ctx.dispatch(threads=ctx.extent("ao_raw"), defines=defines, t_depth=depth,
                     t_normal=ctx.sampled("normal"), o_ao=ctx.storage("ao_raw"),
                     u_params=self.params)
        ctx.step(1)
        ctx.dispatch(threads=ctx.extent("ao"), shader="ssao_blur.comp.glsl", defines=defines,
                     t_depth=depth, t_ao=ctx.storage("ao_raw"), o_ao=ctx.storage("ao"),
                     u_params=self.params)
