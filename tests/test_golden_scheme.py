"""The golden comparison (``golden_util.image_diff`` within ``BOUNDS``) holds across
processors and still catches regressions.

- Accepts: every golden re-rendered on another CPU (``tests/data/golden-other-cpu/``, an AMD
  EPYC; the goldens they re-render come from an Intel Xeon) against the golden of the same
  name (``golden_of``: the committed one, or its Intel render kept in ``intel/`` where the
  committed one was since regenerated on the AMD machine).
- Rejects, for every config the golden test renders: exposure +3 %, the image shifted by
  one pixel, a technique switched (shadows, AO), and one pass's output replaced by its input
  (tonemap or FXAA skipped). Each mutated render is compared with the unmutated render of the
  same adapter (the session cache of ``test_golden``), so the controls run on any adapter.
  The rendered controls use the tiny scene: it has the fewest pixels to change, so it is
  where a regression comes closest to the bounds (measured margins: ``golden_util.Bounds``).
- An adapter without goldens fails under CI and skips elsewhere, with the command that
  creates them.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from . import golden_util
from .golden_util import (
    BOUNDS,
    REGEN_COMMAND,
    REGEN_ENV,
    adapter_key,
    check_golden,
    image_diff,
    mismatch,
    read_png,
)
from .test_golden import CONFIGS, config

OTHER_CPU = Path(__file__).resolve().parent / "data" / "golden-other-cpu"
# the adapter both machines report; the goldens the AMD files re-render
ADAPTER = "llvmpipe-llvm15-256bit-mesa-25.0"

# per config: the technique switches (--set) and the pass whose output is replaced by its
# input; rt_primary has neither (no tonemap: its outputs are linear, so exposure scales the
# 8-bit levels; its one pass reads only the acceleration structure)
SWITCHES = {
    "deferred": ["shadow.enabled=true"],
    "deferred_meshlet": ["shadow.enabled=true"],
    "deferred_vis": ["shadow.enabled=true"],
    "deferred_mixed": ["shadow.enabled=false"],
    "deferred_ssao_shadows": ["shadows=off", "ao=off"],
    "flat": ["flat.ambient=0.2", "flat.ambient=0.3"],
    "forward": ["shadow.enabled=true"],
    "forward_prepass": ["shadow.enabled=true"],
    "meshlet": ["shadow.enabled=true"],
    "rt_primary": [],
    "rt_shadows": ["shadow.enabled=false", "ssao.enabled=false"],
}
SKIPPED = {"deferred_ssao_shadows": "fxaa", "flat": None, "rt_primary": None}  # default: tonemap
# configs without tonemap (linear 8-bit outputs): exposure scales the levels
LINEAR = ("flat", "rt_primary")
# goldens added after the AMD renders (tests/data/golden-other-cpu/README.md): re-render them
# on another processor and empty this
NO_OTHER_CPU_YET = {"flat__courtyard.png", "flat__tiny.png", "deferred_vis__courtyard.png",
                    "deferred_vis__tiny.png"}


def controls(name: str) -> list[str]:
    out = ["exposure", "shift-x", "shift-y", *(f"set:{s}" for s in SWITCHES[name])]
    skipped = SKIPPED.get(name, "tonemap")
    return out + ([f"skip:{skipped}"] if skipped else [])


def shifted(image: np.ndarray, axis: int) -> np.ndarray:
    """The image moved one pixel right (axis 1) or down (axis 0), the first row or column
    repeated, so only the move itself differs."""
    first = image[:1] if axis == 0 else image[:, :1]
    rest = image[:-1] if axis == 0 else image[:, :-1]
    return np.concatenate([first, rest], axis=axis)


def scaled(image: np.ndarray, factor: float) -> np.ndarray:
    rgb = np.clip(np.rint(image[..., :3] * factor), 0, 255).astype(np.uint8)
    return np.concatenate([rgb, image[..., 3:]], axis=-1)


def mutated(name: str, control: str, renders) -> tuple[dict, dict]:
    """(unmutated, mutated) renders of ``name`` on the tiny scene: output -> image."""
    base = renders(config(name), "tiny")
    if control.startswith("shift-"):
        return base, {k: shifted(v, 1 if control == "shift-x" else 0) for k, v in base.items()}
    if control == "exposure" and name in LINEAR:
        return base, {k: scaled(v, 1.03) for k, v in base.items()}
    if control == "exposure":
        return base, renders(config(name, "tonemap.exposure=1.03"), "tiny")
    if control.startswith("set:"):
        return base, renders(config(name, control[4:]), "tiny")
    # skip:<pass>: the graph's output becomes that pass's (only) input
    cfg = config(name)
    (source,) = cfg.entry(control[5:]).inputs.values()
    (out,) = base
    return base, {out: renders(replace(cfg, outputs=[source]), "tiny")[source]}


@pytest.mark.parametrize("name, control",
                         [(n, c) for n in CONFIGS for c in controls(n)])
def test_comparison_rejects_the_negative_control(name, control, renders):
    base, other = mutated(name, control, renders)
    assert base.keys() == other.keys()
    for out, image in base.items():
        assert image[..., :3].std() > 10  # a picture, not a flat field
        why = mismatch(other[out], image)
        assert why, f"{name} {out}: {control} accepted ({image_diff(other[out], image)})"


def test_every_config_has_its_controls():
    # a new config must say which technique it can switch and which pass it can skip
    assert set(SWITCHES) == set(CONFIGS)
    for name in CONFIGS:
        assert "exposure" in controls(name) and "shift-x" in controls(name)
        if name != "rt_primary":
            assert len(controls(name)) >= 5, name


# the Intel goldens that AMD files re-render, kept where the committed golden was since
# regenerated on the AMD machine (the sRGB mip fix, tests/data/golden-other-cpu/README.md):
# the pair still measures two processors on one picture. Re-render both halves on an Intel
# CPU and the AMD one, then empty this folder
INTEL = OTHER_CPU / "intel"


def other_cpu_files() -> list[Path]:
    return sorted(OTHER_CPU.glob("*.png"))


def golden_of(path: Path) -> np.ndarray:
    """The golden the other-CPU render ``path`` re-renders: the kept Intel one, else the
    committed golden."""
    kept = INTEL / path.name
    return read_png(kept if kept.exists() else golden_util.GOLDEN / ADAPTER / path.name)


def test_every_golden_has_an_other_cpu_render():
    committed = {p.name for p in (golden_util.GOLDEN / ADAPTER).glob("*.png")}
    assert committed >= NO_OTHER_CPU_YET
    assert committed and committed - NO_OTHER_CPU_YET == {p.name for p in other_cpu_files()}
    # a kept Intel golden is one that has changed since: otherwise the committed one serves
    for p in sorted(INTEL.glob("*.png")):
        assert (OTHER_CPU / p.name).exists(), p.name
        assert not np.array_equal(read_png(p), read_png(golden_util.GOLDEN / ADAPTER / p.name))


@pytest.mark.parametrize("path", other_cpu_files(), ids=lambda p: p.stem)
def test_other_cpu_render_matches_the_golden(path):
    # the very comparison check_golden makes
    assert mismatch(read_png(path), golden_of(path)) == ""


def test_other_cpu_renders_are_not_all_identical():
    # the acceptance above means something only if the files differ: they do, up to 42
    # levels on a few shadow-edge pixels of deferred_ssao_shadows
    largest = {}
    for p in other_cpu_files():
        d = read_png(p).astype(int) - golden_of(p)
        largest[p.stem] = int(np.abs(d).max())
    assert largest["deferred_ssao_shadows__courtyard"] > 20
    assert sum(v > 1 for v in largest.values()) >= 5


@pytest.mark.parametrize("field, value", [
    ("flip", BOUNDS.flip_mean * 1.01), ("over2", 42), ("over1", 208),
    ("mean_abs", BOUNDS.mean_abs * 1.01), ("mean_signed", BOUNDS.mean_signed * 1.01)])
def test_each_bound_rejects_on_its_own(field, value):
    # a difference within every bound but one is still rejected, naming that bound
    ok = golden_util.ImageDiff(pixels=20736, largest=2, over1=0, over2=0, mean_abs=0.0,
                               mean_signed=0.0, flip=0.0)
    assert ok.violations() == []
    assert len(replace(ok, **{field: value}).violations()) == 1


def test_shapes_that_differ_are_a_mismatch():
    a = np.zeros((4, 6, 4), np.uint8)
    assert "shapes differ" in mismatch(a, a[:, :5])


# ---------------------------------------------------------------------------------------------
# an adapter without goldens


class FakeAdapter:
    name = "Fake GPU 9000 (test double)"
    driver = "fakedrv 1.2.3"


def picture() -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.integers(0, 256, (12, 16, 4), dtype=np.uint8)


def test_fake_adapter_has_no_goldens():
    assert adapter_key(FakeAdapter()) == "fake-gpu-9000-fakedrv-1.2"
    assert not (golden_util.GOLDEN / adapter_key(FakeAdapter())).exists()


@pytest.mark.parametrize("ci", ["true", "1", "yes"])
def test_missing_goldens_fail_under_ci_with_the_command(monkeypatch, tmp_path, ci):
    monkeypatch.setenv("CI", ci)
    monkeypatch.delenv(REGEN_ENV, raising=False)
    with pytest.raises(pytest.fail.Exception, match=re.escape(REGEN_COMMAND)) as info:
        check_golden(picture(), "deferred__tiny", FakeAdapter(), tmp_path / "art")
    assert "fake-gpu-9000-fakedrv-1.2" in str(info.value)


@pytest.mark.parametrize("ci", [None, "", "0", "false"])
def test_missing_goldens_skip_outside_ci_with_the_command(monkeypatch, tmp_path, ci):
    if ci is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", ci)
    monkeypatch.delenv(REGEN_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match=re.escape(REGEN_COMMAND)):
        check_golden(picture(), "deferred__tiny", FakeAdapter(), tmp_path / "art")


def test_regenerate_then_compare(monkeypatch, tmp_path):
    # goldens written for the fake adapter (into tmp_path) are then compared: the same
    # picture passes, a shifted one fails with actual, expected and diff written
    monkeypatch.setattr(golden_util, "GOLDEN", tmp_path / "golden")
    monkeypatch.setenv("CI", "true")
    image = picture()
    monkeypatch.setenv(REGEN_ENV, "1")
    check_golden(image, "x", FakeAdapter(), tmp_path / "art")
    assert (tmp_path / "golden" / "fake-gpu-9000-fakedrv-1.2" / "x.png").exists()
    monkeypatch.delenv(REGEN_ENV)
    check_golden(image, "x", FakeAdapter(), tmp_path / "art")
    assert not (tmp_path / "art").exists()
    with pytest.raises(AssertionError, match=r"x on 'fake-gpu-9000-fakedrv-1.2': .*over 2"):
        check_golden(shifted(image, 1), "x", FakeAdapter(), tmp_path / "art")
    assert {p.name for p in (tmp_path / "art").iterdir()} == {"actual.png", "expected.png",
                                                             "diff.png"}


def _vendor_pairs():
    names = ("llvmpipe-llvm15-256bit-mesa-25.0", "nvidia-h200-580.159.04")
    lavapipe, nvidia = (golden_util.GOLDEN / a for a in names)
    return [(p, nvidia / p.name) for p in sorted(lavapipe.glob("*.png"))
            if (nvidia / p.name).exists()]


def test_vendor_bounds_hold_between_lavapipe_and_the_h200():
    """rfw.golden.VENDOR_BOUNDS (what `rfw bench replay` allows across devices) holds every
    golden both adapters have; the CPU bounds reject most of them (the control: another
    vendor is not another CPU), and a 3 % brighter H200 render is still caught."""
    from rfw.golden import VENDOR_BOUNDS

    pairs = _vendor_pairs()
    assert len(pairs) >= 20
    diffs = [image_diff(read_png(b), read_png(a)) for a, b in pairs]
    assert [d.violations(VENDOR_BOUNDS) for d in diffs] == [[]] * len(diffs)
    assert sum(bool(d.violations(BOUNDS)) for d in diffs) >= len(diffs) // 2
    a, b = next((a, b) for a, b in pairs if a.name == "deferred__courtyard.png")
    brighter = np.clip(np.rint(read_png(b).astype(np.float32) * [1.03, 1.03, 1.03, 1]), 0, 255)
    assert image_diff(brighter.astype(np.uint8), read_png(a)).violations(VENDOR_BOUNDS)
