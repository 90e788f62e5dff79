"""The harness end to end: plans, a tiny real run, the report files and their sections."""

from __future__ import annotations

import json

import pytest

from rfw.bench.report import write_report
from rfw.bench.runner import Job, Plan, make_plan
from rfw.cli import main
from rfw.graph import GraphError

from .synthetic import results


def test_schedule_interleaves_and_rotates():
    jobs = [Job("rfw", n, n) for n in "abc"]
    order = [(r, j.label) for r, _, j in Plan(jobs, (8, 8), 1, 0, 3).schedule()]
    assert order == [(0, "a"), (0, "b"), (0, "c"), (1, "b"), (1, "c"), (1, "a"),
                     (2, "c"), (2, "a"), (2, "b")]
    shuffled = Plan(jobs, (8, 8), 1, 0, 4, order="shuffle", seed=5).schedule()
    for r in range(4):  # every repeat runs every job once
        assert sorted(j.label for rr, _, j in shuffled if rr == r) == ["a", "b", "c"]


def test_matrix_of_configs_backends_and_vary():
    plan = make_plan(["deferred", "deferred_ssao_shadows", "meshlet@vk", "deferred@vk"],
                     vary=["ao=on,off"], size=(32, 18), peers=["embree"])
    labels = [j.label for j in plan.jobs]
    assert labels == ["deferred@wgpu", "deferred@vk", "deferred_ssao_shadows[ao=on]@wgpu",
                      "deferred_ssao_shadows[ao=off]@wgpu", "meshlet@vk", "peer:embree"]
    assert any("--vary ao applies to deferred_ssao_shadows only" in n for n in plan.notes)


def test_bad_config_fails_naming_the_file(tmp_path, capsys):
    with pytest.raises(GraphError, match="no_such_config"):
        make_plan(["no_such_config.toml"])
    assert main(["bench", "no_such_config.toml", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "no_such_config.toml" in err and "not found" in err
    with pytest.raises(GraphError, match=r"deferred\.toml"):
        make_plan(["deferred"], vary=["nonsense=a,b"])
    with pytest.raises(GraphError, match=r"deferred_ssao_shadows\.toml"):
        make_plan(["deferred_ssao_shadows"], vary=["ao=maybe"])
    assert main(["bench", "deferred", "--peers", "embre", "--out", str(tmp_path)]) == 2
    assert "did you mean 'embree'" in capsys.readouterr().err


def test_report_sections_from_synthetic_results(tmp_path):
    out = results(tmp_path, {"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.0},
                             "forward@wgpu": {"forward": 8.0}})
    with (out / "results.jsonl").open("a") as f:
        f.write(json.dumps({"kind": "rfw", "variant": "forward@vk", "repeat": 0,
                            "error": "ShaderError: no GLSL twin"}) + "\n")
        f.write(json.dumps({"kind": "peer", "variant": "peer:mitsuba", "repeat": 0,
                            "available": False, "reason": "not installed",
                            "peer_kind": "raycast"}) + "\n")
    md, page = write_report(out)
    text = md.read_text()
    for section in ("# rfw benchmark", "## Frame time per variant", "## Charts",
                    "## Per pass", "### deferred@wgpu", "## Peers",
                    "## Failed and unavailable", "## How this was measured"):
        assert section in text, section
    assert "| forward@vk | 1 of 1 | ShaderError: no GLSL twin |" in text
    assert "unavailable: not installed" in text
    assert (out / "charts" / "passes.png").exists()
    assert "<table>" in page.read_text()


def test_tiny_real_run_writes_results_and_reports(tmp_path, capsys):
    out = tmp_path / "bench"
    rc = main(["bench", "deferred", "forward", "--size", "32x18", "--frames", "2",
               "--warmup", "1", "--repeat", "2", "--peers", "embree", "--no-progress",
               "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert len(lines) == 6  # (2 configs + 1 peer) x 2 repeats
    assert [x["variant"] for x in lines[:3]] == ["deferred@wgpu", "forward@wgpu", "peer:embree"]
    assert [x["variant"] for x in lines[3:]] == ["forward@wgpu", "peer:embree", "deferred@wgpu"]
    run = lines[0]
    assert not run.get("error"), run.get("error")
    for key in ("rfw_commit", "device", "driver", "backend", "config", "settings", "scene",
                "size", "passes", "frame", "memory"):
        assert key in run, key
    assert run["size"] == [32, 18] and run["frames"] == 2
    gbuffer = next(p for p in run["passes"] if p["name"] == "gbuffer")
    assert len(gbuffer["cpu_ms"]) == 2 and gbuffer["stats"]["cpu_ms"]["n"] == 2
    assert len(run["frame"]["wall_ms"]) == 2
    text = (out / "report.md").read_text()
    for section in ("## Frame time per variant", "## Per pass", "### forward@wgpu",
                    "## Images", "∞ (identical)", "## Memory", "## Peers",
                    "### Ray casting"):
        assert section in text, section
    assert (out / "images" / "forward_wgpu.diff.png").exists()
    assert "<img" in (out / "report.html").read_text()
    # the report can be rebuilt from the results alone
    assert main(["bench", "report", str(out), "--reference", "forward@wgpu"]) == 0
    assert "Reference: **forward@wgpu**" in (out / "report.md").read_text()
