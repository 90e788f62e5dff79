"""Golden images: every config in configs/ at 192x108, on the courtyard and the tiny scene.

Each render is compared with ``tests/golden/<adapter>/<config>__<scene>.png``, where
``<adapter>`` names the device and driver (``golden_util.adapter_key``, for example
``llvmpipe-llvm15-256bit-mesa-25.0``), through ``golden_util.image_diff`` within
``golden_util.BOUNDS``: a FLIP bound, bounds on the pixels over 1 and over 2 levels and on
the mean absolute and signed differences. Lavapipe renders these bit for bit the same from
run to run on one machine, but llvmpipe compiles for the host CPU: on another processor a
few shadow-edge pixels move by up to 42 levels and a few hundred by 1 or 2. The bounds
accept every golden re-rendered on an AMD EPYC (``tests/data/golden-other-cpu/``) and reject
exposure +3 %, a one-pixel shift, a technique switched off and a pass skipped, for every
config (``test_golden_scheme.py``). A mismatch writes ``actual.png``, ``expected.png`` and
``diff.png`` (x16) under pytest's tmp path and names the folder.

On an adapter without goldens the configs still render, and the comparison fails under CI
(the ``CI`` environment variable) and skips elsewhere, naming the command that creates them.
Regenerate this adapter's goldens (the commit says why the pictures changed)::

    RFW_REGEN_GOLDEN=1 .venv/bin/python -m pytest tests/test_golden.py

(an environment variable rather than a ``--regen-golden`` option, which would have to be
added in tests/conftest.py). The comparisons between configs below hold on every adapter.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rfw.config import PassEntry, apply_overrides, build, load_config
from rfw.graph import GraphError, compile

from .conftest import ROOT
from .golden_util import check_golden

SIZE = (192, 108)
# the path tracer's references are judged by closed forms and by Mitsuba 3
# (tests/passes/test_pathtrace.py, tests/truth/), not by pixels: another CPU's float
# rounding sends a path another way, so its noise is not a golden's to keep
NOT_GOLDEN = {"pathtrace"}
CONFIGS = sorted(p.stem for p in (ROOT / "configs").glob("*.toml") if p.stem not in NOT_GOLDEN)
SCENES = ("courtyard", "tiny")


def config(name: str, *sets: str):
    return apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"),
                           [f"size={SIZE[0]}x{SIZE[1]}", *sets])


def rgb(images: dict[str, np.ndarray]) -> np.ndarray:
    (image,) = images.values()
    return image[..., :3].astype(int)


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("name", CONFIGS)
def test_golden(name, scene, renders, device, tmp_path):
    images = renders(config(name), scene)
    for out, image in images.items():
        golden = f"{name}__{scene}" + (f"__{out}" if len(images) > 1 else "")
        check_golden(image, golden, device, tmp_path / golden)


def test_forward_and_deferred_agree_on_the_courtyard(renders):
    # measured on lavapipe (llvmpipe-llvm15-256bit-mesa-25.0), 192x108: max 2 levels, 99.9th percentile of
    # the per-pixel max 2, 99th 1; 8240 pixels (40%) differ by 1 and 128 (0.6%) by 2; mean
    # |difference| 0.18, mean signed -0.04. The g-buffer's quantisation explains it, not the
    # interpolation: stored as rgba16float the albedo leaves 5 pixels at 2 and 1115 at 1, and
    # with albedo and material in rgba16float nothing is over 1 (976 pixels at 1), while fp32
    # normals change nothing. Half a step of 8-bit sRGB albedo (and 8-bit roughness and
    # metallic) moves the lit result by up to a level, and the two paths' outputs round
    # independently: 2 levels at most. A missing or doubled lighting term shows as a shifted
    # mean, which the last bound catches.
    fwd = rgb(renders(config("forward"), "courtyard"))
    dfr = rgb(renders(config("deferred"), "courtyard"))
    d = fwd - dfr
    per_pixel = np.abs(d).max(axis=-1)
    assert fwd.std() > 20  # a picture, not a flat field
    assert per_pixel.max() <= 2
    assert np.percentile(per_pixel, 99.9) <= 2
    assert np.abs(d).mean() < 0.5 and abs(d.mean()) < 0.25


def test_forward_prepass_matches_forward(renders):
    # both compare less-equal, so depth ties (two pixels on the courtyard at 192x108) resolve
    # to the last surface drawn with or without the prepass; with plain less in forward those
    # two pixels differ by up to 144 levels. Measured: identical, bit for bit.
    a = rgb(renders(config("forward"), "courtyard"))
    b = rgb(renders(config("forward_prepass"), "courtyard"))
    assert np.abs(a - b).max() <= 1


def deferred_prepass():
    """deferred.toml with a depth prepass feeding the g-buffer and the lighting pass."""
    cfg = config("deferred")
    passes = []
    for p in cfg.passes:
        if p.name == "gbuffer":
            passes.append(PassEntry("depth_prepass", "depth_prepass"))
            p = replace(p, inputs={"depth": "depth_prepass.depth"},
                        settings={**p.settings, "prepass": True})
        elif p.name in ("lighting", "points_lines"):
            p = replace(p, inputs={**p.inputs, "depth": "depth_prepass.depth"})
        passes.append(p)
    return replace(cfg, name="deferred_prepass", passes=passes)


def test_gbuffer_prepass_matches_deferred(renders):
    a = rgb(renders(config("deferred"), "courtyard"))
    b = rgb(renders(deferred_prepass(), "courtyard"))
    assert np.abs(a - b).max() <= 1


def test_prepass_setting_swaps_the_depth_output_for_an_input():
    built = build(config("forward_prepass"))
    assert built.slots["forward"]["depth"] == "depth_prepass.depth"
    plan = compile(built.graph)
    assert plan.order == ("depth_prepass", "forward", "points_lines", "tonemap")
    assert "forward.depth" not in {r.name for r in plan.resources}
    ins, outs = built.passes["forward"].declare()
    assert ins["depth"].read_only and "depth" not in outs
    gb = build(deferred_prepass()).passes["gbuffer"]
    ins, outs = gb.declare()
    assert ins["depth"].read_only and "depth" not in outs and "albedo" in outs


@pytest.mark.parametrize("sets, message", [
    # prepass on, nothing feeds the depth input
    (["depth_prepass.enabled=false"], r"input 'depth' reads 'depth_prepass.depth', whose "
                                      r"pass is disabled"),
    # prepass off, but the config still feeds a depth input the pass no longer declares
    (["forward.prepass=false"], r"no input slot 'depth'"),
])
def test_prepass_wiring_errors(sets, message):
    with pytest.raises(GraphError, match=message):
        build(apply_overrides(config("forward_prepass"), sets))
