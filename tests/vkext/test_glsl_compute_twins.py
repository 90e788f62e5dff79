"""GLSL twins of the compute passes ssao (and its blur), fxaa and debug_view: the WGSL's
bindings, workgroup sizes and uniform layouts, and on Vulkan the image the wgpu backend
renders.

The interface checks reuse ``test_glsl_parity``'s (glslang and spirv-tools, no device). The
renders compare vk against wgpu with ``golden_util.assert_similar`` (the suite's one image
comparison), the vk image against this adapter's committed goldens, and run the config
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

from passes.debug_view.debug_view import DebugViewPass
from passes.fxaa.fxaa import FXAAPass
from passes.ssao.ssao import SSAOPass
from rfw.config import apply_overrides, load_config
from rfw.render import render
from vkext.backend import render_vk

from ..conftest import tiny_scene
from ..golden_util import assert_similar, check_golden, mismatch, read_png
from . import test_glsl_parity as parity

ROOT = Path(__file__).resolve().parents[2]
CONFIG = "deferred_ssao_shadows"


class SSAOBlur(SSAOPass):
    """ssao's second dispatch, as the parity helpers see a pass: its shader and Params."""

    __module__ = SSAOPass.__module__  # the helpers find the shader by the pass's folder
    shader = "ssao_blur.comp.wgsl"


# every define combination the passes' record() can ask for
VARIANTS = {
    SSAOPass: [{}, {"DEPTH_TEXTURE": 1}],
    SSAOBlur: [{}, {"DEPTH_TEXTURE": 1}],
    FXAAPass: [{}],
    DebugViewPass: [{"MODE": 0}, {"MODE": 0, "SRGB_SOURCE": 1}, {"MODE": 0, "DEPTH_SOURCE": 1},
                    {"MODE": 1}, {"MODE": 2, "LINEAR_DEPTH": 1},
                    {"MODE": 2, "LINEAR_DEPTH": 1, "DEPTH_SOURCE": 1}, {"MODE": 3},
                    {"MODE": 3, "DEPTH_SOURCE": 1}],
}
CASES = [pytest.param(cls, d, id=f"{cls.__name__}-{'+'.join(f'{k}{v}' for k, v in d.items())}")
         for cls, variants in VARIANTS.items() for d in variants]


@pytest.fixture(autouse=True)
def private_cache(private_spirv_cache):
    pass


def config(size: str, *sets: str):
    return apply_overrides(load_config(ROOT / "configs" / f"{CONFIG}.toml"),
                           [f"size={size}", *sets])


def vk_image(cfg, scene, vk_device) -> np.ndarray:
    (image,) = render_vk(cfg, scene=scene, device=vk_device).images.values()
    return image


def wgpu_image(cfg, scene, device) -> np.ndarray:
    (image,) = render(cfg, scene=scene, device=device).images.values()
    return image


# ---------------------------------------------------------------------------------------------
# the twins' interfaces are the WGSL's


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_bindings_match_wgsl(cls, defines, tmp_path):
    parity.test_bindings_match_wgsl(cls, defines, tmp_path)


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_workgroup_size(cls, defines, tmp_path):
    parity.test_stages_and_workgroup_size(cls, defines, tmp_path)


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_uniform_layouts_match_wgsl(cls, defines, tmp_path):
    parity.test_uniform_layouts_match_wgsl(cls, defines, tmp_path)


@pytest.mark.parametrize("cls", [SSAOPass, SSAOBlur, FXAAPass])
def test_settings_pack_lands_on_glsl_offsets(cls, tmp_path):
    parity.test_settings_pack_lands_on_glsl_offsets(cls, tmp_path)


def test_debug_view_settings_pack_lands_on_glsl_offsets(tmp_path):
    # mode is a define, not a uniform: the block holds channel and range only
    data = DebugViewPass.Params(mode="heatmap", channel=2, range=(0.25, 1.75)).pack()
    mod = parity.compile_all(DebugViewPass, {"MODE": 3}, tmp_path)[0]
    flat = mod.dis.flatten(mod.dis.uniform_blocks()["u_params"])
    assert set(flat) == {"channel", "range"}
    assert struct.unpack_from("<i", data, flat["channel"][0]) == (2,)
    assert struct.unpack_from("<2f", data, flat["range"][0]) == (0.25, 1.75)


@pytest.mark.parametrize("cls", list(VARIANTS))
def test_variants_cover_every_define(cls):
    # ssao's #ifdefs live in its shared include
    includes = ("ssao_common.wgsl",) if cls in (SSAOPass, SSAOBlur) else ()
    parity.assert_variants_cover(cls, VARIANTS[cls], *includes)


# ---------------------------------------------------------------------------------------------
# vk renders what wgpu renders


# final: ssao, fxaa; view=ao: debug_view color mode on the ssao output; view=normals and
# view=depth: its other modes (depth from a depth format); the heatmap mode on the
# normals' x
VIEWS = {
    "final": (),
    "no-ao": ("ao=off",),
    "ao": ("view=ao",),
    "normals": ("view=normals",),
    "depth": ("view=depth",),
    "heatmap": ("view=normals", "debug.mode=heatmap", "debug.channel=0", "debug.range=-1.0,1.0"),
}


@pytest.mark.parametrize("view", list(VIEWS))
@pytest.mark.parametrize("scene", ["tiny", "courtyard"])
def test_matches_wgpu(view, scene, vk_device, device, courtyard):
    # measured on lavapipe: identical images (largest difference 0) in every case
    s = tiny_scene() if scene == "tiny" else courtyard
    cfg = config("96x54", *VIEWS[view])
    a, b = vk_image(cfg, s, vk_device), wgpu_image(cfg, s, device)
    # the ao views show ssao's half-resolution output as it is
    assert a.shape == b.shape == ((27, 48, 4) if "view=ao" in VIEWS[view] else (54, 96, 4))
    assert a[..., :3].std() > 5  # a picture, not a flat frame
    assert_similar(a, b, f"{CONFIG} view={view} on {scene}: vk against wgpu")


@pytest.mark.parametrize(("what", "sets", "plain"), [
    ("ssao off", ("ao=off",), ()),
    ("ssao intensity x2", ("ssao.intensity=2.0",), ()),
    ("ssao without blur", ("ssao.blur_radius=0",), ()),
    ("fxaa finds no edge", ("fxaa.edge_threshold_min=2.0",), ()),
    ("fxaa no subpixel", ("fxaa.subpixel=0.0",), ()),
    ("depth range", ("view=depth", "debug.range=0.0,0.3"), ("view=depth",)),
    ("heatmap channel", (*VIEWS["heatmap"], "debug.channel=1"), VIEWS["heatmap"]),
])
def test_negative_controls(what, sets, plain, vk_device, device, courtyard):
    # each change reaches the vk shaders and is rejected against wgpu's unchanged render
    a = vk_image(config("96x54", *sets), courtyard, vk_device)
    b = wgpu_image(config("96x54", *plain), courtyard, device)
    assert mismatch(a, b), f"{what}: vk not told apart from wgpu's unchanged render"


@pytest.mark.parametrize("scene", ["tiny", "courtyard"])
def test_vk_matches_committed_golden(scene, vk_device, device, courtyard, tmp_path):
    # the goldens are wgpu renders at 192x108 on this adapter (tests/test_golden.py)
    s = tiny_scene() if scene == "tiny" else courtyard
    image = vk_image(config("192x108"), s, vk_device)
    check_golden(image, f"{CONFIG}__{scene}", device, tmp_path / scene)


# ---------------------------------------------------------------------------------------------
# the real CLI


@pytest.mark.parametrize("view", ["final", "depth"])
def test_cli_runs_on_vk_under_validation(view, tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "rfw.cli", "run", f"configs/{CONFIG}.toml",
                          "--backend", "vk", "--validate", "--size", "96x54", "--frames", "1",
                          "--set", f"view={view}", "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    # --validate exits 1 on any validation message
    assert run.returncode == 0, run.stdout + run.stderr
    assert "validation: 0 message(s)" in run.stderr + run.stdout
    assert "Validation Error" not in run.stderr + run.stdout
    image = read_png(out / "fxaa.color.png")
    assert image.shape == (54, 96, 4) and image[..., :3].std() > 5
