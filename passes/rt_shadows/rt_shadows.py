"""Ray-traced shadows: per-light visibility of each G-buffer pixel, in one bit per light."""

from rfw.authoring import AccelStructure, RayTracedPass, Tex2D, register_pass


@register_pass("rt_shadows")
class RTShadowsPass(RayTracedPass):
    """Hard shadows of the sun and the point lights by ray tracing, in place of a shadow map.

    Each pixel's world point is rebuilt from the G-buffer depth (the camera's inverse
    view-projection) and nudged along its normal; one terminate-on-first-hit ray per light
    that faces it goes toward the light (the sun: along its direction). Blended surfaces cast
    no shadow (the TLAS mask skips them, as the shadow map leaves them out); alpha-tested
    ones shadow as opaque (no any-hit test yet). Bit i of ``visibility`` is set where light
    i is unoccluded: ``deferred_lighting`` takes it as its ``visibility`` input. ``method``
    picks ray queries or a ray-tracing pipeline; the results are the same.
    """

    shaders = {"ray_query": "rt_shadows.comp.glsl", "ray_pipeline": "rt_shadows.rgen.glsl"}
    miss = "rt_shadows.rmiss.glsl"
    inputs = {
        "depth": Tex2D(desc="scene depth, 0 near 1 far"),
        "normal": Tex2D(desc="world-space normal"),
        "tlas": AccelStructure(desc="the scene's acceleration structure"),
    }
    outputs = {"visibility": Tex2D("r32uint", size_of="depth",
                                   desc="bit i: light i reaches the pixel (all set: sky)")}

    class Params(RayTracedPass.Params):
        normal_bias: float = 0.02  # world units off the surface (grows with distance)
        t_min: float = 0.001  # rays ignore hits nearer than this
        point_lights: bool = True  # false: only the sun casts shadows (as a shadow map)

    def record(self, ctx) -> None:
        self.trace(ctx, ctx.extent("visibility"), t_depth=ctx.sampled("depth"),
                   t_normal=ctx.sampled("normal"), tlas=ctx.accel("tlas"),
                   o_visibility=ctx.storage("visibility"), u_params=self.params)
