"""The visibility-buffer G-buffer (``configs/deferred_vis.toml``: ``visbuffer`` then
``vis_resolve``) against the raster one (the same config with ``geometry=raster``: the
``gbuffer`` pass), on the courtyard at 192x108 on Vulkan under the validation layers.

Measured on lavapipe (Mesa 25.0.7, LLVM 15), courtyard, 192x108:
- depth and coverage: identical (the same vertex expression, the same alpha test);
- albedo: at most 3 levels of 8-bit sRGB off; 33 % of covered pixels 1 level, 1.5 % 2;
- normal: largest component difference 0.021, 99th percentile 0.011, 0.006 % over 0.02;
- material (occlusion, roughness, metallic): at most 2 levels, 0.08 % of pixels 2;
  emissive: identical;
- the final image: largest 6 levels, 0.67 % of pixels over 2 levels, FLIP mean 0.010,
  mean signed difference 0.06 levels.
On the tiny scene mirrored, with normal maps, an alpha-masked cube and an emissive slab
(``cutout_scene``): depth and coverage identical, normal, material and emissive identical,
albedo within 0.06 levels. The courtyard's differences are texture filtering: the raster
path's implicit lookups take llvmpipe's own per-quad derivatives and LOD, the resolve
explicit gradients (the same quad differences, computed on the triangle's plane). The bounds below sit about 2x above these;
the negative controls (the resolve given another material, instances moved by 2 cm, its
outputs shifted by one pixel, mirrored instances' tangents left unflipped; the final image
at 3 % more exposure, or with shadows) each exceed them.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, load_config
from rfw.render import render

from ..cli.warm import warm_cli
from ..golden_util import Bounds, mismatch, read_png

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "deferred_vis.toml"
SIZE = (192, 108)
NAMES = ("albedo", "normal", "material", "emissive")

# per G-buffer output: the largest difference, and the share of covered pixels over `step`
BOUNDS = {
    "albedo": {"largest": 5.0, "step": 1.5, "over": 0.03},  # 8-bit sRGB levels
    "normal": {"largest": 0.05, "step": 0.02, "over": 0.005},  # world-space components
    "material": {"largest": 4.0, "step": 1.5, "over": 0.01},  # 8-bit levels
    "emissive": {"largest": 0.01, "step": 0.005, "over": 0.005},  # linear radiance
}
# the final (tonemapped) image: golden_util's measures, looser than a golden's
FINAL = Bounds(flip_mean=0.02, over2_fraction=0.015, over1_fraction=0.08, mean_abs=0.35,
               mean_signed=0.15)


def gbuffer(device, scene, *sets: str) -> dict[str, np.ndarray]:
    """The G-buffer (by output name) and depth of deferred_vis with ``sets``; under
    ``"resources"`` the names of the graph's resources."""
    cfg = apply_overrides(load_config(CONFIG), [f"size={SIZE[0]}x{SIZE[1]}", *sets])
    raster = "geometry=raster" in sets
    source = {n: f"gbuffer.{n}" if raster else f"resolve.{n}" for n in NAMES}
    source["depth"] = "gbuffer.depth" if raster else "vis.depth"
    result = render(replace(cfg, outputs=list(source.values())), scene=scene,
                    device=device, backend="vk")
    out = {n: np.asarray(result.images[r]) for n, r in source.items()}
    out["resources"] = {r.name for r in result.frame.plan.resources}
    return out


def srgb_levels(linear: np.ndarray) -> np.ndarray:
    c = np.clip(linear.astype(np.float64), 0.0, 1.0)
    return 255.0 * np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def comparable(name: str, image: np.ndarray) -> np.ndarray:
    """An output's rgb on a common scale: albedo in 8-bit sRGB levels (the raster path
    stores those, the resolve the linear value they decode to), unorm in levels."""
    rgb = image[..., :3]
    if name == "albedo" and image.dtype != np.uint8:
        return srgb_levels(rgb)
    return rgb.astype(np.float64)


def differences(vis: dict, ras: dict) -> list[str]:
    """Where the visibility-buffer G-buffer leaves the raster one's bounds; [] if nowhere."""
    out = []
    if not np.array_equal(vis["depth"], ras["depth"]):
        out.append("depth differs")
    covered = ras["albedo"][..., 3] > 0
    if not np.array_equal(vis["albedo"][..., 3] > 0, covered):
        out.append("coverage differs")
    for name in NAMES:
        d = np.abs(comparable(name, vis[name]) - comparable(name, ras[name])).max(-1)
        b, on = BOUNDS[name], d[covered]
        over = float((on > b["step"]).mean()) if on.size else 0.0
        if d.max() > b["largest"] or over > b["over"]:
            out.append(f"{name}: largest {d.max():.4g} (bound {b['largest']}), "
                       f"{over:.2%} over {b['step']} (bound {b['over']:.1%})")
    return out


@pytest.fixture(scope="module")
def raster(vk_device, courtyard):
    return gbuffer(vk_device, courtyard, "geometry=raster")


def test_resolve_matches_the_raster_gbuffer(vk_device, courtyard, raster):
    vis = gbuffer(vk_device, courtyard)
    assert raster["albedo"][..., 3].mean() > 0.3 and raster["normal"][..., :3].std() > 0.1
    assert vis["albedo"].dtype == np.float16 and raster["albedo"].dtype == np.uint8
    assert differences(vis, raster) == []
    # negative control: the resolve's outputs one pixel off
    shifted = {n: np.roll(v, 1, axis=1) if n in NAMES else v for n, v in vis.items()}
    assert any(n in why for why in differences(shifted, raster) for n in NAMES)


def _tables_with(monkeypatch, change) -> None:
    import rfw.authoring as authoring

    tables = authoring.scene_tables

    def changed(vk_scene):
        t = tables(vk_scene)
        change(t)
        return t

    monkeypatch.setattr(authoring, "scene_tables", changed)  # what vis_resolve's setup binds


def _next_material(t) -> None:
    t["meshes"]["material"] = (t["meshes"]["material"] + 1) % len(t["materials"])


def _moved(t) -> None:
    # the model matrix's translation column (column-major rows of 16), by 2 cm in x
    t["instances"]["matrices"][:, 12] += 0.02


@pytest.mark.parametrize("change", [_next_material, _moved], ids=["material", "moved"])
def test_comparison_rejects_a_wrong_resolve(vk_device, courtyard, raster, monkeypatch, change):
    _tables_with(monkeypatch, change)
    why = differences(gbuffer(vk_device, courtyard), raster)
    assert why and not any("depth" in w or "coverage" in w for w in why), why


def cutout_scene():
    """The tiny scene mirrored through x = 0 (every instance: its triangles' corners swapped,
    its tangents' w flipped), a normal map on every surface, the cube alpha-masked by a
    checkerboard and the slab emissive: what the courtyard lacks."""
    from rfw.scene.model import Texture

    from ..test_mirrored import bumpy_scene, mirrored

    s = bumpy_scene()
    checker = np.zeros((8, 8, 4), np.uint8)
    checker[...] = (230, 200, 40, 255)
    checker[(np.add.outer(np.arange(8), np.arange(8)) % 2) == 1, 3] = 0
    s.textures.append(Texture("checker", checker, srgb=True, mag_filter="nearest"))
    cube = s.materials[s.meshes[1].material]
    cube.alpha_mode, cube.alpha_cutoff, cube.base_color_texture = "MASK", 0.5, 1
    s.materials[s.meshes[0].material].emissive = (0.2, 0.1, 0.05)
    return mirrored(s)


@pytest.fixture(scope="module")
def cutout_raster(vk_device):
    return gbuffer(vk_device, cutout_scene(), "geometry=raster")


def test_resolve_matches_with_alpha_masks_mirrors_and_normal_maps(vk_device, cutout_raster):
    vis = gbuffer(vk_device, cutout_scene())
    cut = cutout_raster["albedo"][..., 3] == 0
    assert 0.05 < cut.mean() < 0.95  # background and cut-out pixels, and covered ones
    assert cutout_raster["emissive"][..., :3].max() > 0.1
    assert differences(vis, cutout_raster) == []


def test_comparison_rejects_an_unmirrored_tangent_frame(vk_device, cutout_raster, monkeypatch):
    def unmirrored(t):
        t["instances"]["mesh"][:, 1] = 0

    _tables_with(monkeypatch, unmirrored)
    why = differences(gbuffer(vk_device, cutout_scene()), cutout_raster)
    assert why and all(w.startswith("normal") for w in why), why


@pytest.mark.parametrize("scene", ["courtyard", "cutout"])
def test_atomic_write_gives_the_same_gbuffer(vk_device, courtyard, scene):
    # vis_write=atomic: no color attachment, (depth, ~id) kept by 64-bit atomic min in a
    # buffer vis_clear filled; the same surface wins every pixel, ties included
    sc = courtyard if scene == "courtyard" else cutout_scene()
    attachment = gbuffer(vk_device, sc)
    atomic = gbuffer(vk_device, sc, "vis_write=atomic")
    assert "vis.ids" in attachment["resources"] and "clear.ids" not in attachment["resources"]
    assert "clear.ids" in atomic["resources"] and "vis.ids" not in atomic["resources"]
    for name in (*NAMES, "depth"):
        assert np.array_equal(atomic[name], attachment[name]), name


def final_image(tmp_path: Path, label: str, *sets: str) -> np.ndarray:
    """deferred_vis's image through the CLI, on vk under validation (a message fails)."""
    args = ["run", str(CONFIG), "--backend", "vk", "--validate", "--size",
            f"{SIZE[0]}x{SIZE[1]}", "--frames", "1", "--out", str(tmp_path / label)]
    for s in sets:
        args += ["--set", s]
    done = warm_cli(*args, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    return read_png(tmp_path / label / "tonemap.ldr.png")


def test_final_image_matches_the_raster_path(tmp_path):
    vis = final_image(tmp_path, "vis")
    ras = final_image(tmp_path, "raster", "geometry=raster")
    assert vis[..., :3].std() > 10
    assert mismatch(vis, ras, FINAL) == ""
    # negative controls: 3 % more exposure, and the sun's shadow, each fail
    for label, s in (("exposure", "tonemap.exposure=1.03"), ("shadow", "shadow.enabled=true")):
        assert mismatch(final_image(tmp_path, label, s), ras, FINAL), label


def test_wgpu_refuses_the_visibility_buffer_in_one_line(tmp_path):
    text = CONFIG.read_text().replace('backend = "vk"', 'backend = "wgpu"')
    config = tmp_path / "deferred_vis.toml"
    config.write_text(text)
    done = warm_cli("run", str(config), "--backend", "wgpu", "--size", "64x36", "--frames", "1",
                    "--out", str(tmp_path / "out"), cwd=ROOT)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stdout + done.stderr
    assert lines[0].startswith("rfw: error: pass 'vis' (visbuffer) needs geometry_shader")


def test_ids_hold_instance_and_triangle_in_32_bits():
    from types import SimpleNamespace as NS

    from rfw.authoring import triangle_bits
    from rfw.errors import RfwError

    def scene(instances: int, triangles: int):
        return NS(instances=[None] * instances, meshes=[NS(indices=np.zeros(3 * triangles))])

    assert triangle_bits(scene(405, 2304)) == 23  # the courtyard: 9 bits of instance
    assert triangle_bits(scene(1, 10)) == 31
    assert triangle_bits(scene(1 << 16, 1 << 16)) == 16  # exactly full
    with pytest.raises(RfwError, match="do not fit the visibility buffer's 32-bit ids"):
        triangle_bits(scene((1 << 16) + 1, 1 << 16))  # one more instance: 17 + 16 bits


@pytest.mark.parametrize("sets, message", [
    (("vis_write=atomic", "clear.max_pixels=100"),
     "pass 'clear': 64x36 is more than the visibility buffer's max_pixels (100)"),
    (("vis.write=bogus",), "pass 'vis': setting 'write' must be one of attachment, atomic"),
    (("resolve.ids=bogus",), "pass 'resolve': setting 'ids' must be image or buffer"),
])
def test_bad_settings_fail_in_one_line(tmp_path, sets, message):
    args = ["run", str(CONFIG), "--backend", "vk", "--size", "64x36", "--frames", "1",
            "--out", str(tmp_path / "out")]
    for s in sets:
        args += ["--set", s]
    done = warm_cli(*args, cwd=ROOT)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stdout + done.stderr
    assert lines[0].startswith("rfw: error: ") and message in lines[0], lines[0]
