"""Deferred PBR lighting: G-buffer in, linear HDR radiance out."""

from rfw.authoring import ComputePass, Settings, Texture, register_pass


@register_pass("deferred_lighting")
class DeferredLightingPass(ComputePass):
    """Directional and point lights with GGX, sun shadows (PCF) and ambient occlusion.

    Shadows come from a sun shadow map (``shadow``), or from a screen-space ``visibility``
    mask (``rt_shadows``: bit i set where light i reaches the pixel, for all lights), or
    both."""

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "deferred_lighting.comp.glsl"
    inputs = {
        "albedo": Texture(desc="base color"),
        "normal": Texture(desc="world normal"),
        "material": Texture(desc="occlusion, roughness, metallic"),
        "emissive": Texture(desc="emitted radiance"),
        "depth": Texture(desc="scene depth"),
        "shadow": Texture(optional=True, desc="sun shadow map"),
        "ao": Texture(optional=True, desc="ambient occlusion (1 = open)"),
        "visibility": Texture("r32uint", optional=True,
                              desc="per-light visibility bits (bit i: light i unoccluded)"),
    }
    outputs = {"hdr": Texture("rgba16float", desc="linear scene radiance")}

    class Params(Settings):
        shadow_bias: float = 0.0015  # in light-space depth
        ambient: float = 1.0  # sky ambient multiplier

    def record(self, ctx) -> None:
        defines = {"HAS_SHADOW": 1} if ctx.has("shadow") else {}
        extra = {"t_shadow": ctx.sampled("shadow"), "s_shadow": ctx.scene.shadow_sampler} \
            if ctx.has("shadow") else {}
        if ctx.has("ao"):
            defines["HAS_AO"] = 1
            extra["t_ao"] = ctx.sampled("ao")
            extra["s_linear"] = ctx.scene.linear_sampler
        if ctx.has("visibility"):
            defines["HAS_VISIBILITY"] = 1
            extra["t_visibility"] = ctx.sampled("visibility")
        ctx.dispatch(threads=ctx.extent("hdr"), defines=defines,
                     t_albedo=ctx.sampled("albedo"), t_normal=ctx.sampled("normal"),
                     t_material=ctx.sampled("material"), t_emissive=ctx.sampled("emissive"),
                     t_depth=ctx.sampled("depth"), o_hdr=ctx.storage("hdr"),
                     u_params=self.params, **extra)
