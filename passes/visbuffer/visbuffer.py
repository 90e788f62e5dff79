"""Visibility buffer: the nearest surface's instance and triangle per pixel, and depth."""

from rfw.authoring import (
    Attachment,
    DepthAttachment,
    RenderPass,
    Settings,
    SettingsError,
    Storage,
    register_pass,
    triangle_bits,
)

WRITES = ("attachment", "atomic")


@register_pass("visbuffer")
class VisBufferPass(RenderPass):
    """The first half of a G-buffer made in two passes: the scene rasterised into depth and
    one 32-bit id per pixel of the nearest surface: its instance (the scene's index) in the
    high bits, its triangle in the mesh in the low ``triangle_bits(scene)``. The fragment
    shader writes that id and nothing else; alpha-masked materials still test their alpha,
    so coverage and depth are the ``gbuffer`` pass's.

    ``write = "attachment"`` (default): ``ids`` is an ``r32uint`` color attachment, not
    cleared: where ``depth`` is 1 (the background) it holds whatever was there, and its
    reader (``vis_resolve``) looks at depth first. ``write = "atomic"``: no color attachment
    (raster writes cost by the byte, and an H100-class GPU has little raster hardware);
    each fragment keeps the smaller of its (depth bits << 32 | ~id) and the word already
    in the ``ids`` buffer (``vis_clear``'s, in place) with a 64-bit atomic min, so the
    nearest surface wins and, at equal depth, the larger id (the one drawn later, as
    less-equal gives). Opaque materials then draw with early fragment tests, masked ones
    after them without.

    Vulkan only: a fragment shader's ``gl_PrimitiveID`` needs the ``geometryShader``
    feature, and the instance comes from the draw's firstInstance.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "visbuffer"
    requires = ("geometry_shader",)
    backend = "vk"
    outputs = {
        "ids": Attachment("r32uint", desc="instance << triangle_bits | triangle "
                                          "(undefined where depth is 1)"),
        "depth": DepthAttachment("depth32float", desc="0 near, 1 far"),
    }

    class Params(Settings):
        write: str = "attachment"  # attachment | atomic

    def declare(self):
        if self.params.write not in WRITES:
            raise SettingsError(f"pass '{self.name}': setting 'write' must be one of "
                                f"{', '.join(WRITES)}, got {self.params.write!r}")
        if self.params.write == "attachment":
            return {}, dict(self.outputs)
        return ({"ids": Storage(desc="vis_clear.ids: per pixel depth bits << 32 | ~id, "
                                     "kept by atomic min")},
                {"depth": self.outputs["depth"]})

    def setup(self, ctx) -> None:
        # fixed while the scene is: the split of the id's bits
        self.defines = {} if ctx.scene is None else \
            {"TRIANGLE_BITS": triangle_bits(ctx.scene.scene)}

    def record(self, ctx) -> None:
        if self.params.write == "attachment":
            # less-equal as the gbuffer pass draws: equal depths resolve to the same surface
            ctx.draw_scene(color=[("ids", None)], depth=("depth", 1.0),
                           depth_compare="less-equal", defines=self.defines)
            return
        # the atomic min orders surfaces itself, so opaque ones may skip the shader where
        # hidden (early tests); masked ones discard, so they test late, after them
        ids = ctx.buffer("ids")
        ctx.draw_scene(depth=("depth", 1.0), depth_compare="less-equal", alpha=("OPAQUE",),
                       defines={**self.defines, "ATOMIC": 1, "EARLY_TESTS": 1}, ids=ids)
        ctx.draw_scene(depth=("depth", None), depth_compare="less-equal", alpha=("MASK",),
                       defines={**self.defines, "ATOMIC": 1}, ids=ids)

