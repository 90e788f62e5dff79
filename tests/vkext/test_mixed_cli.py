"""Mixed and vk-pinned frames through the real CLI: the counters a vk run reports (meshlet
culling, acceleration structures) whatever the run's backend, and depth crossing from vk into
wgpu (which cannot write depth textures from the host) as r32float for passes that sample it,
or one clear line for those that need a depth texture."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vkext import VkDevice, VkUnavailableError

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"


@pytest.fixture(scope="module", autouse=True)
def _needs_vulkan():
    try:
        VkDevice(label="rfw-tests-probe").destroy()
    except VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")


def rfw(tmp_path: Path, out: str, *args: str) -> tuple[subprocess.CompletedProcess, Path]:
    target = tmp_path / out
    done = warm_cli("run", *args, "--frames", "1", "--out", target, cwd=ROOT)
    return done, target


def image(folder: Path) -> np.ndarray:
    return np.asarray(Image.open(folder / "tonemap.ldr.png")).astype(np.int16)[..., :3]


def timings(folder: Path) -> dict:
    return json.loads((folder / "timings.json").read_text())


def test_meshlet_culling_counters_with_and_without_backend(tmp_path):
    # the passes are pinned to vk: without --backend the frame runs through rfw.mixed
    runs = {}
    for label, extra in (("plain", ()), ("vk", ("--backend", "vk"))):
        done, out = rfw(tmp_path, label, str(CONFIGS / "meshlet.toml"), "--size", "64x36",
                        *extra)
        assert done.returncode == 0, done.stderr
        runs[label] = timings(out)
    assert runs["plain"]["backend"] == runs["vk"]["backend"] == "vk"
    plain, vk = runs["plain"]["culling"], runs["vk"]["culling"]
    assert plain.keys() == vk.keys() and plain["meshlets_total"] > 0
    # the same scene and view: the same meshlets considered and drawn
    assert plain["meshlets_total"] == vk["meshlets_total"]
    assert plain["meshlets_drawn"] == vk["meshlets_drawn"]


def test_rt_primary_reports_its_structures_with_and_without_backend(tmp_path):
    # its passes need Vulkan: without --backend the frame runs through rfw.mixed too
    runs = {}
    for label, extra in (("plain", ()), ("vk", ("--backend", "vk"))):
        done, out = rfw(tmp_path, label, str(CONFIGS / "rt_primary.toml"), "--size", "64x36",
                        *extra)
        assert done.returncode == 0, done.stderr
        runs[label] = timings(out)
    assert runs["plain"]["backend"] == runs["vk"]["backend"] == "vk"
    plain, vk = runs["plain"]["accel"], runs["vk"]["accel"]
    assert plain["pass"] == vk["pass"] == "accel"
    assert plain["blas"] == vk["blas"] > 0 and plain["instances"] == vk["instances"] > 0


def test_readme_ray_pipeline_with_ssao_renders(tmp_path):
    # the README's example: every pass, ssao included, runs on Vulkan (no bridge)
    done, out = rfw(tmp_path, "rt", str(CONFIGS / "rt_shadows.toml"), "--backend", "vk",
                    "--set", "shadows=ray_pipeline", "--set", "ao=ssao", "--size", "64x36")
    assert done.returncode == 0, done.stderr
    t = timings(out)
    assert t["techniques"] == {"shadows": "ray_pipeline", "ao": "ssao"}
    assert t["backend"] == "vk" and not t.get("bridges")
    assert t["accel"]["pass"] == "accel" and t["accel"]["blas"] > 0
    assert image(out).std() > 10  # a picture, not a flat frame


def test_depth_bridged_into_wgpu_matches_wgpu(tmp_path):
    # ssao on wgpu reading vk's depth (as r32float) against ssao reading wgpu's own depth
    sets = ("--set", "shadows=shadow_map", "--size", "96x54")
    pinned = pinned_config(tmp_path, "rt_shadows.toml", {"ssao": "wgpu"})
    mixed, a = rfw(tmp_path, "mixed", str(pinned), "--backend", "vk",
                   "--set", "ao=ssao", *sets)
    assert mixed.returncode == 0, mixed.stderr
    assert "bridge.gbuffer.depth.vk-wgpu" in timings(a)["bridges"]
    alone, b = rfw(tmp_path, "wgpu", str(CONFIGS / "rt_shadows.toml"), "--backend", "wgpu",
                   "--set", "ao=ssao", *sets)
    assert alone.returncode == 0, alone.stderr
    # negative control: without ambient occlusion the image differs from either one
    off, c = rfw(tmp_path, "off", str(CONFIGS / "rt_shadows.toml"), "--backend", "wgpu",
                 "--set", "ssao.enabled=false", *sets)
    assert off.returncode == 0, off.stderr
    # measured on lavapipe: identical (max 0); without ao 2,844 pixels differ, by up to 14
    assert np.abs(image(a) - image(b)).max() <= 1
    assert (np.abs(image(c) - image(b)).max(axis=2) > 1).sum() > 100


def test_depth_sampled_as_a_float_texture_crosses_into_wgpu(tmp_path):
    # deferred_lighting's one GLSL source samples depth as a float texture, so the G-buffer
    # drawn on vk lights on wgpu from its depth carried as r32float (it was refused while
    # the WGSL twin declared texture_depth_2d)
    sets = ("--size", "96x54", "--set", "shadow.enabled=true")
    pinned = pinned_config(tmp_path, "deferred.toml", {"gbuffer": "vk"})
    mixed, a = rfw(tmp_path, "mixed", str(pinned), *sets)
    assert mixed.returncode == 0, mixed.stderr
    assert "bridge.gbuffer.depth.vk-wgpu" in timings(a)["bridges"]
    alone, b = rfw(tmp_path, "wgpu", str(CONFIGS / "deferred.toml"), *sets)
    assert alone.returncode == 0, alone.stderr
    # negative control: without the shadow map the image differs from either one
    off, c = rfw(tmp_path, "off", str(CONFIGS / "deferred.toml"), "--size", "96x54")
    assert off.returncode == 0, off.stderr
    # measured on lavapipe: identical (max 0); without shadows 2,340 of 5,184 pixels differ
    assert np.abs(image(a) - image(b)).max() <= 1
    assert (np.abs(image(c) - image(b)).max(axis=2) > 1).sum() > 100


def pinned_config(tmp_path: Path, source: str, pins: dict[str, str]) -> Path:
    text = (CONFIGS / source).read_text()
    for name, backend in pins.items():
        text = text.replace(f'name = "{name}"\n', f'name = "{name}"\nbackend = "{backend}"\n')
    path = tmp_path / source
    path.write_text(text)
    return path


@pytest.mark.parametrize("source, pins, words", [
    # forward tests against the prepass's depth as an attachment: r32float cannot serve
    ("forward_prepass.toml", {"depth_prepass": "vk"},
     ("pass 'forward'", "depth_prepass.depth", "depth32float", "pin 'forward' to vk")),
])
def test_depth_readers_that_need_depth_are_one_line(tmp_path, source, pins, words):
    config = pinned_config(tmp_path, source, pins)
    done, out = rfw(tmp_path, "out", str(config), "--size", "64x36")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not (out / "timings.json").exists()
