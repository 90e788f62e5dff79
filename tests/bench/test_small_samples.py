"""Significance needs enough samples, and wall time is per run (review of the bench's
statistics, item 2), through ``rfw bench report`` and ``rfw bench compare`` in a subprocess
on synthetic results: a clear difference from too few samples or one run gets no mark and
says why; with enough it keeps its mark (the negative control)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.bench.stats import (
    MIN_RUNS,
    MIN_SAMPLES,
    mark,
    no_mark,
    summarize,
    summarize_passes,
    summarize_runs,
)

from ..cli.warm import warm_cli
from .synthetic import record


def write(out: Path, variants: dict[str, float], *, repeats: int, frames: int,
          wall: list[float] | None = None) -> Path:
    """``variants``: label -> frame GPU ms (one pass ``g``), each run an image; ``wall``:
    every run's per-frame wall ms instead of GPU + 1."""
    lines = []
    for r in range(repeats):
        for label, gpu in variants.items():
            rec = record(label, r, {"g": gpu}, frames=frames, seed=len(label))
            if wall is not None:
                rec["frame"]["wall_ms"] = [w * (1 + 0.01 * r) for w in wall]
            rel = f"runs/{rec['variant_id']}/r{r}/image.png"
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.full((18, 32, 3), 100, np.uint8)).save(out / rel)
            rec["image"] = rel
            lines.append(json.dumps(rec) + "\n")
    (out / "results.jsonl").write_text("".join(lines))
    return out


def vs_reference(out: Path, label: str) -> str:
    md = (out / "report.md").read_text()
    images = md.split("## Images")[1].split("\n## ")[0]
    line = next(x for x in images.splitlines() if x.startswith(f"| {label} |"))
    return line.strip().strip("|").split("|")[-1].strip()


def test_the_rule():
    assert (MIN_SAMPLES, MIN_RUNS) == (6, 2)
    # n=5: even the samples' range covers the median with under 95% (1 - 2 * 0.5**5)
    assert 1 - 2 * 0.5**5 < 0.95 <= 1 - 2 * 0.5**6
    apart = [[10.0 + 0.01 * i for i in range(3)] for _ in range(3)]  # 3 runs x 3 frames
    far = [[20.0 + 0.01 * i for i in range(3)] for _ in range(3)]
    assert mark(summarize(apart), summarize(far)) == "*"  # n=9, 3 runs: enough
    assert mark(summarize(apart[:1]), summarize(far)) == "(n=3<6: no mark)"
    assert mark(summarize([10.0] * 8), summarize(far)) == "(1 run: no mark)"
    assert no_mark(summarize_runs([1.0, 2.0, 3.0, 4.0, 5.0])) == "n=5<6"
    assert no_mark(summarize_runs([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])) is None
    # n=2: the bootstrap gives the min-max range, which the rule does not call a 95% CI
    two = summarize_runs([1.0, 3.0])
    assert (two["ci_lo"], two["ci_hi"]) == (1.0, 3.0) and no_mark(two) == "n=2<6"
    # what the examples use: per pass, one number per render; a pass without times is None
    per_pass = summarize_passes([{"g": 10.0 + i, "t": None} for i in range(6)])
    assert per_pass["t"] is None
    assert (per_pass["g"]["n"], per_pass["g"]["runs"], per_pass["g"]["median"]) == (6, 6, 12.5)


@pytest.mark.parametrize("repeats, frames, expected", [
    (1, 3, "(n=3<6: no mark)"),  # the review's case: one run of 3 frames
    (1, 20, "(1 run: no mark)"),  # many frames of one process: run-to-run noise unmeasured
    (3, 3, "*"),  # negative control: 9 frames from 3 runs keep the mark
])
def test_report_marks_only_enough_samples(tmp_path, repeats, frames, expected):
    out = write(tmp_path / "b", {"r@wgpu": 10.0, "s@wgpu": 20.0}, repeats=repeats,
                frames=frames)
    done = warm_cli("bench", "report", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    vs = vs_reference(out, "s@wgpu")
    assert vs.startswith("+") and vs.endswith(f"% {expected}"), vs
    md = (out / "report.md").read_text()
    frame = md.split("## Frame time per variant")[1].split("\n## ")[0]
    row = next(x for x in frame.splitlines() if x.startswith("| s@wgpu |"))
    cells = [c.strip() for c in row.strip().strip("|").split("|")]
    assert cells[-1] == f"{repeats} x {frames}"  # runs x frames
    note = expected.removesuffix(": no mark)").removeprefix("(")
    assert cells[4].endswith(f" ({note})") == (expected != "*"), cells[4]  # the GPU CI
    how = md.split("## How this was measured")[1]
    assert "percentile bootstrap" in how and "Below 6 samples or 2 runs there is no mark" in how


@pytest.mark.parametrize("repeats, frames, flagged", [(1, 3, False), (6, 5, True)])
def test_compare_judges_only_enough_samples(tmp_path, repeats, frames, flagged):
    old = write(tmp_path / "old", {"d@wgpu": 10.0}, repeats=repeats, frames=frames)
    new = write(tmp_path / "new", {"d@wgpu": 20.0}, repeats=repeats, frames=frames)
    done = warm_cli("bench", "compare", str(old), str(new), "--fail-on-regression", "--out",
                    str(tmp_path / "cmp"), safe_path=True)
    assert done.returncode == (1 if flagged else 0), done.stdout + done.stderr
    md = (tmp_path / "cmp" / "compare.md").read_text()
    row = next(x for x in md.splitlines() if x.startswith("| d@wgpu | g | gpu_ms |"))
    if flagged:  # negative control: the same +100 % with enough samples is a regression
        assert "% * | regression |" in row
        assert "not judged" not in done.stdout
    else:
        assert "% (n=3<6: no mark) | too few samples (n=3<6) |" in row
        assert "1 regression" not in done.stdout
        assert "not judged: too few samples (under 6 samples or 2 runs a side" in done.stdout
        listed = warm_cli("bench", "compare", str(old), str(new), "--all", safe_path=True)
        assert "too few samples (n=3<6)" in listed.stdout


def test_wall_is_per_run_total_over_frames(tmp_path):
    # frames in flight: one frame's wall clock absorbs the wait for another
    wall = [0.9, 0.9, 0.9, 60.3]
    out = write(tmp_path / "b", {"r@wgpu": 15.0}, repeats=6, frames=4, wall=wall)
    done = warm_cli("bench", "report", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader((out / "results.csv").open()))
    w = next(r for r in rows if r["pass"] == "frame" and r["metric"] == "wall_ms")
    per_run = [sum(wall) / 4 * (1 + 0.01 * r) for r in range(6)]
    assert (int(w["n"]), int(w["runs"])) == (6, 6)  # one sample per run
    assert float(w["median"]) == pytest.approx(float(np.median(per_run)), rel=1e-6)
    assert float(w["ci_lo"]) >= min(per_run) - 1e-6 and float(w["ci_hi"]) <= max(per_run) + 1e-6
    # negative control: single frames pooled would say 0.9 ms, a quarter of the frames
    pooled = summarize([[x * (1 + 0.01 * r) for x in wall] for r in range(6)])
    assert pooled["median"] < 1.0 < float(w["median"])
    md = (out / "report.md").read_text()
    assert "| wall ms/frame | wall 95% CI |" in md
    assert "total wall time of its timed frames" in md
