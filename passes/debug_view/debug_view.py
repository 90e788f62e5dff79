"""Debug view: any float texture turned into something a person can look at."""

from typing import ClassVar

from rfw.authoring import (
    ComputePass,
    Settings,
    SettingsError,
    Slot,
    Tex2D,
    did_you_mean,
    format_info,
    register_pass,
)

# mode names and their numbers (configs may use either)
MODES = {"color": 0, "normals": 1, "depth": 2, "heatmap": 3}
_ALIASES = {"albedo": 0, "passthrough": 0}


@register_pass("debug_view")
class DebugViewPass(ComputePass):
    """Shows ``source`` as rgba8unorm, by ``mode``:

    - ``color`` (0, also ``albedo``, ``passthrough``): the texel as is, clamped to 0..1;
      sRGB sources are re-encoded so their bytes pass through unchanged.
    - ``normals`` (1): ``n * 0.5 + 0.5`` of the xyz channels.
    - ``depth`` (2): depth linearised with the camera's near and far planes, as
      ``(distance - near) / (far - near)`` mapped through ``range`` to grey.
    - ``heatmap`` (3): one ``channel`` mapped through ``range`` onto the turbo colour map.

    Depth formats bind as ``texture_depth_2d``; other formats read channel values directly.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "debug_view.comp.glsl"
    inputs: ClassVar[dict[str, Slot]] = {"source": Tex2D(desc="any float, unorm or depth texture")}
    outputs: ClassVar[dict[str, Slot]] = {
        "view": Tex2D("rgba8unorm", size_of="source", desc="display color"),
    }

    class Params(Settings):
        mode: str = "color"  # color | normals | depth | heatmap, or 0-3
        channel: int = 0  # heatmap: which channel (0-3)
        range: tuple[float, float] = (0.0, 1.0)  # heatmap, depth: value shown as 0 and 1

    def __init__(self, name, params=None, **settings):
        super().__init__(name, params, **settings)
        self.mode = _mode(self.params.mode, name)
        if self.params.range[0] == self.params.range[1]:
            raise SettingsError(f"pass '{name}': setting 'range': needs two different values, "
                                f"got {self.params.range}")

    def record(self, ctx) -> None:
        fmt = format_info(ctx.format("source"))
        defines = {"MODE": self.mode}
        if fmt.depth:
            defines["DEPTH_SOURCE"] = 1
        if fmt.srgb:
            defines["SRGB_SOURCE"] = 1
        if self.mode == MODES["depth"]:
            defines["LINEAR_DEPTH"] = 1  # the only mode that reads the camera
        ctx.dispatch(threads=ctx.extent("view"), defines=defines, t_source=ctx.sampled("source"),
                     o_view=ctx.storage("view"), u_params=self.params)


def _mode(value: str, owner: str) -> int:
    if value.isdigit() and int(value) in MODES.values():
        return int(value)
    key = value.lower()
    if key in MODES or key in _ALIASES:
        return {**MODES, **_ALIASES}[key]
    raise SettingsError(f"pass '{owner}': setting 'mode': unknown mode '{value}'"
                        + did_you_mean(key, [*MODES, *_ALIASES]))
