"""Frames in flight (rfw.frame.InFlight): on wgpu and vk, K = 1, 2 and 3 frames in flight give
the same images, bit for bit, and one timing sample per pass and frame; with K > 1 frames do
overlap (a frame is submitted while the last one is still pending); the last timed frame
drains inside its own frame() call, so the bench's per-frame wall clock counts the drain; the
setting comes from render(), the config (``frames_in_flight``, ``--set``) or
RFW_FRAMES_IN_FLIGHT, and a bad value is one line and exit 2 through the CLI."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from rfw.backends.base import FrameExecutor
from rfw.config import apply_overrides, load_config
from rfw.errors import RfwError
from rfw.frame import InFlight, frames_in_flight
from rfw.options import RunOptions
from rfw.render import render

from ..cli.warm import warm_cli
from ..conftest import tiny_scene
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
FRAMES = 4


def _config(name: str = "deferred", size: str = "96x54"):
    sets = ["shadow.enabled=true"] if name == "deferred" else []
    return apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"),
                           [*sets, f"size={size}"])


@pytest.fixture
def overlap(monkeypatch):
    """The most frames ever in flight at once, per run (InFlight.submitted counted)."""
    seen: list[int] = []
    submitted = InFlight.submitted

    def counted(self, slot, finish):
        submitted(self, slot, finish)
        seen.append(self.busy)

    monkeypatch.setattr(InFlight, "submitted", counted)
    return seen


@pytest.mark.parametrize("backend", ["wgpu", "vk"])
def test_images_and_samples_equal_for_one_two_and_three_frames_in_flight(backend, overlap):
    runs = {}
    for k in (1, 2, 3):
        overlap.clear()
        result = render(_config(), scene=tiny_scene(), frames=FRAMES, backend=backend,
                        frames_in_flight=k)
        runs[k] = result
        assert result.timings["frames_in_flight"] == k
        # K = 1 never has two frames pending; K > 1 submits while the last is pending
        assert max(overlap) == k
        for name, t in result.executor.timings.items():
            assert len(t.cpu_ms) == FRAMES, name
            assert len(t.gpu_ms) == (FRAMES if result.timings["timestamps"] else 0), name
    images = {k: r.images["tonemap.ldr"] for k, r in runs.items()}
    assert images[1][..., :3].std() > 10  # a picture, not a cleared target
    assert np.array_equal(images[1], images[2]) and np.array_equal(images[1], images[3])


def test_a_different_state_gives_a_different_image():
    # negative control of the equality above: the same run with another setting differs
    a = render(_config(), scene=tiny_scene(), frames=2, frames_in_flight=2)
    b = render(apply_overrides(_config(), ["tonemap.exposure=1.5"]), scene=tiny_scene(),
               frames=2, frames_in_flight=2)
    assert changed_share(a.images["tonemap.ldr"], b.images["tonemap.ldr"]) > 0.5  # all


@pytest.mark.parametrize("backend", ["wgpu", "vk"])
def test_the_last_timed_frame_drains_inside_its_frame_call(backend, monkeypatch):
    """What the bench's FrameClock times (FrameExecutor.frame) includes the final drain:
    when the last frame() returns, nothing is in flight and every frame's timings are in."""
    after: list[tuple[int, int]] = []  # (frames in flight, cpu samples of one pass)
    frame = FrameExecutor.frame

    def timed(self, drain=False):
        frame(self, drain)
        after.append((self.in_flight.busy, len(next(iter(self.timings.values())).cpu_ms)))

    monkeypatch.setattr(FrameExecutor, "frame", timed)
    render(_config(), scene=tiny_scene(), frames=FRAMES, warmup=2, backend=backend,
           frames_in_flight=2)
    warmup, timed_frames = after[:2], after[2:]
    # frames overlap inside a run: a frame returns with itself and the one before in flight
    assert [busy for busy, _ in timed_frames[:-1]] == [1] + [2] * (FRAMES - 2)
    assert warmup[0][0] == 1
    # ... and the last frame of each run returns with everything finished and counted
    assert warmup[-1] == (0, 2)
    assert timed_frames[-1] == (0, FRAMES)


def test_frames_in_flight_setting(monkeypatch):
    # the environment is read at the edge, into RunOptions (rfw.options)
    monkeypatch.delenv("RFW_FRAMES_IN_FLIGHT", raising=False)
    assert RunOptions.from_env().in_flight() == 2 == frames_in_flight()
    monkeypatch.setenv("RFW_FRAMES_IN_FLIGHT", " 3 ")
    assert RunOptions.from_env().in_flight() == 3
    assert frames_in_flight() == 2  # below the edge nothing reads it
    assert RunOptions.from_env(frames_in_flight=1).in_flight() == 1  # an explicit value wins
    assert frames_in_flight(1) == 1
    for bad in ("0", "9", "two", "1.5", "-1"):
        monkeypatch.setenv("RFW_FRAMES_IN_FLIGHT", bad)
        with pytest.raises(RfwError, match="RFW_FRAMES_IN_FLIGHT"):
            RunOptions.from_env()
    for bad in (0, 9, 2.0, True, "2"):
        with pytest.raises(RfwError, match="frames_in_flight"):
            frames_in_flight(bad)
        with pytest.raises(RfwError, match="frames_in_flight"):
            RunOptions(frames_in_flight=bad)


def test_the_config_key_wins_over_the_environment(monkeypatch):
    monkeypatch.setenv("RFW_FRAMES_IN_FLIGHT", "1")
    cfg = apply_overrides(_config("flat", "32x18"), ["frames_in_flight=3"])
    assert cfg.frames_in_flight == 3
    assert render(cfg, scene=tiny_scene(), frames=1).timings["frames_in_flight"] == 3
    # without the key the environment decides; a render argument wins over both
    plain = _config("flat", "32x18")
    assert render(plain, scene=tiny_scene(), frames=1).timings["frames_in_flight"] == 1
    assert render(cfg, scene=tiny_scene(), frames=1,
                  frames_in_flight=2).timings["frames_in_flight"] == 2


def _rfw_run(tmp_path: Path, env_value: str | None, *sets: str) -> subprocess.CompletedProcess:
    extra = [a for s in sets for a in ("--set", s)]
    return warm_cli("run", ROOT / "configs" / "flat.toml", "--size", "32x18", "--frames", "2",
                    *extra, "--out", tmp_path / "out", env={"RFW_FRAMES_IN_FLIGHT": env_value},
                    timeout=600)


@pytest.mark.parametrize(("env_value", "sets", "where"), [
    ("0", (), "RFW_FRAMES_IN_FLIGHT: "), ("many", (), "RFW_FRAMES_IN_FLIGHT: "),
    ("100", (), "RFW_FRAMES_IN_FLIGHT: "), (None, ("frames_in_flight=0",), "--set "),
    (None, ("frames_in_flight=two",), "--set "), (None, ("frames_in_flight=9",), "--set ")])
def test_a_bad_value_is_one_line_and_exit_2_through_the_cli(tmp_path, env_value, sets, where):
    run = _rfw_run(tmp_path, env_value, *sets)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: ") and where in lines[0]
    assert "Traceback" not in run.stderr and not (tmp_path / "out" / "timings.json").exists()


def test_a_bad_config_value_is_one_line_and_exit_2(tmp_path):
    cfg = tmp_path / "flat.toml"
    text = (ROOT / "configs" / "flat.toml").read_text()
    cfg.write_text("frames_in_flight = true\n" + text)
    run = warm_cli("run", cfg, "--size", "32x18", "--out", tmp_path / "out", timeout=600)
    assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
    assert f"rfw: error: {cfg}: frames_in_flight: " in run.stderr


@pytest.mark.parametrize(("env_value", "sets", "want"), [("3", (), 3),
                                                         ("3", ("frames_in_flight=1",), 1)])
def test_a_good_value_runs_through_the_cli(tmp_path, env_value, sets, want):
    # negative control of the refusals: the same command with a valid value renders
    run = _rfw_run(tmp_path, env_value, *sets)
    assert run.returncode == 0, run.stderr
    timings = json.loads((tmp_path / "out" / "timings.json").read_text())
    assert timings["frames_in_flight"] == want and timings["frames"] == 2


@pytest.mark.parametrize(("env_value", "code"), [("0", 2), ("1", 0)])
def test_rfw_bench_refuses_a_bad_environment_value_once(tmp_path, env_value, code):
    # before any run starts (each run would fail alone); "1" is the negative control
    run = warm_cli("bench", "flat", "--size", "16x8", "--frames", "1", "--warmup", "0",
                   "--repeat", "1", "--out", tmp_path / "b", env={"RFW_FRAMES_IN_FLIGHT": env_value},
                   timeout=600)
    assert run.returncode == code, run.stderr
    if code:
        assert run.stderr.count("\n") == 1 and "RFW_FRAMES_IN_FLIGHT: " in run.stderr
        assert not (tmp_path / "b").exists()
    else:
        assert (tmp_path / "b" / "results.jsonl").exists()
