"""The reference path tracer: ground truth for the raster and ray-traced techniques."""

import struct

import numpy as np

from rfw.authoring import (
    AccelStructure,
    History,
    RayTracedPass,
    SettingsError,
    Tex2D,
    did_you_mean,
    register_pass,
    scene_table_bindings,
)

MODES = ("full", "ao", "visibility")

# Sobol dimensions 1-4 (Joe and Kuo's construction: degree s, coefficients a, initial m)
_SOBOL = ((0, 0, ()), (1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)))


def sobol_directions() -> np.ndarray:
    """The 32 direction numbers of each of the first four Sobol dimensions, as uint32
    (dimension-major): x_i = XOR of v[d][b] over the set bits b of index i."""
    out = np.zeros((len(_SOBOL), 32), np.uint32)
    for d, (s, a, m) in enumerate(_SOBOL):
        if s == 0:  # van der Corput
            out[d] = [1 << (31 - b) for b in range(32)]
            continue
        mm = list(m)
        for i in range(s, 32):
            value = mm[i - s] ^ (mm[i - s] << s)
            for k in range(1, s):
                if (a >> (s - 1 - k)) & 1:
                    value ^= mm[i - k] << k
            mm.append(value)
        out[d] = [(mm[b] << (31 - b)) & 0xFFFFFFFF for b in range(32)]
    return out.reshape(-1)


@register_pass("pathtrace")
class PathTracePass(RayTracedPass):
    """A progressive unidirectional path tracer of the scene the raster passes draw, with
    their material model, lights and sky, as the reference they are measured against.

    Materials are ``shaders/common/material.glsl``'s surface (base color, metallic-roughness
    and normal textures, emissive, alpha mask) with ``pbr.glsl``'s BRDF, whose dielectric
    lobe ``Material.specular`` scales (KHR_materials_specular; 1 is what the raster passes
    shade). Lights are the scene's punctual lights (the default sun where it has none) and a
    uniform sky of the lights block's ambient radiance times ``sky``. Every bounce samples
    each punctual light with one shadow ray and the sky with a cosine-distributed one,
    weighted against BSDF sampling (GGX visible normals, or cosine for the diffuse lobe) by
    the power heuristic; Russian roulette from bounce ``rr_start``. Blended surfaces let
    rays through with the probability of their transparency, masked ones where their
    coverage is under the cutoff. Textures are read at the LOD of each hit's ray cone (the
    talk's texture-LOD problem: ray-traced albedo aliases without one).

    Samples are Owen-scrambled Sobol points (Burley 2020) seeded by ``seed`` and the pixel,
    so a run is deterministic for a seed. Each frame adds ``spp`` samples to ``sums`` (rgb:
    radiance, a: samples) and ``half`` (the even samples' radiance, a: camera-ray hits),
    history pairs carried from frame to frame, which restart on the first frame and when the
    camera or an instance moves (a camera path, the scene's animations). ``hdr`` is their
    mean (linear radiance; alpha: the share of samples whose camera ray hit the scene, 0 on
    the sky, as the raster passes leave the background) and
    ``error`` the convergence estimate: half the difference of the even and odd samples'
    means, per channel (alpha: samples). ``mode`` ``ao`` and ``visibility`` make per-effect
    references instead: the ambient occlusion rt_ao computes (radius ``ao_radius``) and the
    visibility of light ``light`` (-1: the sun) that rt_shadows computes, each averaged over
    the pixel. ``jitter = false`` sends camera rays through pixel centres only: the truth
    of what a technique that samples each pixel once at its centre should give (no
    anti-aliasing), to judge its shading apart from its edges.
    """

    shaders = {"ray_query": "pathtrace.comp.glsl", "ray_pipeline": "pathtrace.rgen.glsl"}
    miss = "pathtrace.rmiss.glsl"
    closest_hit = "pathtrace.rchit.glsl"
    any_hit = "pathtrace.rahit.glsl"
    inputs = {
        "tlas": AccelStructure(desc="the scene's acceleration structure"),
        "sums_prev": History(desc="last frame's sums (this pass's own, via @prev)"),
        "half_prev": History(desc="last frame's half sums"),
    }
    outputs = {
        "sums": Tex2D("rgba32float", desc="radiance sum, samples (history)"),
        "half": Tex2D("rgba32float", desc="even samples' radiance sum, camera hits (history)"),
        "hdr": Tex2D("rgba32float", desc="mean linear radiance; alpha: camera-ray hit share"),
        "error": Tex2D("rgba32float", desc="convergence estimate per channel; alpha: samples"),
    }

    class Params(RayTracedPass.Params):
        spp: int = 1  # samples per pixel added each frame
        max_bounces: int = 8
        rr_start: int = 3  # Russian roulette from this bounce on
        seed: int = 0
        sky: float = 1.0  # the sky's radiance: the lights block's ambient times this
        ao_radius: float = 1.0  # mode ao: world units a ray may travel and still occlude
        light: int = -1  # mode visibility: the light (-1: the sun)
        jitter: bool = True  # false: camera rays through pixel centres (no anti-aliasing)
        mode: str = "full"  # full | ao | visibility

    def __init__(self, name, params=None, **settings):
        super().__init__(name, params, **settings)
        p = self.params
        if p.mode not in MODES:
            raise SettingsError(f"pass '{name}': setting 'mode' must be one of "
                                f"{', '.join(MODES)}, got {p.mode!r}" + did_you_mean(p.mode, MODES))
        for field, lo, hi in (("spp", 1, 4096), ("max_bounces", 0, 64), ("rr_start", 0, 64)):
            value = getattr(p, field)
            if not lo <= value <= hi:
                raise SettingsError(f"pass '{name}': setting '{field}' must be in "
                                    f"{lo}..{hi}, got {value}")
        self._next = 0  # the next sample's index since the sums restarted
        self._camera = None

    def setup(self, ctx) -> None:
        """The scene tables, textures and samplers (what any hit reads) and the Sobol
        direction numbers."""
        self.tables = None
        if ctx.scene is None:
            return
        self.tables, self.defines = scene_table_bindings(ctx, self.name)
        if self.params.mode != "full":
            self.defines[f"MODE_{self.params.mode.upper()}"] = 1
        self.tables = {**self.tables,
                       "sobol_directions": ctx.buffer(f"{self.name}:sobol", sobol_directions())}

    def record(self, ctx) -> None:
        # the cameras and the instances' pose (animations move them) the sums are of
        camera = (ctx.scene.camera_blob, getattr(getattr(ctx.scene, "poses", None), "pose", 0))
        restart = ctx.frame == 0 or camera != self._camera
        if restart:
            self._next, self._camera = 0, camera
        frame = struct.pack("<2I", self._next, int(restart))
        self._next += self.params.spp
        self.trace(ctx, ctx.extent("hdr"), defines=self.defines, push_constants=frame,
                   tlas=ctx.accel("tlas"), t_sums_prev=ctx.sampled("sums_prev"),
                   t_half_prev=ctx.sampled("half_prev"), o_sums=ctx.storage("sums"),
                   o_half=ctx.storage("half"), o_hdr=ctx.storage("hdr"),
                   o_error=ctx.storage("error"), u_params=self.params, **self.tables)
