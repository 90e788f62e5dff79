"""Overdraw: how many fragments the scene rasterises into each pixel."""

from typing import ClassVar

from rfw.authoring import (
    Attachment,
    RenderPass,
    Settings,
    SettingsError,
    Slot,
    did_you_mean,
    register_pass,
)

# every fragment adds its output to what is there
_ADD = {"src_factor": "one", "dst_factor": "one", "operation": "add"}
_CULL = ("back", "front", "none")


@register_pass("overdraw")
class OverdrawPass(RenderPass):
    """Every instance drawn without depth testing, each fragment adding 1 to ``count``.

    ``count`` is rgba16float because it is blendable in core WebGPU (r32float needs the
    float32-blendable feature); counts are exact up to 2048. Show it with ``debug_view``
    in heatmap mode.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "overdraw"
    outputs: ClassVar[dict[str, Slot]] = {
        "count": Attachment("rgba16float", desc="fragments per pixel, in every channel"),
    }

    class Params(Settings):
        cull: str = "back"  # back: what the shading passes rasterise; none: every triangle

    def __init__(self, name, params=None, **settings):
        super().__init__(name, params, **settings)
        if self.params.cull not in _CULL:
            raise SettingsError(f"pass '{name}': setting 'cull': unknown mode "
                                f"'{self.params.cull}'" + did_you_mean(self.params.cull, _CULL))

    def record(self, ctx) -> None:
        ctx.draw_scene(color=[("count", (0.0, 0.0, 0.0, 0.0))], depth=None,
                       cull=self.params.cull, blend={"color": _ADD, "alpha": _ADD},
                       alpha=("OPAQUE", "MASK", "BLEND"))
