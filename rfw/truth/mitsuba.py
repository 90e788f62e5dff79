"""An rfw ``Scene`` rendered by Mitsuba 3: the independent check of rfw's path tracer.

Mitsuba runs on the CPU in its ``llvm_ad_rgb`` variant (Dr.Jit's LLVM backend, which needs a
libLLVM that ``scripts/setup-system.sh`` installs). ``scene_dict`` converts a scene under
rfw's conventions, ``render`` renders it to linear radiance, ``depth`` gives the distance to
the first hit through each pixel centre (for checking that the two cameras agree).

What maps (exactly, but for the metal's shadowing term, measured below; the agreement scenes,
``rfw.scene.agreement`` and the glTF file ``tests/data/agreement/still_life.gltf``, use only
this):

- **Lambert** (``metallic = 0``, ``specular = 0``): ``pbr.glsl``'s diffuse term is then
  base / pi, Mitsuba's ``diffuse`` BSDF.
- **Metals** (``metallic = 1``): GGX with alpha = roughness^2 and Schlick's Fresnel from
  f0 = base, which is Mitsuba's ``principled`` BSDF with ``metallic = 1`` (its dielectric,
  sheen and clearcoat lobes are then weightless). The one difference is the shadowing term:
  Mitsuba's is the separable Smith G1 * G1, pbr.glsl's the height-correlated one, so Mitsuba's
  lobe is never brighter and is darker toward grazing angles. Measured for copper
  (0.95, 0.64, 0.54) at roughness 0.4 by integrating both over the hemisphere
  (``tests/truth/test_mitsuba.py``), Mitsuba's directional albedo differs from rfw's by
  0.000 % at normal incidence, -0.002 % at 30 degrees, -0.01 % at 45, -0.06 % at 60, -0.23 %
  at 70 and -1.1 to -1.2 % at 80 (red to blue). ``roughconductor`` with a constant
  reflectance (no Schlick rise toward white) is -2.7 % off at 60 degrees and -15 % at 80 in
  the blue channel, so it is not used.
- **Lights** (``rfw/backends/scene_data.py``'s ``lights_bytes``): a directional light's
  irradiance is color * intensity on a surface facing it (Mitsuba's ``directional``, its
  ``direction`` the way the light travels, as rfw's is); a point light's radiant intensity is
  color * intensity with irradiance I / d^2 (Mitsuba's ``point``). A scene without lights gets
  rfw's ``DEFAULT_SUN``; only the first ``MAX_LIGHTS`` count, as in rfw.
- **The sky**: a ``constant`` emitter of radiance ``AMBIENT * sky``, seen by every ray after
  the first bounce. Camera rays that miss return 0, as rfw's (alpha 0, the tonemap paints
  the background): Mitsuba's ``hide_emitters``, which is exact per sample.
- **The camera**: Mitsuba's ``perspective`` sensor placed by the inverse of rfw's own view
  matrix (Mitsuba looks along +Z with +X to the left, rfw along -Z with +X to the right),
  ``fov_axis = "y"`` with rfw's ``yfov``, near and far as rfw's; a box filter of one pixel
  and Mitsuba's ``multijitter`` sampler, so the samples are uniform over the pixel, as rfw's
  jittered primary rays are (stratified, which lowers the noise, not the expectation).
- **Geometry**: every drawable instance is one world-space Mitsuba mesh (positions through
  the transform, normals through its inverse transpose, winding flipped for mirrored ones),
  with its vertex normals (smooth shading) and uvs.

- **Base colour textures**: a ``bitmap`` texture of the image's linear values (the sRGB
  curve taken off in float64 where the texture is sRGB, as the GPU's sRGB formats do before
  they filter) times the base colour factor, in Mitsuba's ``raw`` mode (no further
  conversion); ``nearest`` or ``bilinear`` from the texture's magnification filter, and its
  wrap mode. Mitsuba has no mipmaps, so this is exact where rfw's ray cones read the finest
  level (magnified textures: the glTF agreement scene's floor); a minified texture is
  filtered by rfw and point-sampled by Mitsuba, which agree in the mean over a pixel where
  rfw's mip levels keep the linear mean (``mip_chain`` averages sRGB textures in linear
  light, to the nearest byte).

What is approximate, each said in one warning line: other materials (``0 < metallic < 1``,
or a dielectric with ``specular > 0``) become ``principled`` with Mitsuba's ``specular =
0.5 * specular`` (its f0 is 0.08 * specular, rfw's 0.04 * specular) but Mitsuba's dielectric
Fresnel and Disney diffuse; the other textures (metallic-roughness, normal, occlusion,
emissive), a base colour texture's alpha and alpha modes are not converted, nor two wrap
modes (Mitsuba has one per texture: u's is used); spot
lights become Mitsuba's ``spot`` (its falloff is not rfw's smoothstep); a point light's range
is ignored (Mitsuba has no cut-off); points and lines are left out. Emissive materials get an
``area`` emitter of radiance ``emissive`` on their meshes; Mitsuba's ``hide_emitters`` would
hide such a surface together with the light it reflects, so a scene with one is rendered with
the sky visible and the sky's share of each pixel, its radiance times the share of camera
rays that miss (a second render's alpha), taken away: exact in expectation, not per sample.

Mitsuba's ``max_depth`` counts path segments, the camera's included: 1 is what the camera
sees of emitters, 2 adds direct light, -1 is unlimited (Russian roulette from depth 5, which
is unbiased).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..backends.scene_data import AMBIENT, DEFAULT_SUN, MAX_LIGHTS
from ..errors import RfwError, warn
from ..scene.model import Light, Material, Scene, Texture

VARIANT = "llvm_ad_rgb"
# samples per pixel in one Mitsuba pass: its wavefront holds width * height * this many lanes
SPP_PER_PASS = 64


def load_mitsuba() -> Any:
    """The ``mitsuba`` module with ``VARIANT`` set (once per process)."""
    try:
        import mitsuba as mi
    except ImportError as e:
        raise RfwError(f"rfw.truth.mitsuba needs the mitsuba package ({e}); pip install "
                       "-e '.[test]'") from None
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    return mi


def _rgb(value) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(v) for v in value[:3]]}


# Mitsuba's bitmap filters and wrap modes for rfw's (WebGPU's) sampler names
_FILTERS = {"nearest": "nearest", "linear": "bilinear"}
_WRAPS = {"repeat": "repeat", "mirror-repeat": "mirror", "clamp-to-edge": "clamp"}


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB curve taken off values in 0..1 (IEC 61966-2-1), in float64."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def texture_dict(texture: Texture, factor) -> dict[str, Any]:
    """Mitsuba's ``bitmap`` of ``texture``'s linear RGB times ``factor`` (module
    docstring)."""
    if texture.pixels is None:
        raise RfwError(f"rfw.truth.mitsuba: texture {texture.name!r} has no pixels (they go "
                       "once uploaded: Scene.keep_pixels); load the scene again")
    mi = load_mitsuba()
    rgb = texture.pixels[..., :3] / 255.0
    linear = (srgb_to_linear(rgb) if texture.srgb else rgb) * np.asarray(factor[:3])
    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(linear, np.float32)),
            "raw": True, "filter_type": _FILTERS[texture.mag_filter],
            "wrap_mode": _WRAPS[texture.address_u]}


def bsdf_dict(m: Material, textures: list[Texture] | tuple = ()) -> tuple[dict[str, Any], bool]:
    """Mitsuba's BSDF for ``m``, and whether it is one of the two that match rfw's model
    (Lambert exactly, metals but for the shadowing term: module docstring). ``textures``
    are the scene's, which ``m``'s base colour texture indexes (without them, factors
    only)."""
    base: dict[str, Any] = _rgb(m.base_color)
    if m.base_color_texture is not None and m.base_color_texture < len(textures):
        base = texture_dict(textures[m.base_color_texture], m.base_color)
    if m.metallic == 1.0:
        out = {"type": "principled", "base_color": base, "metallic": 1.0,
               "roughness": float(m.roughness)}
        exact = True
    elif m.metallic == 0.0 and m.specular == 0.0:
        out, exact = {"type": "diffuse", "reflectance": base}, True
    else:
        out = {"type": "principled", "base_color": base,
               "metallic": float(m.metallic), "roughness": float(m.roughness),
               "specular": 0.5 * float(m.specular)}
        exact = False
    if m.double_sided:
        out = {"type": "twosided", "bsdf": out}
    return out, exact


def light_dict(li: Light) -> dict[str, Any]:
    """Mitsuba's emitter for an rfw light (module docstring)."""
    power = [float(c) * float(li.intensity) for c in li.color]
    if li.kind == "directional":
        return {"type": "directional", "direction": [float(v) for v in li.direction],
                "irradiance": _rgb(power)}
    if li.kind == "point":
        return {"type": "point", "position": [float(v) for v in li.position],
                "intensity": _rgb(power)}
    mi = load_mitsuba()
    at = np.asarray(li.position, np.float64)
    return {"type": "spot", "intensity": _rgb(power),
            "cutoff_angle": math.degrees(li.outer_cone),
            "beam_width": math.degrees(li.inner_cone),
            "to_world": mi.ScalarTransform4f().look_at(
                origin=at.tolist(), target=(at + np.asarray(li.direction)).tolist(),
                up=_any_up(li.direction))}


def _any_up(direction) -> list[float]:
    d = np.asarray(direction, np.float64)
    return [0.0, 0.0, 1.0] if abs(d[1]) > 0.99 * np.linalg.norm(d) else [0.0, 1.0, 0.0]


def sensor_dict(scene: Scene, size: tuple[int, int], camera: int = 0, *,
                spp: int = 1, sampler: dict[str, Any] | None = None,
                alpha: bool = False) -> dict[str, Any]:
    """Mitsuba's ``perspective`` sensor for ``scene``'s camera ``camera`` (its default
    camera when it has none) at ``size`` = (width, height)."""
    mi = load_mitsuba()
    cam = scene.cameras[camera] if scene.cameras else scene.default_camera()
    # rfw's camera looks down -Z with +X right; Mitsuba's down +Z with +X left
    to_world = np.linalg.inv(cam.view().astype(np.float64)) @ np.diag([-1.0, 1.0, -1.0, 1.0])
    width, height = size
    return {"type": "perspective", "fov": math.degrees(cam.yfov), "fov_axis": "y",
            "near_clip": float(cam.znear), "far_clip": float(cam.zfar),
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "sampler": sampler or {"type": "multijitter", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgba" if alpha else "rgb",
                     "component_format": "float32"}}


def _meshes(scene: Scene, *, emitters: bool) -> tuple[dict[str, Any], list[str]]:
    """One world-space Mitsuba mesh per drawable instance, keyed ``mesh_K``, and the names
    of the materials that do not map exactly."""
    import drjit as dr

    mi = load_mitsuba()
    bsdfs: dict[int, Any] = {}
    approximate: list[str] = []
    out: dict[str, Any] = {}
    for k, inst in enumerate(scene.drawable().instances):
        mesh = scene.meshes[inst.mesh]
        if not mesh.triangle_count:
            continue
        material = scene.materials[mesh.material]
        if mesh.material not in bsdfs:
            d, exact = bsdf_dict(material, scene.textures)
            bsdfs[mesh.material] = mi.load_dict(d)
            if not exact:
                approximate.append(material.name)
        props = mi.Properties()
        props["bsdf"] = bsdfs[mesh.material]
        if emitters and any(c > 0.0 for c in material.emissive):
            props["emitter"] = mi.load_dict({"type": "area",
                                             "radiance": _rgb(material.emissive)})
        t = np.asarray(inst.transform, np.float64)
        p = mesh.positions @ t[:3, :3].T + t[:3, 3]
        n = mesh.normals @ np.linalg.inv(t[:3, :3])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        tri = mesh.indices.reshape(-1, 3)
        if np.linalg.det(t[:3, :3]) < 0.0:  # mirrored: keep the faces on the normals' side
            tri = tri[:, ::-1]
        m = mi.Mesh(f"{inst.name or 'instance'} {k}", len(p), len(tri), props,
                    has_vertex_normals=True, has_vertex_texcoords=True)
        params = mi.traverse(m)
        params["vertex_positions"] = dr.ravel(mi.Point3f(*_columns(p)))
        params["vertex_normals"] = dr.ravel(mi.Normal3f(*_columns(n)))
        params["vertex_texcoords"] = dr.ravel(mi.Point2f(*_columns(mesh.uvs)))
        params["faces"] = dr.ravel(mi.Vector3u(*(np.ascontiguousarray(tri[:, c], np.uint32)
                                                 for c in range(3))))
        params.update()
        out[f"mesh_{k}"] = m
    return out, approximate


def _columns(a: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(a[:, c], np.float32) for c in range(a.shape[1])]


def _emissive(scene: Scene) -> bool:
    return any(any(c > 0.0 for c in scene.materials[scene.meshes[i.mesh].material].emissive)
               for i in scene.instances)


def scene_dict(scene: Scene, size: tuple[int, int], *, camera: int = 0, sky: float = 1.0,
               max_depth: int = -1, spp: int = 1) -> dict[str, Any]:
    """``scene`` as a Mitsuba scene description (``mitsuba.load_dict`` takes it) under rfw's
    conventions (module docstring): meshes, BSDFs, lights, the sky (``AMBIENT * sky``) and
    camera ``camera`` at ``size`` = (width, height), with a ``path`` integrator of
    ``max_depth`` that hides what camera rays see of emitters. One warning line names what
    does not map exactly."""
    meshes, approximate = _meshes(scene, emitters=True)
    notes = []
    if approximate:
        notes.append(f"materials {', '.join(approximate)} are approximated by Mitsuba's "
                     "principled BSDF (exact: Lambert with specular 0, and metals)")
    used = {scene.meshes[i.mesh].material for i in scene.drawable().instances}
    if any(m.normal_texture is not None or m.metallic_roughness_texture is not None
           or m.occlusion_texture is not None or m.emissive_texture is not None
           or m.alpha_mode != "OPAQUE" for k, m in enumerate(scene.materials) if k in used):
        notes.append("textures other than base colour and alpha modes are not converted "
                     "(factors only, opaque)")
    based = [scene.textures[m.base_color_texture] for k, m in enumerate(scene.materials)
             if k in used and m.base_color_texture is not None]
    if any(t.address_u != t.address_v for t in based):
        notes.append("base colour textures wrap in v as in u (Mitsuba has one wrap mode)")
    lights = scene.lights[:MAX_LIGHTS] or [DEFAULT_SUN]
    if any(li.kind == "spot" for li in lights):
        notes.append("spot lights fall off as Mitsuba's spot, not rfw's smoothstep")
    if any(li.kind == "point" and li.range is not None for li in lights):
        notes.append("point lights' ranges are ignored (Mitsuba has no cut-off)")
    if scene.stroke_instances:
        notes.append("points and lines are left out")
    if notes:
        warn(f"rfw.truth.mitsuba: {scene.name}: {'; '.join(notes)}")
    out: dict[str, Any] = {"type": "scene",
                           "integrator": {"type": "path", "max_depth": int(max_depth),
                                          "hide_emitters": not _emissive(scene)},
                           "sensor": sensor_dict(scene, size, camera, spp=spp), **meshes}
    for k, li in enumerate(lights):
        out[f"light_{k}"] = light_dict(li)
    if sky > 0.0:
        out["sky"] = {"type": "constant", "radiance": _rgb([c * sky for c in AMBIENT])}
    return out


def _passes(mscene: Any, spp: int, seed: int, channels: int) -> np.ndarray:
    """The mean of ``spp`` samples per pixel, in passes of at most ``SPP_PER_PASS``, each
    with its own seed (``seed`` * 65,536 + the pass: seeds never share a pass)."""
    mi = load_mitsuba()
    if not 0 <= seed < 65_536:
        raise RfwError(f"rfw.truth.mitsuba: seed must be from 0 to 65,535, not {seed}")
    total = None
    done = 0
    for k in range(math.ceil(spp / SPP_PER_PASS)):
        n = min(SPP_PER_PASS, spp - done)
        img = np.array(mi.render(mscene, spp=n, seed=seed * 65_536 + k), np.float64)
        total = img[..., :channels] * n if total is None else total + img[..., :channels] * n
        done += n
    return total / spp


def render(scene: Scene, size: tuple[int, int], *, spp: int, seed: int = 0,
           max_depth: int = -1, sky: float = 1.0, camera: int = 0) -> np.ndarray:
    """Mitsuba's render of ``scene`` at ``size`` = (width, height): (H, W, 3) float32 linear
    radiance, row 0 at the top, 0 where camera rays miss everything (module docstring).

    ``spp`` samples per pixel, uniform over the pixel; the same ``seed`` (0 to 65,535) gives
    the same image, another seed an independent one."""
    if spp < 1:
        raise RfwError(f"rfw.truth.mitsuba: spp must be at least 1, not {spp}")
    mi = load_mitsuba()
    d = scene_dict(scene, size, camera=camera, sky=sky, max_depth=max_depth)
    image = _passes(mi.load_dict(d), spp, seed, 3)
    if not d["integrator"]["hide_emitters"] and "sky" in d:
        # the sky seen by camera rays, taken away: its radiance times the share that miss
        coverage = _coverage(scene, size, camera=camera, spp=spp, seed=seed)
        image -= np.asarray(d["sky"]["radiance"]["value"]) * (1.0 - coverage[..., None])
    return image.astype(np.float32)


def _coverage(scene: Scene, size: tuple[int, int], *, camera: int, spp: int,
              seed: int) -> np.ndarray:
    """The share of each pixel's camera rays that hit the scene (an independent render's
    alpha: without any emitter it is the hit mask, box-filtered)."""
    mi = load_mitsuba()
    meshes, _ = _meshes(scene, emitters=False)
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 1},
         "sensor": sensor_dict(scene, size, camera, spp=spp, alpha=True), **meshes}
    # the seed's other half, so the coverage's noise is independent of the image's
    return _passes(mi.load_dict(d), spp, 65_535 - seed, 4)[..., 3]


def depth(scene: Scene, size: tuple[int, int], *, camera: int = 0) -> np.ndarray:
    """(H, W) float32: the distance from the camera to the first hit of the ray through
    each pixel's centre, NaN where it misses; row 0 at the top. The same sensor and film as
    ``render``, sampled once per pixel at its centre (a stratified sampler, not jittered);
    the distance is taken to the hit's position, since Mitsuba's rays start on the near
    plane."""
    mi = load_mitsuba()
    meshes, _ = _meshes(scene, emitters=False)
    sampler = {"type": "stratified", "sample_count": 1, "jitter": False}
    d = {"type": "scene", "integrator": {"type": "aov", "aovs": "t:depth,p:position"},
         "sensor": sensor_dict(scene, size, camera, sampler=sampler), **meshes}
    img = np.array(mi.render(mi.load_dict(d), spp=1), np.float64)
    cam = scene.cameras[camera] if scene.cameras else scene.default_camera()
    dist = np.linalg.norm(img[..., -3:] - np.asarray(cam.position, np.float64), axis=-1)
    return np.where(img[..., -4] > 0.0, dist, np.nan).astype(np.float32)
