"""Depth pre-pass: the scene's depth alone, before any shading pass."""

from typing import ClassVar

from rfw import RenderPass, register_pass
from rfw.graph import DepthAttachment, Slot


@register_pass("depth_prepass")
class DepthPrepassPass(RenderPass):
    """Opaque geometry rasterised into depth only, with no fragment shader.

    Its depth matches the G-buffer's bit for bit (same transform, same culling), so a later
    pass can load it and test with ``equal``/``less-equal`` without writing. Alpha-masked
    materials are left out: without a fragment stage their cut-outs would write depth.
    """

    shader = "depth_prepass"
    outputs: ClassVar[dict[str, Slot]] = {
        "depth": DepthAttachment("depth32float", desc="scene depth, 0 near 1 far"),
    }

    def record(self, ctx) -> None:
        if ctx.replay():  # the same settings, image and scene as a recorded frame
            return
        ctx.draw_scene(depth=("depth", 1.0), alpha=("OPAQUE",))
