"""GLSL twins of the raster passes forward, depth_prepass and overdraw: the WGSL's bindings,
stage interfaces and uniform layouts, and on Vulkan the image the wgpu backend renders.

The interface checks reuse ``test_glsl_parity``'s (glslang and spirv-tools, no device). The
renders compare vk against wgpu with ``golden_util.assert_similar`` (the suite's one image
comparison), the vk image against this adapter's committed goldens, and run the configs
through the real CLI with ``--backend vk --validate``. Numbers measured on lavapipe (Mesa
25.0, LLVM 15) are stated where they are asserted.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from passes.depth_prepass.depth_prepass import DepthPrepassPass
from passes.forward.forward import ForwardPass
from passes.overdraw.overdraw import OverdrawPass
from rfw.config import apply_overrides, load_config
from rfw.render import render, to_png_array
from vkext.backend import render_vk

from ..conftest import tiny_scene
from ..golden_util import assert_similar, check_golden, mismatch, read_png
from . import test_glsl_parity as parity

ROOT = Path(__file__).resolve().parents[2]

# every define combination the passes' record() can ask for (forward: a shadow input or not)
VARIANTS = {
    ForwardPass: [{}, {"HAS_SHADOW": 1}],
    DepthPrepassPass: [{}],
    OverdrawPass: [{}],
}
CASES = [pytest.param(cls, d, id=f"{cls.__name__}-{'+'.join(d) or 'base'}")
         for cls, variants in VARIANTS.items() for d in variants]

# overdraw on its own: its count target is the output (the config's view=overdraw goes
# through debug_view too, tested below)
OVERDRAW_TOML = """\
name = "overdraw_only"
scene = "default"
size = [96, 54]
outputs = ["overdraw.count"]

[[pass]]
name = "overdraw"
"""


@pytest.fixture(autouse=True)
def private_cache(private_spirv_cache):
    pass


def config(name: str, size: str, *sets: str):
    return apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"),
                           [f"size={size}", *sets])


def both(cfg, scene, vk_device, device) -> tuple[np.ndarray, np.ndarray]:
    """(vk, wgpu) 8-bit images of ``cfg``'s single output."""
    vk = render_vk(cfg, scene=scene, device=vk_device)
    wg = render(cfg, scene=scene, device=device)
    (a,), (b,) = vk.images.values(), wg.images.values()
    return a, b


# ---------------------------------------------------------------------------------------------
# the twins' interfaces are the WGSL's


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_bindings_match_wgsl(cls, defines, tmp_path):
    parity.test_bindings_match_wgsl(cls, defines, tmp_path)


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_stages_interfaces_and_invariance(cls, defines, tmp_path):
    # depth_prepass has no fragment stage; forward and depth_prepass keep gl_Position
    # invariant, overdraw does not (as their WGSL)
    parity.test_stages_and_workgroup_size(cls, defines, tmp_path)


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_uniform_layouts_match_wgsl(cls, defines, tmp_path):
    parity.test_uniform_layouts_match_wgsl(cls, defines, tmp_path)


def test_forward_settings_pack_lands_on_glsl_offsets(tmp_path):
    # distinct values per field, read back at the offsets glslang gave the fragment stage's
    # block (parity's version reads the first stage; forward's u_params is fragment-only)
    values = {"shadow_bias": 0.25, "ambient": 1.25, "prepass": True}
    assert set(values) == set(ForwardPass.Params.fields())
    data = ForwardPass.Params(**values).pack()
    (mod,) = [m for m in parity.compile_all(ForwardPass, {}, tmp_path)
              if "u_params" in m.dis.uniform_blocks()]
    flat = mod.dis.flatten(mod.dis.uniform_blocks()["u_params"])
    assert set(flat) == set(values)
    for name, value in values.items():
        off, t = flat[name]
        fmt = {"f32": "<f", "u32": "<I"}[t]
        (got,) = struct.unpack_from(fmt, data, off)
        assert got == (int(value) if t == "u32" else value), f"{name} at offset {off}"


@pytest.mark.parametrize("cls", list(VARIANTS))
def test_variants_cover_every_define(cls):
    parity.assert_variants_cover(cls, VARIANTS[cls])


# ---------------------------------------------------------------------------------------------
# vk renders what wgpu renders


@pytest.mark.parametrize(("name", "sets"), [
    ("forward", ()),
    ("forward", ("shadow.enabled=true",)),
    ("forward_prepass", ()),
    ("forward_prepass", ("shadow.enabled=true",)),
], ids=["forward", "forward-shadow", "forward_prepass", "forward_prepass-shadow"])
@pytest.mark.parametrize("scene", ["tiny", "courtyard"])
def test_forward_configs_match_wgpu(name, sets, scene, vk_device, device, courtyard):
    s = tiny_scene() if scene == "tiny" else courtyard
    a, b = both(config(name, "96x54", *sets), s, vk_device, device)
    assert a.shape == b.shape == (54, 96, 4)
    assert a[..., :3].std() > 10  # lit geometry and sky, not a flat frame
    # measured on lavapipe: identical in all eight cases; compared like goldens
    # (golden_util.Bounds) for drivers whose two shader compilers round differently
    assert_similar(a, b, f"{name} {' '.join(sets)} on {scene}: vk against wgpu")


def test_forward_shadow_negative_control(vk_device, device, courtyard):
    # the comparison above can fail: the vk image with the sun's shadow is rejected against
    # the wgpu image without it (measured: 2338 of 5184 pixels over 2 levels, FLIP 0.52)
    lit, _ = both(config("forward", "96x54", "shadow.enabled=true"), courtyard, vk_device,
                  device)
    _, unlit = both(config("forward", "96x54"), courtyard, vk_device, device)
    assert mismatch(lit, unlit)


def test_forward_ambient_negative_control(vk_device, device):
    # the ambient setting reaches the vk uniform block: doubling it is rejected (measured:
    # 1857 of 5184 pixels over 2 levels, mean signed difference 1.70, FLIP 0.044)
    a, _ = both(config("forward", "96x54", "forward.ambient=2.0"), tiny_scene(), vk_device,
                device)
    _, b = both(config("forward", "96x54"), tiny_scene(), vk_device, device)
    assert mismatch(a, b)


@pytest.mark.parametrize("name", ["forward", "forward_prepass"])
@pytest.mark.parametrize("scene", ["tiny", "courtyard"])
def test_vk_matches_committed_golden(name, scene, vk_device, device, courtyard, tmp_path):
    # the goldens are wgpu renders at 192x108 on this adapter (tests/test_golden.py);
    # measured on lavapipe: the vk renders equal them bit for bit, all four
    s = tiny_scene() if scene == "tiny" else courtyard
    image = render_vk(config(name, "192x108"), scene=s, device=vk_device).images["tonemap.ldr"]
    check_golden(image, f"{name}__{scene}", device, tmp_path / name)


def counts_png(count: np.ndarray) -> np.ndarray:
    """Overdraw counts as 8-bit levels, 64 fragments to white."""
    return to_png_array(count / 64, "rgba16float")


def overdraw_config(tmp_path: Path, *sets: str):
    path = tmp_path / "overdraw_only.toml"
    path.write_text(OVERDRAW_TOML)
    return apply_overrides(load_config(path), list(sets))


@pytest.mark.parametrize("cull", ["back", "none", "front"])
def test_overdraw_counts_match_wgpu(cull, vk_device, device, courtyard, tmp_path):
    cfg = overdraw_config(tmp_path, f"overdraw.cull={cull}")
    vk = render_vk(cfg, scene=courtyard, device=vk_device).images["overdraw.count"]
    wg = render(cfg, scene=courtyard, device=device).images["overdraw.count"]
    a, b = np.asarray(vk, np.float32), np.asarray(wg, np.float32)
    assert a.shape == b.shape == (54, 96, 4)
    # whole numbers of fragments, several layers deep somewhere (measured: up to 16, 33
    # and 17 for back, none and front)
    assert np.array_equal(a, np.round(a)) and a.max() >= 3
    # measured on lavapipe: the same count in every pixel. as an image, counts / 64: one
    # fragment more is 4 levels, so a pixel off by one counts as an outlier
    assert_similar(counts_png(a), counts_png(b), f"overdraw cull={cull}: vk against wgpu")


def test_overdraw_cull_negative_control(vk_device, device, courtyard, tmp_path):
    # culling reaches the vk pipeline: no culling counts more than back-face culling, and
    # the comparison rejects one against the other
    back = render_vk(overdraw_config(tmp_path, "overdraw.cull=back"), scene=courtyard,
                     device=vk_device).images["overdraw.count"]
    none = render_vk(overdraw_config(tmp_path, "overdraw.cull=none"), scene=courtyard,
                     device=vk_device).images["overdraw.count"]
    back, none = np.asarray(back, np.float32), np.asarray(none, np.float32)
    assert (none >= back).all() and none.sum() > back.sum()
    # measured: 57472 fragments against 33808, 2455 of 5184 pixels over 2 levels
    assert mismatch(counts_png(none), counts_png(back))


def test_overdraw_view_of_deferred_ssao_shadows_matches_wgpu(vk_device, device, courtyard):
    # the config's view=overdraw variant: overdraw, then debug_view's heatmap and fxaa
    # (their twins are debug_view's and fxaa's); measured on lavapipe: identical
    cfg = config("deferred_ssao_shadows", "96x54", "view=overdraw")
    a, b = both(cfg, courtyard, vk_device, device)
    assert a.shape == b.shape == (54, 96, 4) and a[..., :3].std() > 10
    assert_similar(a, b, "deferred_ssao_shadows view=overdraw: vk against wgpu")
    # negative control: every triangle counted (cull none) is rejected against it (measured:
    # 2455 of 5184 pixels over 2 levels, FLIP 0.50)
    c = render_vk(config("deferred_ssao_shadows", "96x54", "view=overdraw",
                         "overdraw.cull=none"), scene=courtyard, device=vk_device)
    assert mismatch(c.images["fxaa.color"], b)


# ---------------------------------------------------------------------------------------------
# the real CLI


@pytest.mark.parametrize("name", ["forward", "forward_prepass"])
def test_cli_runs_on_vk_under_validation(name, tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "rfw.cli", "run", f"configs/{name}.toml",
                          "--backend", "vk", "--validate", "--size", "96x54",
                          "--set", "shadow.enabled=true", "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    # --validate exits 1 on any validation message
    assert run.returncode == 0, run.stdout + run.stderr
    assert "validation" not in run.stderr.lower(), run.stderr
    image = read_png(out / "tonemap.ldr.png")
    assert image.shape == (54, 96, 4) and image[..., :3].std() > 10
