"""benchmarks/bench_fill.py: each way it times really writes every pixel of every target, and
its report gives every way a row with the raster/compute ratio."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_fill as bf  # noqa: E402


@pytest.fixture(scope="module")
def bench():
    return bf.Bench()


@pytest.mark.parametrize("name", list(bf.SETS))
def test_raster_and_compute_fill_every_target(bench, name):
    rows = bf.measure(bench, name, (24, 16), frames=1, warmup=0)  # checks every target
    assert [r["way"] for r in rows] == list(bf.WAYS)
    assert all(r["gpu_ms"] > 0 and r["bytes_per_pixel"] == sum(bf.BYTES[f] for f in
                                                                 bf.SETS[name]) for r in rows)


@pytest.mark.parametrize("fmt", ["rgba8unorm", "rgba16float", "r32uint"])
def test_the_fill_check_rejects_an_unwritten_target(bench, fmt):
    # negative control: a target nothing wrote (zeros) fails the check
    tex = bench.targets((fmt,), (8, 8))[0]
    with pytest.raises(SystemExit, match="was not filled"):
        bench.check(tex, fmt, (8, 8), 0)
    tex.destroy()


def test_the_cli_writes_its_report(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_fill.py"), "--sizes",
                        "16x8", "--sets", "id", "--frames", "1", "--warmup", "0", "--out",
                        str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rows = json.loads((tmp_path / "fill.json").read_text())["rows"]
    assert [(x["set"], x["way"], x["size"]) for x in rows] == [("id", w, "16x8")
                                                               for w in bf.WAYS]
    md = (tmp_path / "fill.md").read_text()
    assert md.count("| id (4 B/px) | 16x8 |") == 3 and "raster ÷ compute" in md
