"""Every config in ``configs/`` on both backends, through the real CLI: one GLSL source (one
SPIR-V for comp, vert and frag) gives the same image with ``--backend wgpu`` and
``--backend vk``; starting from an empty SPIR-V cache, the vk run compiles nothing the wgpu
run did not.

A config whose passes need Vulkan (mesh shaders, acceleration structures, ray tracing) is
listed in ``VK_ONLY``: its passes are pinned to vk, so ``--backend wgpu`` leaves them there;
pinned to wgpu instead, the run is refused with one line naming the pass and what wgpu lacks.
Every config is in exactly one list, so a new one fails here until it is placed.

How close the backends are, measured on lavapipe (Mesa 25.0, LLVM 15) at 64x36 with the
default scene: identical, bit for bit, for every portable config (``IDENTICAL``); the test
keeps that bar where it holds and falls back to ``golden_util.assert_similar`` elsewhere.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from .cli.warm import warm_cli
from .golden_util import assert_similar, changed_share, mismatch, read_png

ROOT = Path(__file__).resolve().parents[1]
SIZE = "64x36"

# config -> --set values for both runs: rt_shadows picks its raster techniques, the ones
# both backends have (auto would trace rays on vk and rasterise on wgpu)
PORTABLE = {
    "deferred": ["shadow.enabled=true"],
    "deferred_mixed": [],  # pins passes to both backends: each run is a mixed frame
    "deferred_ssao_shadows": [],
    "flat": [],
    "forward": ["shadow.enabled=true"],
    "forward_prepass": [],
    "rt_shadows": ["shadows=shadow_map", "ao=ssao"],
}
# configs whose images were identical on lavapipe (every portable one)
IDENTICAL = set(PORTABLE)
# config -> the pass a wgpu run refuses first, and the capability wgpu lacks
VK_ONLY = {
    "deferred_meshlet": ("cull", "VK_EXT_mesh_shader"),
    "deferred_vis": ("vis", "geometry_shader"),
    "meshlet": ("cull", "VK_EXT_mesh_shader"),
    "pathtrace": ("accel", "VK_KHR_acceleration_structure"),
    "rt_primary": ("accel", "VK_KHR_acceleration_structure"),
}


def render(config: Path, backend: str, out: Path, sets: list[str],
           cache: Path | None = None) -> dict[str, np.ndarray]:
    """The config's output images, rendered by the CLI on ``backend`` (vk: under the
    validation layers with synchronization validation, where any message fails the run)."""
    args = ["run", str(config), "--backend", backend, "--size", SIZE, "--frames", "1",
            "--out", str(out), *(["--validate"] if backend == "vk" else [])]
    for s in sets:
        args += ["--set", s]
    done = warm_cli(*args, cwd=ROOT, env={"RFW_CACHE_SPIRV": str(cache)} if cache else None)
    assert done.returncode == 0, f"{config.name} on {backend}: {done.stdout}{done.stderr}"
    images = {p.name: read_png(p) for p in sorted(out.glob("*.png"))}
    assert images, f"{config.name} on {backend} wrote no image"
    return images


def test_every_config_is_placed():
    configs = {p.stem for p in (ROOT / "configs").glob("*.toml")}
    assert not set(PORTABLE) & set(VK_ONLY)
    assert configs == set(PORTABLE) | set(VK_ONLY), (
        f"place {sorted(configs - set(PORTABLE) - set(VK_ONLY))} in PORTABLE or VK_ONLY")


@pytest.mark.parametrize("name", sorted(PORTABLE))
def test_wgpu_and_vk_render_the_same(name, tmp_path):
    config = ROOT / "configs" / f"{name}.toml"
    cache = tmp_path / "spirv"  # a fresh SPIR-V cache: what each backend compiles shows
    wgpu = render(config, "wgpu", tmp_path / "wgpu", PORTABLE[name], cache)
    compiled = sorted(cache.iterdir())
    vk = render(config, "vk", tmp_path / "vk", PORTABLE[name], cache)
    # one SPIR-V for both: the vk run finds every module in the wgpu run's cache
    assert compiled and sorted(cache.iterdir()) == compiled
    assert wgpu.keys() == vk.keys()
    for image in wgpu:
        if name in IDENTICAL:
            diff = np.abs(wgpu[image].astype(int) - vk[image].astype(int))
            assert np.array_equal(wgpu[image], vk[image]), (
                f"{name} {image}: vk differs from wgpu in {int((diff.max(-1) > 0).sum())} "
                f"pixels (largest {diff.max()})")
        assert_similar(vk[image], wgpu[image], f"{name} {image}, vk against wgpu")


def test_comparison_rejects_another_picture(tmp_path):
    # negative control: 3 % more exposure on one backend is not the same picture
    config = ROOT / "configs" / "deferred.toml"
    wgpu = render(config, "wgpu", tmp_path / "wgpu", [])
    vk = render(config, "vk", tmp_path / "vk", ["tonemap.exposure=1.03"])
    assert changed_share(wgpu["tonemap.ldr.png"], vk["tonemap.ldr.png"]) > 0.01  # 5.2 %
    assert mismatch(vk["tonemap.ldr.png"], wgpu["tonemap.ldr.png"])


@pytest.mark.parametrize("name", sorted(VK_ONLY))
def test_vk_only_configs_run_on_vk_and_wgpu_refuses_them(name, tmp_path):
    render(ROOT / "configs" / f"{name}.toml", "vk", tmp_path / "vk", [])
    # the config with every pass pinned to wgpu: one line, exit 2, no traceback
    text = (ROOT / "configs" / f"{name}.toml").read_text()
    text = re.sub(r'^backend = "vk"\n', "", text, flags=re.M)
    text = text.replace("[[pass]]\n", '[[pass]]\nbackend = "wgpu"\n')
    config = tmp_path / f"{name}.toml"
    config.write_text(text)
    done = warm_cli("run", str(config), "--backend", "wgpu", "--size", SIZE, "--frames", "1",
                    "--out", str(tmp_path / "out"), cwd=tmp_path)
    pass_, cap = VK_ONLY[name]
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stdout + done.stderr
    assert lines[0].startswith(f"rfw: error: pass '{pass_}' (")
    assert f"needs {cap}, which the wgpu backend does not have" in lines[0]
    assert "Traceback" not in done.stderr
