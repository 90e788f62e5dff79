"""Depth pre-pass: the scene's depth alone, before any shading pass."""

from typing import ClassVar

from rfw.authoring import DepthAttachment, RenderPass, Slot, register_pass


@register_pass("depth_prepass")
class DepthPrepassPass(RenderPass):
    """Opaque geometry rasterised into depth only, with no fragment shader.

    Its depth matches the G-buffer's bit for bit (same transform, same culling), so a later
    pass can load it and test with ``equal``/``less-equal`` without writing. Alpha-masked
    materials are left out: without a fragment stage their cut-outs would write depth.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "depth_prepass"
    outputs: ClassVar[dict[str, Slot]] = {
        "depth": DepthAttachment("depth32float", desc="scene depth, 0 near 1 far"),
    }

    def record(self, ctx) -> None:
        ctx.draw_scene(depth=("depth", 1.0), alpha=("OPAQUE",))
