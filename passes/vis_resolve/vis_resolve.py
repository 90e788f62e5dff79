"""Visibility-buffer resolve: the G-buffer computed from instance and triangle ids."""

from rfw.authoring import (
    Buffer,
    ComputePass,
    Settings,
    SettingsError,
    Tex2D,
    register_pass,
    scene_table_bindings,
    triangle_bits,
)


@register_pass("vis_resolve")
class VisResolvePass(ComputePass):
    """The ``gbuffer`` pass's outputs, made by one compute thread per pixel from a
    ``visbuffer``: the thread reads the triangle's three vertices from the scene's own
    vertex and index buffers (device addresses), solves perspective-correct barycentrics
    from the camera and the three clip-space corners, interpolates normal, uv and tangent
    as the rasteriser would, and evaluates the material with the G-buffer's own code
    (``shaders/common/material.glsl``; any material of the scene: descriptor indexing). Its
    texture gradients are what a fragment shader's implicit lookup takes: differences across
    the pixel's 2x2 quad, on the triangle's plane. Where ``depth`` is 1 every output is
    zero, the G-buffer's clear. ``ids = "buffer"`` reads the 64-bit words of a visbuffer
    with ``write = "atomic"`` instead of its ``r32uint`` image.

    ``albedo`` is ``rgba16float`` instead of the G-buffer's ``rgba8unorm-srgb`` (a storage
    image cannot be sRGB): it holds the 8-bit sRGB level decoded, the linear value lighting
    reads from the G-buffer's attachment. Vulkan only.
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "vis_resolve.comp.glsl"
    requires = ("descriptor_indexing", "buffer_device_address")
    backend = "vk"
    inputs = {
        "ids": Tex2D(desc="instance and triangle ids (visbuffer.ids)"),
        "depth": Tex2D(desc="scene depth: 1 is background"),
    }
    outputs = {
        "albedo": Tex2D("rgba16float", size_of="depth", desc="base color, linear (alpha: coverage)"),
        "normal": Tex2D("rgba16float", size_of="depth", desc="world-space normal"),
        "material": Tex2D("rgba8unorm", size_of="depth", desc="occlusion, roughness, metallic"),
        "emissive": Tex2D("rgba16float", size_of="depth", desc="emitted radiance"),
    }

    class Params(Settings):
        ids: str = "image"  # image (visbuffer write = attachment) | buffer (write = atomic)

    def declare(self):
        if self.params.ids not in ("image", "buffer"):
            raise SettingsError(f"pass '{self.name}': setting 'ids' must be image or buffer, "
                                f"got {self.params.ids!r}")
        if self.params.ids == "image":
            return dict(self.inputs), dict(self.outputs)
        # the atomic visbuffer's words
        return {**self.inputs, "ids": Buffer(desc="per pixel depth bits << 32 | ~id "
                                                  "(visbuffer write = atomic)")}, \
            dict(self.outputs)

    def setup(self, ctx) -> None:
        """The scene's mesh, instance and material tables (host-visible storage buffers),
        and what every dispatch binds besides them (fixed while the scene is)."""
        self.tables = None
        if ctx.scene is None:
            return
        self.tables, self.defines = scene_table_bindings(ctx, self.name)
        self.defines["TRIANGLE_BITS"] = triangle_bits(ctx.scene.scene)

    def record(self, ctx) -> None:
        ids = {"t_ids": ctx.sampled("ids")} if self.params.ids == "image" else \
            {"ids": ctx.buffer("ids")}
        defines = self.defines if self.params.ids == "image" else {**self.defines, "ATOMIC": 1}
        ctx.dispatch(threads=ctx.extent("albedo"), defines=defines, **ids,
                     t_depth=ctx.sampled("depth"),
                     o_albedo=ctx.storage("albedo"), o_normal=ctx.storage("normal"),
                     o_material=ctx.storage("material"), o_emissive=ctx.storage("emissive"),
                     **self.tables)
