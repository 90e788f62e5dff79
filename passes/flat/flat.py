"""Flat: one directional light, Lambert per vertex, no textures, no tonemap curve."""

from typing import Annotated

from rfw.authoring import Attachment, DepthAttachment, Range, RenderPass, Settings, register_pass


@register_pass("flat")
class FlatPass(RenderPass):
    """The simplest shading rfw has: the equal-work technique of the raster peers.

    Each vertex gets ``base_color * (ambient + (1 - ambient) * max(n.l, 0))``, with the
    material's base colour factor (no texture is read), the world normal and the scene's sun
    (the first directional light; rfw's default sun in a scene without lights). The colour is
    interpolated (Gouraud, as three.js's Lambert material was) and written as it is into an
    8-bit target: no exposure, no curve, no sRGB encoding. Every material is drawn opaque and
    back faces are culled. ``benchmarks/peers/`` renders exactly this in moderngl, pygfx and
    pyvista/VTK (``tests/bench/test_peer_images.py`` measures how close they come).
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "flat"
    outputs = {
        "color": Attachment("rgba8unorm", desc="shaded colour, linear, background black"),
        "depth": DepthAttachment("depth32float", desc="scene depth"),
    }

    class Params(Settings):
        ambient: Annotated[float, Range(0.0, 1.0)] = 0.25  # share of the colour without light

    def record(self, ctx) -> None:
        # masks and blending read textures: without them every material is opaque
        ctx.draw_scene(color=[("color", (0.0, 0.0, 0.0, 1.0))], depth=("depth", 1.0),
                       alpha=("OPAQUE", "MASK", "BLEND"), u_params=self.params)
