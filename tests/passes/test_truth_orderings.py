"""The path tracer as ground truth ranks what is known: more rt_ao samples and a matching
radius lower the AO error; more SSAO samples and a radius grown toward the truth's lower
SSAO's; a larger shadow map lowers the error of the sun's shadows, and ray-traced shadows
beat every shadow map. Errors are RMSE of linear values against the pathtrace pass's
per-effect reference at the same camera and size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pass_scenes import box, ray_method, translate

import rfw
from rfw.render import render
from rfw.scene.model import Camera, Instance, Light, Material, Scene

ROOT = rfw.__file__.rsplit("/rfw/", 1)[0]
SIZE = 48


def sun_scene() -> Scene:
    """A slab, a box and a thin pole under a low sun: hard shadows with long, thin edges."""
    s = Scene("sun", materials=[Material("grey", (0.7, 0.7, 0.7, 1), roughness=0.8),
                                Material("white", (0.9, 0.9, 0.9, 1), roughness=0.5)])
    s.meshes = [box(8, 0.2, 8), box(1, 1, 1), box(0.08, 1.6, 0.08)]
    s.meshes[1].material = s.meshes[2].material = 1
    s.instances = [Instance(0, translate(0, -0.1, 0)), Instance(1, translate(-0.6, 0.5, 0)),
                   Instance(2, translate(1.0, 0.8, 0.4))]
    s.lights = [Light("directional", (1, 1, 1), 3.0, direction=(0.7, -0.55, 0.45))]
    s.cameras = [Camera((3.2, 3.0, 3.6), (0, 0.2, 0), yfov=np.radians(50))]
    return s


def with_outputs(tmp_path, config: str, outputs: list[str]) -> str:
    src = Path(f"{ROOT}/configs/{config}.toml").read_text()
    lines = [f"outputs = {outputs!r}".replace("'", '"') if line.startswith("outputs =") else line
             for line in src.splitlines()]
    path = tmp_path / f"{config}-{'-'.join(outputs)}.toml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def images(path: str, *sets: str, frames: int = 1) -> dict[str, np.ndarray]:
    cfg = rfw.load(path, *sets, size=(SIZE, SIZE))
    return render(cfg, scene=sun_scene(), backend="vk", frames=frames, warmup=0).images


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def configs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("truth")
    return {"rt": with_outputs(tmp, "rt_shadows", ["lighting.hdr", "rt_ao.ao"]),
            "shadows": with_outputs(tmp, "rt_shadows", ["lighting.hdr"]),
            "ssao": with_outputs(tmp, "deferred_ssao_shadows", ["ssao.ao"]),
            "pt": f"{ROOT}/configs/pathtrace.toml"}


@pytest.fixture(scope="module")
def ao_truth(configs):
    """The AO truth of radius 1 (pt.hdr: the open fraction in rgb, coverage in alpha), and
    the same at another seed."""
    sets = ("pt.mode=ao", "pt.spp=32", "pt.ao_radius=1.0")
    return (images(configs["pt"], *sets, frames=4)["pt.hdr"],
            images(configs["pt"], *sets, "pt.seed=5", frames=4)["pt.hdr"])


def test_more_rt_ao_samples_and_the_matching_radius_lower_the_ao_error(configs, ao_truth):
    ref, second = ao_truth
    seen = ref[..., 3] == 1  # pixels wholly on the scene (rt_ao: 1 on the sky, truth 0)
    truth = ref[..., 0][seen]
    errors = {}
    for samples in (1, 4, 16):
        ao = images(configs["rt"], f"ao={ray_method()}", f"rt_ao.samples={samples}",
                    "rt_ao.radius=1.0")["rt_ao.ao"][..., 0][seen].astype(np.float32)
        errors[samples] = rmse(ao, truth)
    assert errors[1] > errors[4] > errors[16], errors
    mismatched = images(configs["rt"], f"ao={ray_method()}", "rt_ao.samples=16",
                        "rt_ao.radius=0.25")["rt_ao.ao"][..., 0][seen].astype(np.float32)
    assert rmse(mismatched, truth) > 1.5 * errors[16]  # the radius the truth was made with
    # negative control: the error measure does not rank two seeds of one count apart
    assert rmse(second[..., 0][seen], truth) < 0.5 * errors[16]


def test_more_ssao_samples_and_a_radius_grown_toward_the_truths_lower_the_ao_error(
        configs, ao_truth):
    """SSAO against the AO truth, compared where SSAO looks: its half-resolution texels
    stand for the full-resolution pixel at their top-left (ssao_common.glsl), so the truth
    is read there; pixels on the scene only; every occluder of the sun scene is in view.
    SSAO is set to estimate the truth's quantity, the open fraction: power 1 (its default
    1.5 is a contrast curve), intensity 1.

    What holds, blur off (its depth-aware blur trades noise for bias): 1, 4 and 16 samples
    at the truth's radius lower the error (48x48 on lavapipe: RMSE 0.099, 0.067, 0.056; 64
    samples 0.052, where the bias dominates); at 16 samples a radius of 0.25, 0.5 and 1
    (the truth's) lowers it (0.082, 0.073, 0.056); at 4 samples the blur lowers it (0.059
    against 0.067), at 16 it does not (0.057 against 0.056: not asserted).

    What does not hold, so is not asserted: the truth's radius is not SSAO's best. SSAO
    tests points at 0.1 to 1 radius (a mean of 0.4), not rays that reach the radius, so it
    misses occluders the truth counts, and its error is least at 1.5 to 2 times the truth's
    radius (64 samples: 0.050 and 0.048 at 1.5 and 2, 0.052 at 1, 0.054 at 4).
    """
    ref, second = ao_truth
    seen = ref[::2, ::2, 3] == 1
    truth = ref[::2, ::2, 0][seen]

    def error(*sets: str) -> float:
        ao = images(configs["ssao"], "ssao.power=1", "ssao.intensity=1", *sets)["ssao.ao"]
        return rmse(ao[..., 0][seen].astype(np.float32), truth)

    samples = {n: error(f"ssao.samples={n}", "ssao.radius=1.0", "ssao.blur_radius=0")
               for n in (1, 4, 16)}
    assert samples[1] > samples[4] > samples[16], samples
    radii = {r: error("ssao.samples=16", f"ssao.radius={r}", "ssao.blur_radius=0")
             for r in (0.25, 0.5)}
    radii[1.0] = samples[16]
    assert radii[0.25] > radii[0.5] > 1.15 * radii[1.0], radii
    blurred = error("ssao.samples=4", "ssao.radius=1.0", "ssao.blur_radius=2")
    assert blurred < 0.95 * samples[4], (blurred, samples[4])
    # negative controls: the pixels compared hold occlusion SSAO finds (SSAO off, every
    # pixel open, is far worse), and two seeds of the truth are far nearer than SSAO
    assert error("ssao.intensity=0") > 1.4 * samples[16]
    assert rmse(second[::2, ::2, 0][seen], truth) < 0.5 * samples[16]


def test_larger_shadow_maps_lower_the_shadow_error_and_ray_tracing_beats_them(configs):
    # the sun's direct light alone (no sky, no ambient, no bounces) at pixel centres, where
    # the raster passes shade: a pixel's share of a shadow edge is anti-aliasing's question
    # (a filtered shadow map's soft edge comes nearer the footprint's mean than one ray)
    truth = images(configs["pt"], "pt.max_bounces=1", "pt.sky=0", "pt.spp=1",
                   "pt.jitter=false")["pt.hdr"]
    lit = truth[..., 3] == 1
    flat = ("lighting.ambient=0", "ao=ssao")
    errors = {}
    for res in (64, 256, 1024):
        hdr = images(configs["shadows"], "shadows=shadow_map", f"shadow.resolution={res}",
                     *flat)["lighting.hdr"]
        errors[res] = rmse(hdr[lit][:, :3].astype(np.float32), truth[lit][:, :3])
    traced = images(configs["shadows"], f"shadows={ray_method()}", *flat)["lighting.hdr"]
    errors["rt"] = rmse(traced[lit][:, :3].astype(np.float32), truth[lit][:, :3])
    assert errors[64] > errors[256] > errors[1024] > errors["rt"], errors
    # negative control: the same ray-traced shadows with the sun's shadows turned off
    unshadowed = images(configs["shadows"], "shadows=shadow_map", "shadow.enabled=false",
                        *flat)["lighting.hdr"]
    assert rmse(unshadowed[lit][:, :3].astype(np.float32), truth[lit][:, :3]) > errors[64]
