"""``rfw bench --executor ray`` (issue 14, item 9) on a local Ray instance, CPU only (lavapipe):
one small test, as Ray's start-up is slow."""

from __future__ import annotations

import contextlib
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ..conftest import rfw_cli
from .test_paper_report import relative_refs

TINY = ["--size", "32x18", "--frames", "2", "--warmup", "1", "--repeat", "1", "--no-progress"]


def _raylets() -> int:
    n = 0
    for cmd in Path("/proc").glob("[0-9]*/cmdline"):
        with contextlib.suppress(OSError):  # a process that ended meanwhile
            n += b"raylet" in cmd.read_bytes()
    return n


def test_ray_executor_runs_the_matrix_as_tasks_and_merges_one_report(tmp_path):
    # the test extra installs ray; a GPU machine without it (benchmarks/device_env.sh) skips
    pytest.importorskip("ray", reason="ray is not installed (pip install 'rfw[scale]')")
    before = _raylets()
    t = time.perf_counter()
    done = rfw_cli("bench", "forward", "flat", "--executor", "ray", "--out", "ray", *TINY,
                   cwd=tmp_path, safe_path=True)
    wall = time.perf_counter() - t
    print(f"rfw bench --executor ray, 2 runs: {wall:.1f} s")  # kept small; never asserted
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    out = tmp_path / "ray"
    recs = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert [r["variant"] for r in recs] == ["forward@wgpu", "flat@wgpu"]  # schedule order
    for r in recs:
        assert not r.get("error"), r.get("error")
        assert r["executor"] == "ray"
        assert r["ray"]["node"] and r["ray"]["host"] and r["ray"]["gpu_ids"] == []  # CPU only
        assert (out / r["image"]).is_file() and (out / r["image"]).stat().st_size > 0
        assert r["passes"] and len(r["frame"]["wall_ms"]) == 2
    # one report with a device column naming where each variant ran
    device = f"{recs[0]['device']} @ {recs[0]['ray']['host']}"
    md = (out / "report.md").read_text()
    assert f"| forward@wgpu | {device} | wgpu |" in md
    assert "## Images" in md and "flat_wgpu.diff.png" in md
    # both runs on one device: the report says so and points to no per-device table
    # (test_report_views has the two-device control)
    assert "## Per device" not in md and "per-device table (" not in md
    assert f"all runs measured one device ({device}), so there is no per-device table" in md
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert {r["device"] for r in rows} == {device}
    assert relative_refs((out / "report.html").read_text()) == []
    assert _raylets() <= before  # the local instance rfw started is stopped
    # negative control: the default executor runs here, with no Ray in its records
    local = rfw_cli("bench", "flat", "--out", "local", *TINY, cwd=tmp_path, safe_path=True)
    assert local.returncode == 0, local.stderr
    (rec,) = [json.loads(x) for x in (tmp_path / "local" / "results.jsonl").read_text()
              .splitlines()]
    assert "ray" not in rec and "executor" not in rec
    assert f"| flat@wgpu | {rec['device']} | wgpu |" in (tmp_path / "local" / "report.md"
                                                         ).read_text()


def test_without_ray_installed_one_line_and_nothing_written(tmp_path, monkeypatch, capsys):
    from rfw.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    out = tmp_path / "o"
    assert main(["bench", "flat", "--executor", "ray", "--out", str(out), *TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["rfw: error: --executor: --executor ray needs Ray, which is not installed: "
                   "pip install 'rfw[scale]' (or: pip install ray)"]
    assert not out.exists()


def test_a_ray_task_hands_its_gpu_to_the_worker_and_leaves_its_environment(tmp_path,
                                                                              monkeypatch):
    # the GPU Ray gave the task reaches the worker process through run_one's env; the Ray
    # worker's own environment (it runs task after task) is not changed
    import types

    from rfw.backend import GPU_ENV
    from rfw.bench import ray_executor, runner

    seen = {}

    def fake_worker(cmd, **kw):  # runner._worker starts every bench worker
        seen["env"] = kw["env"]
        return subprocess.CompletedProcess(cmd, 1, "", "no worker here")

    ctx = types.SimpleNamespace(get_node_id=lambda: "node")
    fake_ray = types.SimpleNamespace(get_gpu_ids=lambda: [2],
                                     get_runtime_context=lambda: ctx)
    monkeypatch.setitem(sys.modules, "ray", fake_ray)
    monkeypatch.setattr(runner, "_worker", fake_worker)
    monkeypatch.setattr(ray_executor, "uuid_of_gpu", lambda g: ("ab" * 15 + f"{int(g):02x}",
                                                                "nvml"))
    monkeypatch.setenv(GPU_ENV, "7")
    job = runner.Job("rfw", "flat", "flat", config="configs/flat.toml")
    plan = runner.Plan([job], (8, 8), 1, 0, 1)
    done = ray_executor.run_task(job, plan, str(tmp_path))
    assert seen["env"][GPU_ENV] == "uuid:" + "ab" * 15 + "02"  # GPU 2, by its UUID
    assert ray_executor.os.environ[GPU_ENV] == "7"
    assert done["record"]["ray"]["gpu_ids"] == ["2"]
    assert done["record"]["error"] == "exit 1: no worker here"
