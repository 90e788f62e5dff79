"""Ray-traced ambient occlusion from the G-buffer's depth and normals."""

from rfw.authoring import AccelStructure, RayTracedPass, Tex2D, register_pass


@register_pass("rt_ao")
class RTAOPass(RayTracedPass):
    """Ambient occlusion by ray tracing, in place of SSAO.

    Each pixel's world point is rebuilt from the G-buffer depth and nudged along its normal;
    ``samples`` cosine-weighted rays of the normal's hemisphere test for any hit within
    ``radius`` world units (terminate on the first). The directions come from a hash of the
    pixel and the sample index, so the result is deterministic. ``ao`` is the fraction of
    unoccluded rays (1 = open), in every channel, for ``deferred_lighting``'s ``ao`` input.
    Blended surfaces do not occlude. ``method`` picks ray queries or a ray-tracing pipeline.
    """

    shaders = {"ray_query": "rt_ao.comp.glsl", "ray_pipeline": "rt_ao.rgen.glsl"}
    miss = "rt_ao.rmiss.glsl"
    inputs = {
        "depth": Tex2D(desc="scene depth, 0 near 1 far"),
        "normal": Tex2D(desc="world-space normal"),
        "tlas": AccelStructure(desc="the scene's acceleration structure"),
    }
    outputs = {"ao": Tex2D("rgba16float", size_of="depth",
                           desc="ambient occlusion in every channel (1 = open)")}

    class Params(RayTracedPass.Params):
        radius: float = 1.0  # world units a ray may travel and still occlude
        samples: int = 8  # rays per pixel
        normal_bias: float = 0.02  # world units off the surface (grows with distance)
        t_min: float = 0.001  # rays ignore hits nearer than this

    def record(self, ctx) -> None:
        self.trace(ctx, ctx.extent("ao"), t_depth=ctx.sampled("depth"),
                   t_normal=ctx.sampled("normal"), tlas=ctx.accel("tlas"),
                   o_ao=ctx.storage("ao"), u_params=self.params)
