"""The reference path tracer against closed-form radiance: convex objects under a uniform
sky reflect the sky times their BRDF's directional albedo; a point light over a Lambert
plane gives rho / pi * I cos / d^2. Plus determinism, both tracing methods, accumulation
and its convergence estimate, the per-effect modes and the Sobol sampler."""

from __future__ import annotations

import numpy as np
import pytest
from pass_scenes import box, corner_scene, quad, ray_method, rotate_x, translate
from pathtrace_scenes import SKY, directional_albedo, sphere_cosines, sphere_scene

import rfw
from rfw.render import render
from rfw.scene.model import Camera, Instance, Light, Material, Scene


def trace(scene, size=48, frames=4, *sets, warmup=0) -> dict[str, np.ndarray]:
    cfg = rfw.load("configs/pathtrace.toml", *sets, size=(size, size))
    return render(cfg, scene=scene, backend="vk", frames=frames, warmup=warmup).images


def test_a_lambert_sphere_reflects_its_albedo_times_the_sky():
    out = trace(sphere_scene(Material("lambert", (0.5, 0.5, 0.5, 1), specular=0.0)), 48, 4,
                "pt.sky=10", "pt.spp=16")
    hdr, err = out["pt.hdr"], out["pt.error"]
    assert np.all(err[..., 3] == 64)  # 4 frames of 16 samples
    inside = hdr[..., 3] == 1
    assert 0.45 < inside.mean() < 0.65  # the sphere's disk; the rest is sky (alpha 0)
    assert np.all(hdr[~(hdr[..., 3] > 0)][:, :3] == 0)  # camera rays that miss: no radiance
    ratio = hdr[inside][:, :3] / (0.5 * SKY * 10)
    assert abs(ratio.mean() - 1) < 0.003, ratio.mean()
    assert np.percentile(np.abs(ratio - 1), 99) < 0.02
    # negative control: an albedo 5 % off is far outside that
    assert abs((hdr[inside][:, :3] / (0.525 * SKY * 10)).mean() - 1) > 0.04


@pytest.mark.parametrize("material", [Material("metal", (1, 1, 1, 1), metallic=1.0, roughness=0.5),
                                      Material("plastic", (0.6, 0.6, 0.6, 1), roughness=0.3)],
                         ids=lambda m: m.name)
def test_metal_and_plastic_spheres_reflect_their_brdfs_albedo(material):
    # GGX sampling, the lobe choice, the sky's NEE and their MIS weights all enter here
    out = trace(sphere_scene(material), 48, 8, "pt.sky=10", "pt.spp=16")
    mu = sphere_cosines(48)
    seen = (out["pt.hdr"][..., 3] == 1) & (mu > 0.2)
    got = out["pt.hdr"][seen][:, 0] / (SKY[0] * 10)
    base, metallic = material.base_color[0], material.metallic
    want = directional_albedo(mu[seen], base, metallic, material.roughness)
    assert abs((got / want).mean() - 1) < 0.005
    assert np.percentile(np.abs(got / want - 1), 95) < 0.03
    # negative control: the albedo of a roughness 0.2 higher is not what was traced
    other = directional_albedo(mu[seen], base, metallic, material.roughness + 0.2)
    assert abs((got / other).mean() - 1) > 0.015


def plane_under_a_point_light(intensity: float = 4.0) -> Scene:
    """A 20 x 20 Lambert plane (y = 0) seen from straight above, a point light 1.5 over it."""
    floor = rotate_x(-90.0)  # quad's +z normal turned to +y
    return Scene("plane", meshes=[quad(20, 20)],
                 materials=[Material("lambert", (0.8, 0.8, 0.8, 1), specular=0.0)],
                 instances=[Instance(0, floor)],
                 lights=[Light("point", (1, 1, 1), intensity, position=(0.5, 1.5, 0.0))],
                 cameras=[Camera((0, 4, 0), (0, 0, 0), up=(0, 0, -1), yfov=np.radians(60))])


def plane_points(size: int) -> np.ndarray:
    """Where each pixel centre of ``plane_under_a_point_light``'s camera meets y = 0."""
    cam = plane_under_a_point_light().cameras[0]
    inv = np.linalg.inv(cam.projection(1.0).astype(np.float64) @ cam.view())
    c = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(c, -c)
    far = np.stack([x, y, np.ones_like(x), np.ones_like(x)], -1) @ inv.T
    d = far[..., :3] / far[..., 3:] - np.array(cam.position)
    return np.array(cam.position) + d * (-cam.position[1] / d[..., 1:2])


def test_a_point_light_over_a_lambert_plane_gives_the_inverse_square_law():
    out = trace(plane_under_a_point_light(), 32, 4, "pt.spp=16")
    p = plane_points(32)
    to_light = np.array([0.5, 1.5, 0.0]) - p
    d2 = (to_light ** 2).sum(-1)
    cos = to_light[..., 1] / np.sqrt(d2)
    want = 0.8 / np.pi * 4.0 * cos / d2 + 0.8 * SKY[0]  # direct light and the open sky
    got = out["pt.hdr"][..., 0]
    # pixel footprints: the jittered mean and the centre differ by the curvature of the
    # falloff, most under the light
    assert np.percentile(np.abs(got / want - 1), 90) < 0.01
    assert abs((got / want).mean() - 1) < 0.01
    dimmer = trace(plane_under_a_point_light(3.6), 32, 4, "pt.spp=16")["pt.hdr"][..., 0]
    assert abs((dimmer / want).mean() - 1) > 0.05  # negative control: a light 10 % dimmer


def tiny_scene() -> Scene:
    """A red box on a slab under a sun and a point light, a blended and a masked material."""
    s = Scene("tiny", materials=[Material("grey", (0.8, 0.8, 0.8, 1), roughness=0.6),
                                 Material("red", (0.9, 0.1, 0.1, 1), metallic=0.3, roughness=0.3),
                                 Material("glass", (0.2, 0.4, 0.9, 0.4), alpha_mode="BLEND")])
    slab, cube, pane = box(10, 0.2, 10), box(1, 1, 1), quad(1.5, 1.5)
    cube.material, pane.material = 1, 2
    s.meshes = [slab, cube, pane]
    s.instances = [Instance(0, translate(0, -0.1, 0)), Instance(1, translate(0, 0.5, 0)),
                   Instance(2, translate(0.3, 0.8, 1.6))]
    s.lights = [Light("directional", (1, 0.95, 0.9), 2.0, direction=(0.6, -1.0, 0.4)),
                Light("point", (0.2, 0.5, 1.0), 20.0, position=(2, 1.5, 2))]
    s.cameras = [Camera((3, 2.5, 4), (0, 0.3, 0))]
    return s


def test_deterministic_for_a_seed_and_the_same_by_ray_query_and_by_pipeline():
    a = trace(tiny_scene(), 24, 2, "pt.spp=2", "pt.method=ray_pipeline")["pt.hdr"]
    # by ray query where the device has them (lavapipe; not NVIDIA's Hopper chips), else
    # the pipeline again: the same samples, hits and arithmetic either way
    b = trace(tiny_scene(), 24, 2, "pt.spp=2", f"pt.method={ray_method()}")["pt.hdr"]
    np.testing.assert_array_equal(a, b)
    c = trace(tiny_scene(), 24, 2, "pt.spp=2", "pt.seed=1")["pt.hdr"]
    assert np.mean(np.abs(c - a)) > 1e-4  # negative control: another seed, other samples
    assert np.all(np.isfinite(a))


def test_samples_accumulate_and_the_error_falls_as_one_over_root_n():
    # against a 16x-sample reference: 4x the samples halves the error (1 / sqrt(N))
    sc = tiny_scene()
    bounces = "pt.max_bounces=2"
    ref = trace(sc, 24, 8, "pt.spp=16", "pt.seed=7", bounces)["pt.hdr"][..., :3]
    few = trace(sc, 24, 1, "pt.spp=2", bounces)
    many = trace(sc, 24, 1, "pt.spp=8", bounces)
    assert np.all(few["pt.error"][..., 3] == 2) and np.all(many["pt.error"][..., 3] == 8)
    rmse = [np.sqrt(np.mean((r["pt.hdr"][..., :3] - ref) ** 2)) for r in (few, many)]
    assert 1.6 < rmse[0] / rmse[1] < 2.5, rmse
    # the convergence estimate follows the true error, and falls the same way
    est = [np.sqrt(np.mean(r["pt.error"][..., :3] ** 2)) for r in (few, many)]
    assert 1.4 < est[0] / est[1] < 2.8, est
    assert 0.3 < est[1] / rmse[1] < 3.0
    # negative control: two runs of the same count (another seed) are not 2x apart
    other = trace(sc, 24, 1, "pt.spp=2", "pt.seed=3", bounces)["pt.hdr"][..., :3]
    assert np.sqrt(np.mean((other - ref) ** 2)) / rmse[0] < 1.3
    # frames add samples: 4 frames of 2 are 8
    frames = trace(sc, 24, 4, "pt.spp=2", bounces)
    assert np.all(frames["pt.error"][..., 3] == 8)


def test_ao_mode_is_open_on_a_plane_and_closes_in_a_crease():
    wall = Scene("wall", meshes=[quad(40, 40)], materials=[Material()],
                 instances=[Instance(0, np.identity(4, np.float32))],
                 cameras=[Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0))])
    ao = trace(wall, 32, 2, "pt.mode=ao", "pt.spp=8")["pt.hdr"]
    assert np.all(ao[..., 0] == 1) and np.all(ao[..., 3] == 1)
    crease = trace(corner_scene(), 32, 2, "pt.mode=ao", "pt.spp=16")["pt.hdr"][..., 0]
    assert crease.min() < 0.7 and np.median(crease) > 0.8
    near = trace(corner_scene(), 32, 2, "pt.mode=ao", "pt.spp=16",
                 "pt.ao_radius=0.05")["pt.hdr"][..., 0]
    assert near.mean() > crease.mean()  # a shorter radius: less occluded


def test_visibility_mode_sees_the_box_shadow():
    vis = trace(tiny_scene(), 40, 2, "pt.mode=visibility", "pt.spp=8")["pt.hdr"]
    v = vis[..., 0][vis[..., 3] == 1]
    assert (v == 0).mean() > 0.005 and (v == 1).mean() > 0.5  # the box's shadow, and sun
    assert 0 < ((v > 0) & (v < 1)).mean() < 0.1  # penumbra pixels: the shadow's edges
    point = trace(tiny_scene(), 40, 2, "pt.mode=visibility", "pt.spp=8",
                  "pt.light=1")["pt.hdr"][..., 0]
    assert np.mean(np.abs(point - vis[..., 0])) > 0.01  # another light, another shadow


def test_bad_settings_are_one_line():
    for bad, says in (("pt.mode=everything", "must be one of full, ao, visibility"),
                      ("pt.spp=0", "'spp' must be in 1..4096")):
        with pytest.raises(rfw.RfwError, match=says):
            trace(tiny_scene(), 8, 1, bad)


def test_sobol_directions_give_stratified_points():
    from passes.pathtrace.pathtrace import sobol_directions

    v = sobol_directions().reshape(4, 32)

    def points(n: int) -> np.ndarray:
        out = np.zeros((n, 4), np.uint64)
        for i in range(n):
            for b in range(32):
                if (i >> b) & 1:
                    out[i] ^= v[:, b]
        return out.astype(np.float64) / 2 ** 32

    p = points(256)
    for d in range(4):  # every dimension: one point in each 1/256 interval
        assert len(np.unique(np.floor(p[:, d] * 256))) == 256
    for k in range(9):  # dimensions 1 and 2: a (0, 2)-sequence, every elementary interval
        cells = np.floor(p[:, 0] * 2 ** k) * 2 ** (8 - k) + np.floor(p[:, 1] * 2 ** (8 - k))
        assert len(np.unique(cells)) == 256
    # negative control: the elementary-interval check fails for pseudo-random points
    r = np.random.default_rng(0).random((256, 2))
    assert len(np.unique(np.floor(r[:, 0] * 16) * 16 + np.floor(r[:, 1] * 16))) < 256


def test_the_sums_restart_when_the_camera_moves():
    # an orbit moves the camera every frame: every frame starts again from its own samples
    moving = trace(tiny_scene(), 16, 3, "pt.spp=2", "camera.path=orbit")
    assert np.all(moving["pt.error"][..., 3] == 2)
    still = trace(tiny_scene(), 16, 3, "pt.spp=2")  # negative control: a static camera sums
    assert np.all(still["pt.error"][..., 3] == 6)
