"""The stress scene: deterministic, found by name, and rendered alike on both backends.

The suite renders a few thousand instances through the deferred config, and the full
100,000 through the flat one (one draw per instance), at tiny sizes through the CLI;
benchmarks/bench_scene_load.py times loading, uploading and a frame of them."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from rfw.scene import SceneError, builtin_scene, load_scene, stress
from rfw.scene.stress import STRESS_INSTANCES, grid_transforms

from ..cli.warm import warm_cli
from ..golden_util import changed_share, read_png
from .test_courtyard import digest

ROOT = Path(__file__).resolve().parents[2]
COUNT = 3000  # enough for several draws per material and a far horizon, quick on lavapipe


def test_deterministic_and_counted():
    a, b = stress(500), load_scene("stress:500")
    assert digest(a) == digest(b)
    assert digest(stress(501)) != digest(a)
    assert a.name == "stress:500" and len(a.instances) == 500
    assert a.triangle_count == 500 * 12
    assert a.drawable() is a  # every transform is drawable, none warned about


def test_default_count_is_the_catalogue_entry():
    t = grid_transforms(STRESS_INSTANCES)
    assert t.shape == (100_000, 4, 4) and t.dtype == np.float32
    assert builtin_scene("stress").name == "stress"


def test_grid_cubes_do_not_touch():
    t = grid_transforms(2000).astype(np.float64)
    xz = t[:, [0, 2], 3]
    # a turned cube reaches at most scale * sqrt(2) / 2 from its centre on the ground
    reach = np.linalg.norm(t[:, :3, 0], axis=1) * np.sqrt(2) / 2
    order = np.lexsort((xz[:, 0], xz[:, 1]))
    pairs = list(itertools.pairwise(order))  # neighbours along each row

    def smallest_gap(r):
        return min(np.linalg.norm(xz[i] - xz[j]) - r[i] - r[j] for i, j in pairs)

    assert smallest_gap(reach) > 0
    assert smallest_gap(reach * 2.5) < 0  # negative control: bigger cubes would touch
    bottoms = t[:, 1, 3] - t[:, 1, 1] / 2
    assert np.allclose(bottoms, 0.0, atol=1e-6)  # every cube stands on the ground


def test_bad_counts_are_scene_errors():
    for name in ("stress:0", "stress:-3", "stress:x", "stress:1000001"):
        with pytest.raises(SceneError, match="instance count"):
            load_scene(name)
    with pytest.raises(SceneError, match="no built-in scene"):
        builtin_scene("stres")


def test_bad_count_through_the_cli_is_one_line(tmp_path):
    done = warm_cli("run", "configs/deferred.toml", "--scene", "stress:0", "--size", "32x24",
                    "--out", str(tmp_path), cwd=ROOT)
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0
    assert done.stderr.startswith("rfw: error: stress:0: scene: the instance count")


def _render(tmp_path: Path, backend: str, scene: str, *, config: str = "deferred",
            size: str = "96x64", output: str = "tonemap.ldr.png") -> np.ndarray:
    out = tmp_path / f"{backend}-{config}-{scene.replace(':', '_')}"
    done = warm_cli("run", f"configs/{config}.toml", "--backend", backend, "--scene", scene,
                    "--size", size, "--frames", "1", "--out", str(out), cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    return read_png(out / output)


def _cubes(image: np.ndarray, threshold: int = 60) -> np.ndarray:
    # pixels far from the background colour in the top-left corner
    sky = image[0, 0, :3].astype(int)
    return np.abs(image[..., :3].astype(int) - sky).sum(axis=-1) > threshold


def test_renders_alike_on_both_backends(tmp_path):
    vk = _render(tmp_path, "vk", f"stress:{COUNT}")
    wgpu = _render(tmp_path, "wgpu", f"stress:{COUNT}")
    assert np.array_equal(vk, wgpu)  # as every portable config on lavapipe
    # the cubes are there: pixels far from the sky colour in the corner, in four hues
    cubes = _cubes(vk)
    assert cubes.mean() > 0.2
    hues = {tuple(int(c) for c in np.argsort(p[:3])) for p in vk[cubes]}
    assert len(hues) >= 3
    # negative control: the comparison sees a different count of cubes (24 % of the pixels)
    fewer = _render(tmp_path, "vk", f"stress:{COUNT // 3}")
    assert changed_share(fewer, vk) > 0.05


def test_the_full_stress_scene_renders_alike_on_both_backends(tmp_path):
    # 100,000 draws of 1.2 million triangles, each instance's matrices read from one storage
    # buffer by the draw's first instance (vk once made a descriptor set per instance, past
    # lavapipe's map count; wgpu crashed in the first frame)
    flat = {"config": "flat", "size": "48x32", "output": "flat.color.png"}
    vk = _render(tmp_path, "vk", "stress", **flat)
    wgpu = _render(tmp_path, "wgpu", "stress", **flat)
    assert np.array_equal(vk, wgpu)
    # the grid fills the lower part of the view in several hues, out to the horizon
    cubes = _cubes(vk, threshold=30)
    assert cubes.mean() > 0.2
    assert cubes[: vk.shape[0] // 2].any()  # far rows above the middle of the image
    assert len({tuple(int(c) for c in np.argsort(p[:3])) for p in vk[cubes]}) >= 3
    # negative control: every instance drawn where the first one stands (what a draw that
    # ignored its first instance would show) is one cube, which the checks reject
    one = _render(tmp_path, "vk", "stress:1", **flat)
    assert _cubes(one, threshold=30).mean() < 0.2
