"""Directional shadow map: scene depth from the sun's orthographic camera."""

from typing import Annotated

from rfw.authoring import DepthAttachment, Range, RenderPass, Settings, SizeRule, register_pass


@register_pass("shadow_map")
class ShadowMapPass(RenderPass):
    """Depth of the scene as seen by the sun, for PCF lookups in lighting passes."""

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "shadow_map"
    outputs = {"depth": DepthAttachment("depth32float", desc="sun depth, 0 near 1 far")}

    class Params(Settings):
        resolution: Annotated[int, Range(1, 16384)] = 2048  # texels per side

    def declare(self):
        size = SizeRule.fixed(self.params.resolution, self.params.resolution)
        return {}, {"depth": self.outputs["depth"].with_(size=size)}

    def record(self, ctx) -> None:
        # front faces culled: thin geometry still shadows, and acne moves to back faces
        ctx.draw_scene(depth=("depth", 1.0), camera="sun", cull="front")
