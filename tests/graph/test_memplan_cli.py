"""``rfw graph plan --what-if / --budget / --device-profile`` through the real CLI, no GPU."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rfw.graph import compile, load_graph
from rfw.graph.memory_model import PROFILES, predict
from rfw.units import MiB

from ..conftest import rfw_cli

ROOT = Path(__file__).parents[2]
CONFIG = ROOT / "configs" / "deferred_ssao_shadows.toml"
RAPTOR = ROOT / "tests" / "data" / "raptor" / "chapter11_graph.json"
WHAT_IF = ("--what-if", "size=720p,1080p,4k", "--what-if", "ssao.enabled=on,off")


def _json(*args: object) -> dict:
    done = rfw_cli("graph", "plan", *args, "--json", cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _one_line(done, code: int) -> str:
    assert done.returncode == code, (done.returncode, done.stdout, done.stderr)
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def table() -> dict:
    return _json(CONFIG, *WHAT_IF, "--device-profile", "lavapipe")


def test_what_if_is_the_cross_product_and_each_row_is_its_own_plan(table):
    rows = table["combinations"]
    assert [(r["settings"]["size"], r["settings"]["ssao.enabled"]) for r in rows] == [
        (s, a) for s in ("720p", "1080p", "4k") for a in ("on", "off")]
    assert [tuple(r["size"]) for r in rows[::2]] == [(1280, 720), (1920, 1080), (3840, 2160)]
    # ssao's ao image is transient memory: switching it off saves bytes at every size
    for on, off in zip(rows[::2], rows[1::2], strict=True):
        assert off["transient_bytes"] < on["transient_bytes"] <= on["unaliased_bytes"]
    # a row is the single plan of that combination (--set / --size), not a scaled guess
    single = _json(CONFIG, "--size", "1920x1080", "--device-profile", "lavapipe")
    assert rows[2]["transient_bytes"] == single["transient_bytes"]
    assert table["worst"] == rows[4]


def test_the_profile_changes_the_bytes_as_the_model_says(table):
    # the generic estimate (64 KiB-aligned texel bytes) and the lavapipe model differ, and
    # the lavapipe number is the model's own (predict on the compiled plan)
    generic = _json(CONFIG, *WHAT_IF)["combinations"]
    assert all(g["transient_bytes"] != m["transient_bytes"]
               for g, m in zip(generic, table["combinations"], strict=True))
    graph = load_graph(RAPTOR)
    plan = compile(graph, (1280, 720))
    want = predict(plan, PROFILES["nvidia"]).transient_bytes
    got = _json(RAPTOR, "--what-if", "size=720p", "--device-profile", "nvidia")
    assert got["combinations"][0]["transient_bytes"] == want != plan.transient_bytes


def test_budget_just_below_the_worst_fails_and_just_above_passes(table):
    worst = table["worst"]["transient_bytes"] / MiB
    below = rfw_cli("graph", "plan", CONFIG, *WHAT_IF, "--device-profile", "lavapipe",
                    "--budget", f"{worst - 0.01:.2f}", cwd=ROOT)
    line = _one_line(below, 1)
    assert line.startswith("rfw: over budget: size=4k ssao.enabled=on at 3840x2160 needs")
    assert f"{worst:.2f} MiB" in line
    assert "over" in below.stdout.splitlines()[5]  # the table still prints, row marked
    above = rfw_cli("graph", "plan", CONFIG, *WHAT_IF, "--device-profile", "lavapipe",
                    "--budget", f"{worst + 0.01:.2f}", cwd=ROOT)
    assert above.returncode == 0, above.stderr
    assert above.stderr == ""
    assert "over" not in above.stdout


@pytest.mark.parametrize("args, says", [
    (("--what-if", "sssao.enabled=on,off"), "no pass or variant 'sssao'"),
    (("--what-if", "size=720p,8q"), "size=8q"),
    (("--what-if", "size"), "expected KEY=V1,V2"),
    (("--device-profile", "amd"), "unknown device profile 'amd'"),
])
def test_bad_what_if_input_is_one_line_and_exit_2(args, says):
    line = _one_line(rfw_cli("graph", "plan", CONFIG, *args, "--budget", "100", cwd=ROOT), 2)
    assert line.startswith("rfw: error: ") and says in line


def test_a_graph_file_takes_size_and_pass_enabled_only():
    ok = _json(RAPTOR, "--what-if", "size=64x64,4k")
    assert [r["size"] for r in ok["combinations"]] == [[64, 64], [3840, 2160]]
    line = _one_line(rfw_cli("graph", "plan", RAPTOR, "--what-if", "gbuffer_pass.mode=a",
                             cwd=ROOT), 2)
    assert "a graph file takes size and <pass>.enabled" in line
