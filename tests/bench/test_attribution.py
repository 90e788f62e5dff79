"""What a change costs, pass by pass: the frame total's change split into passes added,
removed and changed and a residual, in ``rfw bench compare`` and the bench report. The CLI
runs in a subprocess on synthetic results.jsonl files; a planted change must land on its own
pass (or, unseen by any timer, on the residual) and nowhere else, and the parts must add up."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from rfw.bench.attribution import attribute
from tests.cli.warm import warm_cli

from .synthetic import record

BASE = {"gbuffer": 10.0, "lighting": 2.0, "tonemap": 0.5}


def write(folder: Path, variants: dict[str, dict[str, float]], *, seed: int, repeats: int = 3,
          frames: int = 20, untimed: float = 0.0) -> Path:
    """A results.jsonl of ``repeats`` runs per variant; ``untimed`` ms are added to each
    frame's total and to no pass (work no pass timer saw)."""
    lines = []
    for r in range(repeats):
        for v, passes in variants.items():
            rec = record(v, r, passes, seed=seed, frames=frames)
            rec["frame"]["gpu_ms"] = [g + untimed for g in rec["frame"]["gpu_ms"]]
            lines.append(rec)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "results.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return folder


def rows_of(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as f:
        return {(r["variant"], r["part"]): r for r in csv.DictReader(f)}


def check_sums(rows: dict[tuple[str, str], dict[str, str]]) -> None:
    """Every pair's parts add up to its frame total's change (CSV cells: 6 decimals)."""
    for variant in {v for v, _ in rows}:
        mine = [r for (v, _), r in rows.items() if v == variant]
        total = next(float(r["change_ms"]) for r in mine if r["kind"] == "total")
        parts = sum(float(r["change_ms"]) for r in mine if r["kind"] != "total")
        assert parts == pytest.approx(total, abs=1e-5), variant


def holds(row: dict[str, str], value: float) -> bool:
    return float(row["ci_lo"]) <= value <= float(row["ci_hi"])


def test_compare_puts_a_planted_change_on_its_pass(tmp_path):
    old = write(tmp_path / "old", {"d@wgpu": BASE}, seed=1)
    new = write(tmp_path / "new", {"d@wgpu": {**BASE, "lighting": 2.6}}, seed=2)
    done = warm_cli("bench", "compare", old, new, "--out", tmp_path / "cmp", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = rows_of(tmp_path / "cmp" / "attribution.csv")
    check_sums(rows)
    light = rows[("d@wgpu", "lighting")]
    assert light["kind"] == "changed" and light["mark"] == "*" and holds(light, 0.6)
    assert float(light["ci_lo"]) > 0.5
    for name in ("gbuffer", "tonemap"):  # the control: unchanged passes stay within the noise
        r = rows[("d@wgpu", name)]
        assert r["mark"] == "(n.s.)" and holds(r, 0.0), r
    resid = rows[("d@wgpu", "residual")]
    assert float(resid["change_ms"]) == 0.0 and resid["mark"] == "(n.s.)"
    total = rows[("d@wgpu", "frame total")]
    assert total["mark"] == "*" and holds(total, 0.6)
    assert (total["baseline_frames"], total["baseline_runs"]) == ("60", "3")
    md = (tmp_path / "cmp" / "compare.md").read_text()
    assert "## Frame change, pass by pass" in md
    assert "| lighting | changed | 2.001 | 2.597 | +0.596 | +0.578 to +0.612 | * |" in md
    assert "Frame change, pass by pass" in (tmp_path / "cmp" / "compare.html").read_text()
    assert "d@wgpu: frame +0." in done.stdout and "lighting +0.596 (changed)" in done.stdout

    # work no timer saw: the residual takes it, no pass does
    hidden = write(tmp_path / "hidden", {"d@wgpu": BASE}, seed=2, untimed=0.3)
    done = warm_cli("bench", "compare", old, hidden, "--out", tmp_path / "cmp2", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = rows_of(tmp_path / "cmp2" / "attribution.csv")
    check_sums(rows)
    resid = rows[("d@wgpu", "residual")]
    assert resid["mark"] == "*" and holds(resid, 0.3) and float(resid["ci_lo"]) > 0.29
    assert all(rows[("d@wgpu", n)]["mark"] == "(n.s.)" for n in BASE)


def test_report_attributes_added_removed_and_renamed_passes(tmp_path):
    out = write(tmp_path / "bench", {
        "d@wgpu": BASE,
        "d[ssao]@wgpu": {"gbuffer": 10.0, "ssao": 1.5, "lighting": 1.8, "tonemap": 0.5},
        "d[aces]@wgpu": {"gbuffer": 10.0, "lighting": 2.0, "tonemap_aces": 0.5},
    }, seed=3)
    done = warm_cli("bench", "report", out, cwd=tmp_path, tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = rows_of(out / "attribution.csv")
    check_sums(rows)
    assert {r["baseline"] for r in rows.values()} == {"d@wgpu"}
    ssao = rows[("d[ssao]@wgpu", "ssao")]
    assert ssao["kind"] == "added" and float(ssao["baseline_ms"]) == 0.0 and holds(ssao, 1.5)
    # what the technique costs and what it saves elsewhere, each with its mark
    light = rows[("d[ssao]@wgpu", "lighting")]
    assert light["mark"] == "*" and holds(light, -0.2)
    assert rows[("d[ssao]@wgpu", "gbuffer")]["mark"] == "(n.s.)"
    # a renamed pass: the old name removed, the new one added, the frame within the noise
    gone, came = rows[("d[aces]@wgpu", "tonemap")], rows[("d[aces]@wgpu", "tonemap_aces")]
    assert (gone["kind"], came["kind"]) == ("removed", "added")
    assert holds(gone, -0.5) and holds(came, 0.5) and float(gone["variant_ms"]) == 0.0
    assert rows[("d[aces]@wgpu", "frame total")]["mark"] == "(n.s.)"
    md = (out / "report.md").read_text()
    section = md.split("## Frame change, pass by pass")[1].split("\n## ")[0]
    assert "### d[ssao]@wgpu against d@wgpu" in section
    assert section.index("| gbuffer |") < section.index("| ssao | added") < \
        section.index("| lighting |")  # frame order
    assert "| tonemap | removed: minus its time |" in section
    assert "Frame change, pass by pass" in (out / "report.html").read_text()

    # another baseline: --reference
    done = warm_cli("bench", "report", out, "--reference", "d[ssao]@wgpu", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = rows_of(out / "attribution.csv")
    check_sums(rows)
    assert {r["baseline"] for r in rows.values()} == {"d[ssao]@wgpu"}
    assert rows[("d@wgpu", "ssao")]["kind"] == "removed"


def test_too_few_frames_or_runs_get_no_mark(tmp_path):
    old = write(tmp_path / "old", {"d@wgpu": BASE}, seed=1, repeats=1, frames=3)
    new = write(tmp_path / "new", {"d@wgpu": {**BASE, "lighting": 4.0}}, seed=2, repeats=1,
                frames=3)
    done = warm_cli("bench", "compare", old, new, "--out", tmp_path / "cmp", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    rows = rows_of(tmp_path / "cmp" / "attribution.csv")
    check_sums(rows)
    assert {r["mark"] for r in rows.values()} == {"(n=3<6: no mark)"}


def test_missing_pass_times_and_unequal_runs_still_add_up():
    """A frame without one pass's time counts that pass 0 and its time in the residual; runs
    of different lengths are resampled each with its own frames."""
    base = [record("d", r, BASE, seed=4, frames=8 + 4 * r) for r in range(3)]
    own = [record("d", r, {**BASE, "lighting": 2.5}, seed=5, frames=10) for r in range(3)]
    for rec in own:
        rec["passes"][2]["gpu_ms"][0] = None  # tonemap without a time in frame 0
    at = attribute(base, own, variant="d", baseline="OLD")
    assert at.frames == (8 + 12 + 16, 30)
    assert sum(p.change for p in at.parts) == pytest.approx(at.total.change, abs=1e-12)
    resid = next(p for p in at.parts if p.kind == "residual")
    assert resid.own == pytest.approx(0.5 / 10, rel=0.05)  # one frame of ten: 0.5 ms
    assert resid.base == 0.0
    assert any("missing" in n for n in at.notes)
    light = next(p for p in at.parts if p.name == "lighting")
    assert light.mark == "*" and light.ci_lo < 0.5 < light.ci_hi


def test_runs_are_resampled_so_run_to_run_shifts_widen_the_ci():
    """+0.1 ms on lighting in every run: marked when the runs agree, within the noise when
    whole runs differ by 0.4 ms (another process, another memory layout): frames alone would
    understate that noise and mark it."""
    def runs(levels: list[float], seed: int) -> list[dict]:
        return [record("d", r, {**BASE, "lighting": x}, seed=seed) for r, x in enumerate(levels)]

    def lighting(a: list[dict], b: list[dict]) -> str:
        at = attribute(a, b, variant="d", baseline="OLD")
        return next(p.mark for p in at.parts if p.name == "lighting")

    assert lighting(runs([2.0, 2.0, 2.0], 6), runs([2.1, 2.1, 2.1], 7)) == "*"
    assert lighting(runs([2.0, 2.4, 1.6], 6), runs([2.1, 2.5, 1.7], 7)) == "(n.s.)"


def test_a_a_pairs_are_rarely_marked_and_a_planted_change_is_found():
    """Calibration on synthetic series with a known distribution: 3 runs of 10 frames a side,
    each run shifted by a normal 2% (another process), each frame 1% noise. 100 A/A pairs
    must mark the frame total at most 8 times (95% CIs: 5 expected; 3 seen; the percentile
    bootstrap alone, without the small-runs widening, marks 12 here, 17% of 400); a planted
    +10% on lighting is found in at least 80 of 100 pairs (99 seen)."""
    rng = np.random.default_rng(8)

    def side(seed: int, lighting: float = 1.0) -> list[dict]:
        out = []
        for r in range(3):
            k = 1 + 0.02 * rng.standard_normal()
            passes = {n: v * k * (lighting if n == "lighting" else 1.0) for n, v in BASE.items()}
            out.append(record("d", r, passes, seed=seed, frames=10))
        return out

    aa = found = 0
    for i in range(100):
        a = side(3 * i + 100)
        at = attribute(a, side(3 * i + 101), variant="d", baseline="a", resamples=1000, seed=i)
        aa += at.total.mark == "*"
        at = attribute(a, side(3 * i + 102, 1.10), variant="d", baseline="a", resamples=1000,
                       seed=i)
        found += next(p for p in at.parts if p.name == "lighting").mark == "*"
    assert aa <= 8 and found >= 80, (aa, found)
