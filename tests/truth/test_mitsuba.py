"""rfw.truth.mitsuba: Mitsuba 3 renders rfw's scenes under rfw's conventions. Its metal lobe
against pbr.glsl's (integrated here in numpy), its lights against closed forms, camera misses
and the sky, seeds, and its camera against rfw's raster on the vk backend, pixel for pixel."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rfw.config import load_config
from rfw.render import render as rfw_render
from rfw.scene import (
    Camera,
    Instance,
    Light,
    Material,
    Scene,
    Texture,
    cornell,
    load_scene,
    spheres,
)
from rfw.scene.agreement import METAL, _quads, lambert

mi = pytest.importorskip("mitsuba")
from rfw.truth import mitsuba as tm  # noqa: E402  (after the skip: it needs mitsuba)

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------------------------------------
# the metal lobe


def rfw_brdf_cos(base, roughness, wo, wi):
    """pbr.glsl's brdf() for a metal (metallic 1), normal +Z, times n.l: f0 = base, GGX of
    alpha = roughness^2, height-correlated Smith visibility, Schlick's Fresnel."""
    h = wo + wi
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    nol = np.clip(wi[..., 2], 0, 1)
    nov = np.clip(np.abs(wo[..., 2]), 1e-4, 1)
    noh, voh = np.clip(h[..., 2], 0, 1), np.clip(np.sum(wo * h, -1), 0, 1)
    a2 = roughness ** 4
    d = a2 / (np.pi * (noh * noh * (a2 - 1) + 1) ** 2)
    v = 0.5 / np.maximum(nol * np.sqrt(nov * nov * (1 - a2) + a2)
                         + nov * np.sqrt(nol * nol * (1 - a2) + a2), 1e-5)
    f = base + (1 - base) * (1 - voh)[..., None] ** 5
    return (d * v)[..., None] * f * nol[..., None]


def hemisphere(n_theta=1000, n_phi=240):
    """Midpoint quadrature of the upper hemisphere: directions and solid angles."""
    t = (np.arange(n_theta) + 0.5) / n_theta * np.pi / 2
    p = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    t, p = np.meshgrid(t, p, indexing="ij")
    w = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    return w, (np.sin(t) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)).ravel()


def mitsuba_albedo(bsdf_dict, wo, wi, dw):
    import drjit as dr

    bsdf = tm.load_mitsuba().load_dict(bsdf_dict)
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    si.wi = mi.Vector3f(*map(float, wo))
    v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(np.ascontiguousarray(wi[:, k], np.float32)
                                                      for k in range(3))))
    v = np.array(v)
    v = v.T if v.shape[0] == 3 else v
    return (v * dw[:, None]).sum(0)


def test_metal_albedo_matches_rfw_within_the_stated_bounds():
    """The docstring's numbers: principled (metallic 1) against pbr.glsl's metal, copper at
    roughness 0.4; roughconductor with a constant reflectance as the control that fails."""
    base = np.array(METAL.base_color[:3])
    wi, dw = hemisphere()
    chosen, _ = tm.bsdf_dict(METAL)
    control = {"type": "roughconductor", "material": "none", "distribution": "ggx",
               "alpha": METAL.roughness ** 2, "specular_reflectance": tm._rgb(base)}
    bounds = {0: 1e-4, 30: 3e-4, 60: 1e-3, 80: 1.5e-2}
    for deg, bound in bounds.items():
        th = math.radians(deg)
        wo = np.array([math.sin(th), 0.0, math.cos(th)])
        ref = (rfw_brdf_cos(base, METAL.roughness, np.broadcast_to(wo, wi.shape), wi)
               * dw[:, None]).sum(0)
        rel = mitsuba_albedo(chosen, wo, wi, dw) / ref - 1
        assert np.all(rel <= 1e-4) and np.abs(rel).max() < bound, (deg, rel)
        if deg >= 60:
            off = mitsuba_albedo(control, wo, wi, dw) / ref - 1
            assert np.abs(off).max() > 2.5e-2, (deg, off)
    assert chosen["type"] == "principled" and chosen["metallic"] == 1.0


def test_materials_map_exactly_or_say_so():
    assert tm.bsdf_dict(lambert("white", (0.5, 0.5, 0.5, 1)))[0]["type"] == "diffuse"
    assert tm.bsdf_dict(lambert("white", (0.5, 0.5, 0.5, 1)))[1]
    plastic, exact = tm.bsdf_dict(Material("plastic", metallic=0.0, specular=1.0))
    assert not exact and plastic["specular"] == 0.5  # f0 0.04 in both
    assert tm.bsdf_dict(replace(METAL, double_sided=True))[0]["type"] == "twosided"


# ---------------------------------------------------------------------------------------------
# lights, misses and the sky against closed forms


def wall_scene(material: Material, lights: list[Light]) -> Scene:
    """A 2 m square facing +Z at z = 0, seen head-on from z = 3 by a camera whose view it
    overfills at the centre and misses at the corners."""
    quad = _quads("wall", [((-1.0, -1.0, 0.0), (2.0, 0, 0), (0, 2.0, 0), (0, 0, 1))], 0)
    return Scene("wall", meshes=[quad], materials=[material],
                 instances=[Instance(0, np.identity(4, np.float32), "wall")], lights=lights,
                 cameras=[Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), yfov=math.radians(50.0))])


GREY = lambert("grey", (0.5, 0.25, 0.125, 1.0))


def test_directional_light_irradiance_and_direction():
    """Lambert under a directional light: base / pi * color * intensity * cos, exactly; a
    light travelling the other way (from behind the wall) gives nothing."""
    travel = np.array([0.0, -0.6, -0.8])  # into the wall's face: cos = 0.8
    lit = wall_scene(GREY, [Light("directional", (1.0, 0.5, 2.0), 3.0, direction=tuple(travel))])
    img = tm.render(lit, (16, 16), spp=4, sky=0.0, max_depth=2)
    want = np.array([0.5, 0.25, 0.125]) / np.pi * np.array([1.0, 0.5, 2.0]) * 3.0 * 0.8
    np.testing.assert_allclose(img[8, 8], want, rtol=1e-4)
    back = replace(lit, lights=[replace(lit.lights[0], direction=tuple(-travel))])
    assert np.abs(tm.render(back, (16, 16), spp=4, sky=0.0, max_depth=2)).max() == 0.0
    assert np.all(img[0, 0] == 0.0)  # the corner ray misses: black, not the (absent) sky


def test_point_light_inverse_square():
    """base / pi * I / d^2 * cos on the wall, the light 1.5 m in front of its centre,
    averaged over the centre pixel's footprint (cos / d^2 falls by 0.3 % across it)."""
    pl = wall_scene(GREY, [Light("point", (1.0, 1.0, 1.0), 6.0, position=(0.0, 0.0, 1.5))])
    img = tm.render(pl, (17, 17), spp=64, sky=0.0, max_depth=2)
    half = 3.0 * math.tan(math.radians(25.0)) / 17  # half a pixel on the wall, 3 m away
    x, y = np.meshgrid(*[np.linspace(-half, half, 201)] * 2)
    falloff = (1.5 / np.sqrt(x * x + y * y + 1.5 ** 2)) ** 3 / 1.5 ** 2  # cos / d^2
    want = np.array([0.5, 0.25, 0.125]) / np.pi * 6.0 * falloff.mean()
    np.testing.assert_allclose(img[8, 8], want, rtol=5e-4)


def test_sky_lights_bounces_but_not_camera_misses():
    """Without lights of its own (an unlit point light, so no default sun), a Lambert wall
    under the uniform sky reflects base * sky radiance; a camera miss stays 0, whatever
    the sky."""
    dark = wall_scene(GREY, [Light("point", intensity=0.0, position=(0.0, 0.0, 1.0))])
    img = tm.render(dark, (16, 16), spp=256, sky=2.0, max_depth=2, seed=3)
    want = np.array([0.5, 0.25, 0.125]) * 2.0 * np.array([0.03, 0.035, 0.045])
    np.testing.assert_allclose(img[6:10, 6:10].mean(axis=(0, 1)), want, rtol=0.03)
    assert np.all(img[0, 0] == 0.0) and np.all(img[15, 15] == 0.0)


def test_no_lights_gets_rfws_default_sun():
    d = tm.scene_dict(wall_scene(GREY, []), (8, 8))
    assert [k for k in d if k.startswith("light_")] == ["light_0"]
    assert d["light_0"]["type"] == "directional"
    np.testing.assert_allclose(d["light_0"]["irradiance"]["value"], [3.0, 2.91, 2.76])


def test_emissive_surfaces_stay_visible_and_misses_black():
    """An emissive wall is seen with its emission plus what it reflects; the sky behind the
    camera misses is taken away (exact where every ray misses)."""
    glow = replace(GREY, emissive=(2.0, 1.0, 0.5))
    s = wall_scene(glow, [Light("point", intensity=0.0, position=(0.0, 0.0, 1.0))])
    img = tm.render(s, (16, 16), spp=64, sky=1.0, max_depth=2, seed=1)
    want = np.array([2.0, 1.0, 0.5]) + np.array([0.5, 0.25, 0.125]) * np.array(
        [0.03, 0.035, 0.045])
    np.testing.assert_allclose(img[6:10, 6:10].mean(axis=(0, 1)), want, rtol=0.01)
    assert np.abs(img[0, 0]).max() < 1e-6


def test_seeds():
    box = cornell()
    a = tm.render(box, (24, 24), spp=2, seed=5)
    assert a.shape == (24, 24, 3) and a.dtype == np.float32
    assert np.array_equal(a, tm.render(box, (24, 24), spp=2, seed=5))
    assert not np.array_equal(a, tm.render(box, (24, 24), spp=2, seed=6))
    with pytest.raises(Exception, match="seed must be from 0 to 65,535"):
        tm.render(box, (8, 8), spp=1, seed=70_000)


def test_base_colour_texture_is_linear_upright_and_scaled():
    """A 2x2 sRGB texture (nearest) on the wall under a directional light: each quarter of
    the wall is base factor * the texel's linear value / pi * irradiance, the image's top
    row at the wall's top (the wall's uv v = 0 there, as glTF's), exactly; the texel
    bytes taken as linear, or the image upside down, would not match."""
    texels = np.array([[[200, 40, 10, 255], [30, 180, 60, 255]],
                       [[90, 90, 220, 255], [250, 250, 250, 255]]], np.uint8)
    factor = (0.8, 0.9, 0.7, 1.0)
    scene = replace(wall_scene(replace(GREY, base_color=factor, base_color_texture=0),
                               [Light("directional", (1.0, 1.0, 1.0), 2.0,
                                      direction=(0.0, 0.0, -1.0))]),
                    textures=[Texture("quarters", texels, srgb=True, mag_filter="nearest")])
    img = tm.render(scene, (16, 16), spp=4, sky=0.0, max_depth=2)
    linear = tm.srgb_to_linear(texels[..., :3] / 255.0) * np.array(factor[:3]) / np.pi * 2.0
    # the wall spans pixels 2.3 to 13.7 of 16: rows and columns 5 and 10 are well inside
    # its quarters
    for (row, col), (ty, tx) in {(5, 5): (0, 0), (5, 10): (0, 1), (10, 5): (1, 0),
                                 (10, 10): (1, 1)}.items():
        np.testing.assert_allclose(img[row, col], linear[ty, tx], rtol=1e-4)
    assert not np.allclose(img[5, 5], linear[1, 0], rtol=0.05)  # upside down
    raw = texels[0, 0, :3] / 255.0 * np.array(factor[:3]) / np.pi * 2.0
    assert not np.allclose(img[5, 5], raw, rtol=0.05)  # bytes taken as linear


# ---------------------------------------------------------------------------------------------
# the glTF agreement scene


STILL_LIFE = ROOT / "tests" / "data" / "agreement"


def still_life() -> Scene:
    return load_scene(STILL_LIFE / "still_life.gltf")


def test_the_still_life_files_are_what_the_script_writes(tmp_path):
    """tests/data/agreement is scripts/make_still_life.py's output: the same JSON and
    buffer bytes and the same texels."""
    import importlib.util

    from PIL import Image

    spec = importlib.util.spec_from_file_location("make_still_life",
                                                  ROOT / "scripts" / "make_still_life.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    written = make.write(tmp_path)
    assert sorted(p.name for p in written) == sorted(p.name for p in STILL_LIFE.iterdir())
    for name in ("still_life.gltf", "still_life.bin"):
        assert (tmp_path / name).read_bytes() == (STILL_LIFE / name).read_bytes(), name
    assert np.array_equal(np.asarray(Image.open(tmp_path / "checker.png")),
                          np.asarray(Image.open(STILL_LIFE / "checker.png")))


def test_the_still_life_converts_from_the_loaded_scene():
    """The loaded glTF converts as it loads: four instances (one box mesh placed twice),
    world-space meshes whose windings agree with their normals (the mirrored small box's
    flipped back), the floor's texture as a bitmap, the point and directional lights; the
    mirrored box's triangles left as they were would face inward."""
    import drjit as dr

    scene = still_life()
    d = tm.scene_dict(scene, (8, 8))
    meshes = [v for k, v in d.items() if k.startswith("mesh_")]
    assert len(meshes) == 4
    facing = {}
    for m in meshes:
        params = mi.traverse(m)
        p = np.array(dr.unravel(mi.Point3f, params["vertex_positions"])).T
        n = np.array(dr.unravel(mi.Normal3f, params["vertex_normals"])).T
        f = np.array(dr.unravel(mi.Vector3u, params["faces"])).T
        face = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        facing[m.id()] = np.sum(face * n[f].sum(axis=1), axis=1)
    assert all(np.all(v > 0) for v in facing.values()), {k: v.min() for k, v in facing.items()}
    small = next(i for i in scene.instances if i.name == "small box")
    assert np.linalg.det(small.transform[:3, :3]) < 0  # mirrored: the flip was needed
    mesh = scene.meshes[small.mesh]
    t = small.transform.astype(np.float64)
    p = mesh.positions @ t[:3, :3].T
    n = mesh.normals @ np.linalg.inv(t[:3, :3])
    tri = mesh.indices.reshape(-1, 3)
    unflipped = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    assert np.all(np.sum(unflipped * n[tri].sum(axis=1), axis=1) < 0)
    floor = scene.materials[0]
    bsdf, exact = tm.bsdf_dict(floor, scene.textures)
    assert exact and bsdf["reflectance"]["type"] == "bitmap"
    assert bsdf["reflectance"]["filter_type"] == "nearest"
    assert sorted(d[k]["type"] for k in d if k.startswith("light_")) == ["directional", "point"]


# ---------------------------------------------------------------------------------------------
# the camera against rfw's raster


def raster_distance(scene: Scene, size: tuple[int, int]) -> np.ndarray:
    """rfw's deferred config on vk: gbuffer.depth at each pixel centre turned back into the
    distance from the camera (through the inverse view-projection), NaN on the cleared
    background."""
    w, h = size
    cfg = replace(load_config(ROOT / "configs" / "deferred.toml"), scene=scene.name, size=size,
                  outputs=["gbuffer.depth"])
    z = rfw_render(cfg, scene=scene, backend="vk", frames=1, warmup=0).images[
        "gbuffer.depth"][..., 0].astype(np.float64)
    cam = scene.cameras[0]
    vp = cam.projection(w / h).astype(np.float64) @ cam.view().astype(np.float64)
    x = ((np.arange(w) + 0.5) / w) * 2 - 1
    y = 1 - ((np.arange(h) + 0.5) / h) * 2  # row 0 at the top
    x, y = np.meshgrid(x, y)
    p = np.stack([x, y, z, np.ones_like(z)], -1) @ np.linalg.inv(vp).T
    p = p[..., :3] / p[..., 3:]
    dist = np.linalg.norm(p - np.asarray(cam.position), axis=-1)
    return np.where(z < 1.0, dist, np.nan)


@pytest.mark.parametrize("make", [cornell, spheres, still_life])
def test_camera_agrees_with_rfws_raster(make):
    """The hit mask and the distance to the first hit through every pixel centre agree with
    rfw's raster (the still life's camera is a glTF node's, turned and tilted); the images
    flipped left-right or up-down (a sensor built the wrong way
    round) do not."""
    scene = make()
    size = (40, 30)
    ours, theirs = tm.depth(scene, size), raster_distance(scene, size)
    hit_ours, hit_theirs = np.isfinite(ours), np.isfinite(theirs)
    assert 0.1 < hit_ours.mean() < 0.95  # silhouettes against the background exist
    assert (hit_ours != hit_theirs).sum() <= 2  # a centre exactly on an edge may tie
    both = hit_ours & hit_theirs
    rel = np.abs(ours[both] / theirs[both] - 1)
    assert np.quantile(rel, 0.98) < 1e-3, np.quantile(rel, 0.98)
    for flipped in (ours[:, ::-1], ours[::-1]):
        hit = np.isfinite(flipped)
        same = hit & hit_theirs
        mismatch = (hit != hit_theirs).sum() + (np.abs(flipped[same] / theirs[same] - 1)
                                                > 1e-2).sum()
        assert mismatch > 40


# ---------------------------------------------------------------------------------------------
# benchmarks/mitsuba_check.py


def test_mitsuba_check_end_to_end(tmp_path, capsys):
    """The check runs on a stand-in (no path tracer config), caches its references, reads
    an rfw EXR when given one, and its negative control (a brighter light) stands out of
    the noise floor by its bias."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("mitsuba_check",
                                                  ROOT / "benchmarks" / "mitsuba_check.py")
    check = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(check)
    common = ["--scenes", "cornell", "--size", "24x16", "--spp", "8", "--out", str(tmp_path),
              "--rfw-config", str(tmp_path / "none.toml")]
    assert check.main(common) == 0
    first = capsys.readouterr().out
    assert "stand-in = floor: mitsuba seed 1" in first and "control: light +10%" in first
    lines = [json.loads(t) for t in (tmp_path / "mitsuba_check.jsonl").read_text().splitlines()]
    rows = {r["image"]: r for r in lines}
    floor, light = rows["stand-in = floor: mitsuba seed 1"], rows["control: light +10%"]
    assert light["rel_bias"] > floor["rel_bias"] + 0.05
    assert all(r["hdr_flip"] > 0 and r["spp"] == 8 for r in lines)
    (exr,) = (tmp_path / "mitsuba").glob("cornell-*.exr")
    assert check.main([*common, "--rfw", f"cornell={exr}", "--no-controls"]) == 0
    again = capsys.readouterr().out
    assert ": cached" in again
    last = json.loads((tmp_path / "mitsuba_check.jsonl").read_text().splitlines()[-1])
    assert last["image"] == f"rfw {exr}" and last["rel_mae"] == 0.0 and last["hdr_flip"] == 0.0
