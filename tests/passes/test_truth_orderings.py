"""The path tracer as ground truth ranks what is known: more rt_ao samples and a matching
radius lower the AO error; a larger shadow map lowers the error of the sun's shadows, and
ray-traced shadows beat every shadow map. Errors are RMSE of linear values against the
pathtrace pass's per-effect reference at the same camera and size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pass_scenes import box, translate

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
            "pt": f"{ROOT}/configs/pathtrace.toml"}


def test_more_rt_ao_samples_and_the_matching_radius_lower_the_ao_error(configs):
    ref = images(configs["pt"], "pt.mode=ao", "pt.spp=32", "pt.ao_radius=1.0",
                 frames=4)["pt.hdr"]
    seen = ref[..., 3] == 1  # pixels wholly on the scene (rt_ao: 1 on the sky, truth 0)
    truth = ref[..., 0][seen]
    errors = {}
    for samples in (1, 4, 16):
        ao = images(configs["rt"], "ao=ray_query", f"rt_ao.samples={samples}",
                    "rt_ao.radius=1.0")["rt_ao.ao"][..., 0][seen].astype(np.float32)
        errors[samples] = rmse(ao, truth)
    assert errors[1] > errors[4] > errors[16], errors
    mismatched = images(configs["rt"], "ao=ray_query", "rt_ao.samples=16",
                        "rt_ao.radius=0.25")["rt_ao.ao"][..., 0][seen].astype(np.float32)
    assert rmse(mismatched, truth) > 1.5 * errors[16]  # the radius the truth was made with
    # negative control: the error measure does not rank two seeds of one count apart
    other = images(configs["pt"], "pt.mode=ao", "pt.spp=32", "pt.ao_radius=1.0", "pt.seed=5",
                   frames=4)["pt.hdr"][..., 0][seen]
    assert rmse(other, truth) < 0.5 * errors[16]


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
    traced = images(configs["shadows"], "shadows=ray_query", *flat)["lighting.hdr"]
    errors["rt"] = rmse(traced[lit][:, :3].astype(np.float32), truth[lit][:, :3])
    assert errors[64] > errors[256] > errors[1024] > errors["rt"], errors
    # negative control: the same ray-traced shadows with the sun's shadows turned off
    unshadowed = images(configs["shadows"], "shadows=shadow_map", "shadow.enabled=false",
                        *flat)["lighting.hdr"]
    assert rmse(unshadowed[lit][:, :3].astype(np.float32), truth[lit][:, :3]) > errors[64]
