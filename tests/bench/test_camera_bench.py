"""``rfw bench`` along a camera path: per-frame GPU ms with each frame's camera in the
record, culling counters per frame on meshlet configs, and the report's path chart."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ..cli.warm import warm_cli
from ..conftest import ROOT


def bench(out: Path, config: str, *args: str) -> list[dict]:
    done = warm_cli("bench", ROOT / config, "--size", "32x18", "--warmup", "1", "--out", out,
                    "--no-progress", *args)
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]


def test_bench_records_each_frame_of_an_orbit(tmp_path):
    records = bench(tmp_path / "b", "configs/flat.toml", "--frames", "4", "--repeat", "2",
                    "--set", "camera.path=orbit", "--set", "camera.path.turns=0.5")
    assert len(records) == 2
    for r in records:
        assert not r.get("error"), r.get("error")
        cams = r["camera_path"]
        assert cams["kind"] == "orbit"
        assert [c["t"] for c in cams["frames"]] == pytest.approx([0.0, 0.25, 0.5, 0.75])
        assert len({tuple(c["position"]) for c in cams["frames"]}) == 4  # each its own view
        for p in r["passes"]:
            assert len(p["gpu_ms"]) == 4 and all(ms > 0 for ms in p["gpu_ms"])
    views = [[{k: v for k, v in c.items() if k != "write_ms"} for c in r["camera_path"]["frames"]]
             for r in records]
    assert views[0] == views[1]  # the same path each run
    report = (tmp_path / "b" / "report.md").read_text()
    charts = sorted(p.name for p in (tmp_path / "b" / "charts").glob("path_*.png"))
    assert charts == ["path_0_flat_wgpu.png"]
    assert "charts/path_0_flat_wgpu.png" in report
    # control: a static bench has no path in its records and no path chart
    static = bench(tmp_path / "s", "configs/flat.toml", "--frames", "2", "--repeat", "1")
    assert "camera_path" not in static[0]
    assert not list((tmp_path / "s" / "charts").glob("path_*.png"))


def test_meshlet_culling_counters_along_the_path(tmp_path):
    (r,) = bench(tmp_path / "m", "configs/meshlet.toml", "--backend", "vk", "--frames", "3",
                 "--repeat", "1", "--set", "camera.path=orbit")
    assert not r.get("error"), r.get("error")
    frames = r["culling_frames"]
    assert len(frames) == 3 and len(r["camera_path"]["frames"]) == 3
    # the untimed replay's last frame is the timed run's last frame: the same counters
    assert frames[-1] == r["culling"]
    # and the view matters: the counters change along the orbit
    assert frames[0]["meshlets_drawn"] != frames[-1]["meshlets_drawn"]
    assert all(f["meshlets_drawn"] <= f["meshlets_total"] for f in frames)
    report = (tmp_path / "m" / "report.md").read_text()
    assert "charts/path_0_" in report
    # each frame's wall time counts its camera write (on vk: the wait for frames in flight)
    writes = [c["write_ms"] for c in r["camera_path"]["frames"]]
    assert writes[0] == pytest.approx(0.0, abs=1.0) and all(w >= 0 for w in writes)
    assert all(w >= c for w, c in zip(r["frame"]["wall_ms"], writes, strict=True))


def test_meshlet_path_under_validation(tmp_path):
    # the camera written between frames on vk (host-mapped uniforms: frames drained first)
    done = warm_cli("run", ROOT / "configs/meshlet.toml", "--backend", "vk", "--validate",
                    "--size", "32x18", "--frames", "3", "--set", "camera.path=orbit",
                    "--out", tmp_path / "o")
    assert done.returncode == 0, done.stderr
    assert "validation: 0 message(s)" in done.stdout


def test_bench_records_the_flicker_of_jittered_and_still_path_runs(tmp_path):
    records = bench(tmp_path / "t", "configs/deferred_ssao_shadows.toml", "--frames", "5",
                    "--repeat", "1", "--vary", "aa=none,taa")
    by = {r["variants"]["aa"]: r for r in records}
    assert not any(r.get("error") for r in records), [r.get("error") for r in records]
    assert "temporal" not in by["none"]  # a still camera, no jitter: one image again
    t = by["taa"]["temporal"]
    assert t["jitter"] == 8 and t["frames"] == 5 and t["still_share"] == 1.0
    assert t["flicker"] > 0  # the jitter moves the image while the history fills
    # along a path that stands still (two keys of the same camera) the G-buffer's motion
    # vectors pick the still pixels: every drawn one
    records = bench(tmp_path / "p", "configs/deferred_ssao_shadows.toml", "--frames", "4",
                    "--repeat", "1", "--vary", "aa=none,taa", "--set",
                    "camera.path.keys=[{}, {}]")
    by = {r["variants"]["aa"]: r for r in records}
    for r in by.values():
        assert r["temporal"]["still"] == "velocity and depth"
        # the sky is left out (16 % at 32x18), and under jitter a few pixels whose samples
        # land on a surface not around them last frame (measured 84 % and 80 % counted)
        assert 0.6 < r["temporal"]["still_share"] < 0.9
    assert by["none"]["temporal"]["flicker"] == 0.0
    assert by["taa"]["temporal"]["flicker"] > 0
    report = (tmp_path / "p" / "report.md").read_text()
    assert "## Temporal stability" in report
