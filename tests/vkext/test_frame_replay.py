"""Whole frames replayed on vk: a frame that would record what its slot's primary command
buffer already holds submits that buffer again (``VkExecutor`` frame replay).

Counted, not timed: primary command buffers begun. N frames over two slots begin one per
slot; a changed setting begins one again (negative control), and ``frame_replay=False``
begins one every frame (negative control). Images equal those of frames recorded each
frame, bit for bit, and every frame keeps its timing samples."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.options import RunOptions
from vkext.executor import VkExecutor
from vkext.fitting import fit_plan
from vkext.scene import VkScene

from ..cli.warm import warm_cli
from ..conftest import tiny_scene
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]


def _run(vk_device, monkeypatch, config: str, frames: int, *, replay: bool = True,
         settings=None, sync: bool = False) -> tuple[list[int], list[np.ndarray], dict[str, tuple[int, int]]]:
    """``frames`` frames, two in flight, read after each batch of ``settings`` (frame ->
    pass -> settings changed before it): primaries begun per batch, images, samples."""
    monkeypatch.setattr(vk_device, "sync_validation", sync)
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), ["size=64x48"])
    built = build(cfg)
    plan, info = fit_plan(built.graph, vk_device, readback=True)
    vscene = VkScene(vk_device, tiny_scene())
    ex = None
    begun, images = [], []
    try:
        vscene.set_viewport(cfg.size)
        ex = VkExecutor(vk_device, plan, built.passes, built.slots, vscene,
                        readback=tuple(plan.outputs), memory_info=info,
                        options=RunOptions(frame_replay=replay))
        ex.keep_in_flight(2)
        cuts = sorted({0, frames, *(settings or {})})
        for start, stop in pairwise(cuts):
            for name, values in (settings or {}).get(start, {}).items():
                ex.passes[name].params = ex.passes[name].params.replace(**values)
            before = ex.primaries
            ex.run(stop - start)
            begun.append(ex.primaries - before)
            images.append(ex.read(plan.outputs[0]).copy())
        samples = {n: (len(t.cpu_ms), len(t.gpu_ms)) for n, t in ex.timings.items()}
    finally:
        if ex is not None:
            ex.destroy()
        vscene.destroy()
    vk_device.check_validation()
    return begun, images, samples


@pytest.mark.parametrize("config", ["flat", "deferred"])
def test_unchanged_frames_record_one_primary_per_slot(vk_device, monkeypatch, config):
    begun, images, samples = _run(vk_device, monkeypatch, config, 8)
    assert begun == [2]
    every, inline, inline_samples = _run(vk_device, monkeypatch, config, 8, replay=False)
    assert every == [8]  # negative control: off, every frame records its primary
    assert all(np.array_equal(a, b) for a, b in zip(images, inline, strict=True))
    assert samples == inline_samples
    assert all(c == 8 for c, _ in samples.values())
    assert all(g == (8 if "timestamp" in vk_device.caps else 0) for _, g in samples.values())


def test_a_changed_setting_records_the_frame_again(vk_device, monkeypatch):
    change = {4: {"tonemap": {"exposure": 2.0}}}
    begun, images, _ = _run(vk_device, monkeypatch, "deferred", 8, settings=change)
    # negative control: the slots' primaries no longer hold what the changed frames record
    assert begun == [2, 2]
    # the change reached the image: 1 of the pixels measured on lavapipe
    assert changed_share(images[0], images[1]) > 0.5
    _, inline, _ = _run(vk_device, monkeypatch, "deferred", 8, settings=change, replay=False)
    assert all(np.array_equal(a, b) for a, b in zip(images, inline, strict=True))


def test_passes_that_record_every_frame_record_the_frame(vk_device, monkeypatch):
    # under synchronization validation passes record their commands into the frame (no
    # replay): negative control, the frame's primary is recorded every frame
    begun, images, _ = _run(vk_device, monkeypatch, "deferred", 6, sync=True)
    assert begun == [6]
    replayed, again, _ = _run(vk_device, monkeypatch, "deferred", 6)
    assert replayed == [2]
    assert all(np.array_equal(a, b) for a, b in zip(images, again, strict=True))


@pytest.mark.parametrize(("value", "code"), [("maybe", 2), ("0", 0)])
def test_a_bad_switch_is_one_line_and_exit_2(tmp_path, value, code):
    # "0" (a good value, the baseline) is the negative control
    run = warm_cli("run", ROOT / "configs" / "flat.toml", "--backend", "vk", "--size", "16x8",
                   "--out", tmp_path / "o", timeout=600, env={"RFW_VK_FRAME_REPLAY": value})
    assert run.returncode == code, run.stderr
    if code:
        assert run.stderr.count("\n") == 1 and "RFW_VK_FRAME_REPLAY: expected 0 or 1" in \
            run.stderr and "Traceback" not in run.stderr
