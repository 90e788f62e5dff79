"""TAA: temporal anti-aliasing, last frame's result reprojected and blended in."""

import struct
from typing import Annotated, ClassVar

from rfw.authoring import (
    ComputePass,
    History,
    Range,
    Settings,
    SettingsError,
    Slot,
    Tex2D,
    did_you_mean,
    register_pass,
)

# how history is limited to what this frame's 3x3 neighbourhood holds (the shader's CLAMP)
CLAMPS = ("off", "minmax", "variance")


@register_pass("taa")
class TAAPass(ComputePass):
    """Temporal anti-aliasing of linear HDR color (before tonemapping). The camera is
    jittered by sub-pixel Halton (2, 3) offsets (``jitter`` phases, asked of the frame:
    every pass draws with it), and each pixel blends this frame's sample with last frame's
    result found through the motion vectors (``velocity``, taken from the nearest surface
    of the 3x3 neighbourhood; the camera's own motion where nothing is drawn). Before the
    blend the history is clipped to the neighbourhood's colors in YCoCg (``clamp``: variance
    box, min/max box, or off), which keeps stale colors from ghosting; where the history is
    off screen or shows another surface (disocclusion: last frame's depth there is not what
    this surface's depth was, within ``depth_tolerance``) the pixel is this frame's sample
    alone, as on the first frame. Blend weights are divided by 1 + luminance, so one bright
    sample does not flicker through.
    """

    shader = "taa.comp.glsl"
    # recorded every frame: the first frame (no history yet) records another uniform value
    replay = False
    inputs: ClassVar[dict[str, Slot]] = {
        "hdr": Tex2D(desc="this frame's linear HDR color, rendered with the jittered camera"),
        "velocity": Tex2D(desc="pixels to last frame's position (gbuffer.velocity)"),
        "depth": Tex2D(desc="this frame's depth (0 near, 1 background)"),
        "history": History(desc="last frame's result (taa.color)"),
        "history_depth": History(desc="last frame's depth (the depth input's resource)"),
    }
    outputs: ClassVar[dict[str, Slot]] = {
        "color": Tex2D("rgba16float", size_of="hdr", desc="temporally resolved linear color"),
    }

    class Params(Settings):
        feedback: Annotated[float, Range(0.0, 0.999)] = 0.9  # history's share of the blend
        jitter: Annotated[int, Range(0, 256)] = 8  # Halton phases of the camera jitter (0 off)
        clamp: str = "variance"  # off | minmax | variance: history kept to the neighbourhood
        variance_gamma: Annotated[float, Range(0.0, 16.0)] = 1.0  # box: mean +- gamma sigma
        depth_tolerance: Annotated[float, Range(0.0, 1e6)] = 0.1  # relative, linear depth

    def __init__(self, name: str, params: Settings | None = None, **settings) -> None:
        super().__init__(name, params, **settings)
        clamp = self.params.clamp
        if clamp not in CLAMPS:
            raise SettingsError(f"pass '{name}': clamp '{clamp}' is not one of "
                                f"{', '.join(CLAMPS)}" + did_you_mean(clamp, CLAMPS))

    def camera_jitter(self) -> int:
        return self.params.jitter

    def record(self, ctx) -> None:
        # the executor's first frame has no history: its @prev images hold nothing yet
        first = struct.pack("<4I", int(ctx.frame > 0), 0, 0, 0)
        ctx.dispatch(threads=ctx.extent("color"), defines={"CLAMP": CLAMPS.index(
            self.params.clamp)}, t_hdr=ctx.sampled("hdr"), t_velocity=ctx.sampled("velocity"),
            t_depth=ctx.sampled("depth"), t_history=ctx.sampled("history"),
            t_history_depth=ctx.sampled("history_depth"),
            s_linear=ctx.sampler(filter="linear", address="clamp-to-edge"),
            o_color=ctx.storage("color"), u_params=self.params, u_frame=first)
