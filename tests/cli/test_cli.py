"""Tests for the ``rfw`` command line (rfw/cli.py).

Almost everything calls ``rfw.cli.main([...])`` in-process and reads stdout/stderr through
capsys; one test runs the installed console script to prove the entry point works.

Contract checked for bad input: exit status 2, nothing on stdout, exactly one line on
stderr that starts with ``rfw: error:`` and names the file (and the pass and slot where
there is one), never a traceback.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rfw import cli

ROOT = Path(__file__).resolve().parents[2]
RAPTOR_DIR = ROOT / "tests" / "data" / "raptor"
RAPTOR_FILES = sorted(RAPTOR_DIR.glob("*.json"))
RAPTOR_IDS = [p.stem for p in RAPTOR_FILES]
DEFERRED_TOML = ROOT / "configs" / "deferred.toml"

PLAN_KEYS = {"order", "culled", "disabled", "resources", "heaps", "transient_bytes",
             "unaliased_bytes", "lower_bound_bytes", "raptor_reuse_bytes", "barriers",
             "step_barriers", "parallel_levels", "queues", "diagnostics"}
RESOURCE_KEYS = {"name", "kind", "format", "width", "height", "bytes", "heap", "offset",
                 "first", "last", "transient"}
TOTALS = ("transient_bytes", "unaliased_bytes", "lower_bound_bytes", "raptor_reuse_bytes")


# ---------------------------------------------------------------------------------------------
# helpers


def rfw(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    """Run the CLI in-process: (exit status, stdout, stderr). argparse exits are caught;
    any other exception propagates and fails the test (it would be a traceback)."""
    try:
        rc = cli.main([str(a) for a in args])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def plan_json(capsys: pytest.CaptureFixture[str], *args: object) -> dict:
    rc, out, err = rfw(capsys, "graph", "plan", *args, "--json")
    assert rc == 0, err
    return json.loads(out)


def assert_error(rc: int, out: str, err: str, *needles: str) -> str:
    """Exit 2, no stdout, exactly one 'rfw: error:' line naming every needle."""
    assert "Traceback" not in err
    assert rc == 2, (rc, err)
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("rfw: error:"), line
    for needle in needles:
        assert needle in line, (needle, line)
    return line


def raptor_graph(*passes: dict) -> dict:
    return {"name": "tiny", "passes": list(passes)}


def raptor_output(name: str = "color", **extra: object) -> dict:
    return {"type": "attachment", "name": name, "format": "VK_FORMAT_R8G8B8A8_UNORM", **extra}


def write_json(path: Path, data: object) -> Path:
    path.write_text(json.dumps(data, indent=2), encoding="utf-8")
    return path


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def leftovers(directory: Path) -> list[str]:
    """Temp files a failed or successful atomic write might have left behind."""
    return sorted(p.name for p in directory.rglob("*") if p.name.endswith(".tmp"))


# ---------------------------------------------------------------------------------------------
# rfw graph plan --json on every Raptor graph


def test_all_28_raptor_graphs_are_present():
    assert len(RAPTOR_FILES) == 28


@pytest.mark.parametrize("path", RAPTOR_FILES, ids=RAPTOR_IDS)
def test_plan_json_schema(capsys, path):
    rc, out, err = rfw(capsys, "graph", "plan", path, "--json")
    assert rc == 0, err
    assert "Traceback" not in err
    d = json.loads(out)  # exactly one JSON document: json.loads rejects trailing data
    assert isinstance(d, dict)
    assert set(d) == PLAN_KEYS

    order = d["order"]
    assert order and all(isinstance(n, str) for n in order)
    assert len(set(order)) == len(order)

    source = json.loads(path.read_text(encoding="utf-8"))
    declared = [p["name"] for p in source["passes"]]
    disabled = [p["name"] for p in source["passes"] if p.get("enabled", True) is False]
    assert d["disabled"] == disabled
    assert not set(d["disabled"]) & set(order)
    assert not set(d["culled"]) & set(order)
    # every declared pass is scheduled, culled or disabled
    assert set(order) | set(d["culled"]) | set(d["disabled"]) == set(declared)

    names = set()
    for r in d["resources"]:
        assert set(r) == RESOURCE_KEYS, r
        assert r["kind"] in ("image", "buffer")
        assert r["format"] is None or isinstance(r["format"], str)
        assert isinstance(r["width"], int) and isinstance(r["height"], int)
        assert isinstance(r["bytes"], int) and r["bytes"] >= 0
        assert isinstance(r["transient"], bool)
        assert r["first"] is None or r["first"] in order, r
        assert r["last"] is None or r["last"] in order, r
        if r["first"] is not None and r["last"] is not None:
            assert order.index(r["first"]) <= order.index(r["last"]), r
        if r["transient"]:
            assert isinstance(r["heap"], int) and isinstance(r["offset"], int), r
        else:
            assert r["heap"] is None and r["offset"] is None, r
        names.add(r["name"])
    assert len(names) == len(d["resources"])

    for i, h in enumerate(d["heaps"]):
        assert set(h) == {"index", "bytes"}
        assert h["index"] == i and isinstance(h["bytes"], int)
    for r in d["resources"]:
        if r["transient"]:
            assert 0 <= r["heap"] < len(d["heaps"])
            assert r["offset"] + r["bytes"] <= d["heaps"][r["heap"]]["bytes"]

    for key in TOTALS:
        assert isinstance(d[key], int) and d[key] >= 0
    assert d["transient_bytes"] == sum(h["bytes"] for h in d["heaps"])
    assert d["lower_bound_bytes"] <= d["transient_bytes"] <= d["unaliased_bytes"]

    for b in d["barriers"]:
        assert set(b) == {"pass", "resource", "from", "to"}
        assert b["pass"] in order
        assert b["resource"] in names
        assert isinstance(b["from"], dict) and isinstance(b["to"], dict)

    assert sorted(n for level in d["parallel_levels"] for n in level) == sorted(order)
    # no device named: one graphics queue, one submission of the whole order (graph.queues)
    q = d["queues"]
    assert q["queues"] == ["graphics"] and q["mode"] == "off"
    assert [s["passes"] for s in q["submissions"]] == [order] and q["transfers"] == []

    for diag in d["diagnostics"]:
        assert set(diag) == {"level", "message"}
        assert diag["level"] in ("error", "warning", "info")
        assert isinstance(diag["message"], str) and diag["message"]


@pytest.mark.parametrize("path", RAPTOR_FILES, ids=RAPTOR_IDS)
def test_plan_text_lists_passes_in_order_and_totals(capsys, path):
    d = plan_json(capsys, path)
    rc, out, err = rfw(capsys, "graph", "plan", path)
    assert rc == 0, err
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("order ("))
    assert lines[start] == f"order ({len(d['order'])} passes):"
    listed = [line.split()[1] for line in lines[start + 1:start + 1 + len(d["order"])]]
    assert listed == d["order"]
    # and each pass name appears in that order in the whole text
    pos = -1
    for name in d["order"]:
        pos = out.index(name, pos + 1)
    for key in TOTALS:
        total = next(line for line in lines if line.startswith(f"{key}:"))
        assert f"{d[key]:,}" in total, total


# ---------------------------------------------------------------------------------------------
# --size, --output, --no-cull, --no-alias, --strict, --lenient


def _expected_size(out: dict, size: tuple[int, int]) -> tuple[int, int]:
    if "resolution" in out:
        return tuple(out["resolution"])
    sx, sy = out.get("resolution_scale", (1.0, 1.0))
    return int(size[0] * sx), int(size[1] * sy)


@pytest.mark.parametrize("name, fixed", [("chapter12_graph", True), ("chapter10_graph", False)])
def test_size_scales_relative_but_not_fixed_resources(capsys, name, fixed):
    path = RAPTOR_DIR / f"{name}.json"
    source = json.loads(path.read_text(encoding="utf-8"))
    described = {o["name"]: o for p in source["passes"] for o in p.get("outputs", [])
                 if o.get("format")}
    base = {r["name"]: r for r in plan_json(capsys, path)["resources"]}
    big = {r["name"]: r for r in plan_json(capsys, path, "--size", "3840x2160")["resources"]}
    checked = 0
    for rname, out in described.items():
        if rname not in big:
            continue
        assert (base[rname]["width"], base[rname]["height"]) == _expected_size(out, (1280, 800))
        assert (big[rname]["width"], big[rname]["height"]) == _expected_size(out, (3840, 2160))
        assert ("resolution" in out) == fixed
        if fixed:
            assert big[rname]["bytes"] == base[rname]["bytes"]
        else:
            assert big[rname]["bytes"] > base[rname]["bytes"]
        checked += 1
    assert checked >= 5


def test_size_mixed_fixed_and_relative_in_one_graph(capsys, tmp_path):
    # one pass per attachment: a raster pass's attachments must share one size
    g = raptor_graph({"name": "a", "outputs": [raptor_output("fixed", resolution=[512, 256])]},
                     {"name": "b", "outputs": [raptor_output("half",
                                                             resolution_scale=[0.5, 0.5])]},
                     {"name": "c", "outputs": [raptor_output("full")]})
    path = write_json(tmp_path / "mixed.json", g)
    res = {r["name"]: (r["width"], r["height"])
           for r in plan_json(capsys, path, "--size", "3840x2160", "--no-cull")["resources"]}
    assert res == {"fixed": (512, 256), "half": (1920, 1080), "full": (3840, 2160)}


def test_output_culls_passes_that_do_not_feed_it(capsys):
    path = RAPTOR_DIR / "chapter15_graph_ray_tracing.json"
    full = plan_json(capsys, path)
    assert "temporal_anti_aliasing_pass" in full["order"]
    assert "volumetric_fog_pass" in full["order"]
    assert full["culled"] == []

    d = plan_json(capsys, path, "--output", "final")
    for culled in ("temporal_anti_aliasing_pass", "volumetric_fog_pass"):
        assert culled in d["culled"]
        assert culled not in d["order"]
    # the passes that write 'final' survive
    assert {"lighting_pass", "transparent_pass"} <= set(d["order"])
    assert sorted(d["order"] + d["culled"]) == sorted(full["order"])
    assert d["order"] == [n for n in full["order"] if n in d["order"]]  # relative order kept
    rc, out, _ = rfw(capsys, "graph", "plan", path, "--output", "final")
    assert rc == 0
    culled_line = next(line for line in out.splitlines() if line.startswith("culled:"))
    assert "temporal_anti_aliasing_pass" in culled_line
    assert "volumetric_fog_pass" in culled_line

    kept = plan_json(capsys, path, "--output", "final", "--no-cull")
    assert kept["culled"] == []
    assert kept["order"] == full["order"]

    both = plan_json(capsys, path, "--output", "final", "--output", "taa_output")
    assert "temporal_anti_aliasing_pass" in both["order"]


@pytest.mark.parametrize("name", ["chapter4_graph", "chapter15_graph_ray_tracing"])
def test_no_alias_gives_every_transient_its_own_bytes(capsys, name):
    path = RAPTOR_DIR / f"{name}.json"
    aliased = plan_json(capsys, path)
    assert aliased["transient_bytes"] < aliased["unaliased_bytes"]  # aliasing saves here
    d = plan_json(capsys, path, "--no-alias")
    assert d["transient_bytes"] == d["unaliased_bytes"] == aliased["unaliased_bytes"]
    spans = sorted((r["heap"], r["offset"], r["offset"] + r["bytes"])
                   for r in d["resources"] if r["transient"])
    for (h1, _, end), (h2, start, _) in itertools.pairwise(spans):
        assert h1 != h2 or end <= start  # no two transients share bytes


def test_strict_raptor_with_unproduced_inputs_fails(capsys):
    path = RAPTOR_DIR / "chapter10_graph.json"
    line = assert_error(*rfw(capsys, "graph", "plan", path, "--strict"), str(path))
    assert "shading_rate_image" in line or "dummy_resource" in line


@pytest.mark.parametrize("flags", [(), ("--lenient",)], ids=["default", "lenient"])
def test_lenient_raptor_reports_unproduced_inputs_as_warnings(capsys, flags):
    d = plan_json(capsys, RAPTOR_DIR / "chapter10_graph.json", *flags)
    warnings = [x["message"] for x in d["diagnostics"] if x["level"] == "warning"]
    for resource in ("dummy_resource", "shading_rate_image"):
        assert any(resource in w for w in warnings), warnings


def test_strict_and_lenient_are_exclusive(capsys):
    rc, _, err = rfw(capsys, "graph", "plan", RAPTOR_DIR / "chapter4_graph.json", "--strict",
                     "--lenient")
    assert rc == 2 and "not allowed" in err


# ---------------------------------------------------------------------------------------------
# bad input: exit 2 and one line naming file, pass and slot


def test_malformed_json(capsys, tmp_path):
    text = (RAPTOR_DIR / "chapter4_graph.json").read_text(encoding="utf-8")
    path = write(tmp_path / "truncated.json", text[: len(text) // 2])
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "malformed JSON")


def test_malformed_toml(capsys, tmp_path):
    path = write(tmp_path / "broken.toml", 'name = "x"\n[[pass]\nname = "a"\n')
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "malformed TOML")


def test_cycle(capsys, tmp_path):
    path = write(tmp_path / "cycle.toml", """\
name = "cyc"
size = [64, 64]

[[pass]]
name = "alpha"
inputs = { x = "beta.out" }
outputs.out = { type = "texture", format = "rgba8unorm" }

[[pass]]
name = "beta"
inputs = { x = "alpha.out" }
outputs.out = { type = "texture", format = "rgba8unorm" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "cycle", "alpha", "beta", "->")


def test_unknown_format_toml(capsys, tmp_path):
    path = write(tmp_path / "fmt.toml", """\
size = [64, 64]
[[pass]]
name = "alpha"
outputs.color = { type = "texture", format = "rgba8unrom" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "alpha", "color",
                 "'rgba8unrom'", "did you mean", "'rgba8unorm'")


def test_unknown_format_raptor(capsys, tmp_path):
    g = raptor_graph({"name": "draw",
                      "outputs": [raptor_output(format="VK_FORMAT_R8G8B8A8_UNORMM")]})
    path = write_json(tmp_path / "fmt.json", g)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "draw", "color",
                 "VK_FORMAT_R8G8B8A8_UNORMM", "did you mean", "'VK_FORMAT_R8G8B8A8_UNORM'")


@pytest.mark.parametrize("extra, key", [
    ({"resolution": [0, 800]}, "resolution"),
    ({"resolution": [1280, -8]}, "resolution"),
    ({"resolution_scale": [-1, 1]}, "resolution_scale"),
    ({"resolution_scale": [1, 0]}, "resolution_scale"),
], ids=["res-zero", "res-negative", "scale-negative", "scale-zero"])
def test_non_positive_raptor_resolution(capsys, tmp_path, extra, key):
    g = raptor_graph({"name": "draw", "outputs": [raptor_output("color", **extra)]})
    path = write_json(tmp_path / "res.json", g)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "draw", "color", key)


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_missing_file(capsys, tmp_path, suffix):
    path = tmp_path / f"nope{suffix}"
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "not found")


def test_unknown_file_type(capsys, tmp_path):
    path = write(tmp_path / "graph.yaml", "passes: []\n")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), ".yaml")


def test_unknown_pass_type_toml(capsys, tmp_path):
    path = write(tmp_path / "ptype.toml", """\
size = [64, 64]
[[pass]]
name = "alpha"
type = "compte"
outputs.color = { type = "texture", format = "rgba8unorm" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "alpha", "'compte'",
                 "'compute'")


def test_unknown_pass_type_raptor(capsys, tmp_path):
    g = raptor_graph({"name": "draw", "type": "compte", "outputs": [raptor_output()]})
    path = write_json(tmp_path / "ptype.json", g)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "draw", "'compte'",
                 "'compute'")


def test_unknown_key_in_toml_pass(capsys, tmp_path):
    path = write(tmp_path / "key.toml", """\
size = [64, 64]
[[pass]]
name = "alpha"
enabeld = false
outputs.color = { type = "texture", format = "rgba8unorm" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "alpha", "'enabeld'",
                 "did you mean", "'enabled'")


def test_misspelt_input_slot_suggests_the_real_one(capsys, tmp_path):
    path = write(tmp_path / "slot.toml", """\
size = [64, 64]
[[pass]]
name = "gbuffer"
outputs.normal = { type = "texture", format = "rgba16float" }

[[pass]]
name = "lighting"
inputs = { n = "gbuffer.nromal" }
outputs.hdr = { type = "texture", format = "rgba16float" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "lighting", "'n'", "nromal",
                 "did you mean", "'normal'")


def test_duplicate_producers(capsys, tmp_path):
    path = write(tmp_path / "dup.toml", """\
size = [64, 64]
[[pass]]
name = "alpha"
outputs.color = { type = "texture", format = "rgba8unorm", name = "shared" }

[[pass]]
name = "beta"
outputs.color = { type = "texture", format = "rgba8unorm", name = "shared" }
""")
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "alpha", "beta", "'color'",
                 "'shared'")


def test_duplicate_producers_raptor(capsys, tmp_path):
    g = raptor_graph({"name": "first", "outputs": [raptor_output("shared")]},
                     {"name": "second", "outputs": [raptor_output("shared")]})
    path = write_json(tmp_path / "dup.json", g)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), "first", "second", "shared")


def test_unknown_graph_output(capsys):
    path = RAPTOR_DIR / "chapter4_graph.json"
    assert_error(*rfw(capsys, "graph", "plan", path, "--output", "fnal"), str(path), "'fnal'",
                 "'final'")


@pytest.mark.parametrize("size", ["0x5", "5x0", "-1x5", "1920", "axb", "1x2x3"])
def test_bad_size_is_an_argparse_error(capsys, size):
    rc, out, err = rfw(capsys, "graph", "plan", RAPTOR_DIR / "chapter4_graph.json",
                       f"--size={size}")
    assert rc == 2
    assert out == ""
    assert "--size" in err
    assert "Traceback" not in err


def test_run_bad_size_is_an_argparse_error(capsys):
    rc, _, err = rfw(capsys, "run", "--size", "0x5")
    assert rc == 2 and "size must be positive" in err


# malformed values: each must still be one clean error line (exit 2), never a traceback
_R_DRAW = {"name": "draw", "outputs": [raptor_output()]}
BAD_RAPTOR = [
    pytest.param({"passes": [{**_R_DRAW, "type": ["compute"]}]}, "draw", id="pass-type-list"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(load_operation=[1])]}]},
                 "draw", id="load-op-list"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(clear_color=["x"])]}]},
                 "clear_color", id="clear-color-str"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(
        format="VK_FORMAT_D32_SFLOAT", clear_depth="x")]}]}, "clear_depth",
        id="clear-depth-str"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(
        resolution=[float("inf"), 8])]}]}, "resolution", id="resolution-inf"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(
        resolution_scale=[float("nan"), 1])]}]}, "resolution_scale", id="scale-nan"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(
        resolution_scale=[float("inf"), 1])]}]}, "resolution_scale", id="scale-inf"),
    pytest.param({"passes": [{"name": "draw", "outputs": [raptor_output(format=["x"])]}]},
                 "format", id="format-list"),
    pytest.param([1, 2], "graph", id="top-level-list"),
    pytest.param({"passes": "nope"}, "passes", id="passes-str"),
    pytest.param({"passes": [{"name": "draw", "enabled": "no"}]}, "enabled", id="enabled-str"),
    pytest.param({"passes": [{"name": "draw", "outputs": [{"type": "image", "name": "c"}]}]},
                 "image", id="resource-type"),
    pytest.param({"passes": [{"name": "a\nb", "type": "bogus"}]}, "'a\\nb' is not an identifier",
                 id="newline-name"),
]


@pytest.mark.parametrize("data, needle", BAD_RAPTOR)
def test_bad_raptor_values_give_one_error_line(capsys, tmp_path, data, needle):
    # json.dumps writes NaN/Infinity, which Python's json (and so the loader) accepts
    path = write_json(tmp_path / "bad.json", data)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), needle)


_T_HEAD = 'size = [8, 8]\n[[pass]]\nname = "alpha"\n'
BAD_TOML = [
    pytest.param(_T_HEAD + 'outputs.c = { type = "buffer", bytes = 16, usage = 5 }\n',
                 "usage", id="usage-int"),
    pytest.param('size = [inf, 8]\n[[pass]]\nname = "alpha"\n'
                 'outputs.c = { type = "texture", format = "rgba8unorm" }\n', "size",
                 id="size-inf"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "texture", format = "rgba8unorm", '
                 'scale = nan }\n', "scale", id="scale-nan"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "texture", format = "rgba8unorm", '
                 'scale = 1e300 }\n', "scale", id="scale-huge"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "texture", format = "rgba8unorm", '
                 'stages = [[1]] }\n', "stages", id="stages-nested"),
    pytest.param('size = [8, 8]\noutputs = [5]\n[[pass]]\nname = "alpha"\n'
                 'outputs.c = { type = "texture", format = "rgba8unorm" }\n', "outputs",
                 id="graph-outputs-int"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "reference", target = 5 }\n', "target",
                 id="target-int"),
    pytest.param(_T_HEAD + 'enabled = "no"\n'
                 'outputs.c = { type = "texture", format = "rgba8unorm" }\n', "enabled",
                 id="enabled-str"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "texture", format = "rgba8unorm", '
                 'mips = 0 }\n', "mips", id="mips-zero"),
    pytest.param(_T_HEAD + 'inputs = { x = 5 }\n'
                 'outputs.c = { type = "texture", format = "rgba8unorm" }\n', "'x'",
                 id="input-int"),
    pytest.param(_T_HEAD + 'outputs.c = { type = "texture", format = "rgba8unorm", '
                 'load = "wipe" }\n', "wipe", id="load-op"),
    pytest.param('size = [8, 8]\n', "[[pass]]", id="no-passes"),
    pytest.param('[[pass]]\nname = "alpha"\n'
                 'outputs.c = { type = "texture", format = "rgba8unorm" }\n', "size",
                 id="no-size"),
]


@pytest.mark.parametrize("text, needle", BAD_TOML)
def test_bad_toml_values_give_one_error_line(capsys, tmp_path, text, needle):
    path = write(tmp_path / "bad.toml", text)
    assert_error(*rfw(capsys, "graph", "plan", path), str(path), needle)


# ---------------------------------------------------------------------------------------------
# rfw graph dot


def test_dot_to_stdout(capsys):
    rc, out, err = rfw(capsys, "graph", "dot", RAPTOR_DIR / "chapter4_graph.json")
    assert rc == 0, err
    assert out.startswith("digraph")
    assert out.rstrip().endswith("}")
    for name in ("depth_pre_pass", "gbuffer_pass", "lighting_pass", "final"):
        assert name in out


def test_dot_to_file(capsys, tmp_path):
    out_dot = tmp_path / "out.dot"
    rc, out, err = rfw(capsys, "graph", "dot", RAPTOR_DIR / "chapter4_graph.json", "-o", out_dot)
    assert rc == 0, err
    text = out_dot.read_text(encoding="utf-8")
    assert text.startswith("digraph")
    assert "lighting_pass" in text
    svg = tmp_path / "out.svg"
    if shutil.which("dot"):
        assert svg.is_file()
        assert "<svg" in svg.read_text(encoding="utf-8")
        assert str(svg) in out
        assert err == ""
    else:
        assert not svg.exists()
        assert "dot" in err and "not installed" in err
    assert leftovers(tmp_path) == []


def test_dot_without_graphviz_writes_no_svg(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    out_dot = tmp_path / "out.dot"
    rc, _, err = rfw(capsys, "graph", "dot", RAPTOR_DIR / "chapter4_graph.json", "-o", out_dot)
    assert rc == 0
    assert out_dot.read_text(encoding="utf-8").startswith("digraph")
    assert not (tmp_path / "out.svg").exists()
    assert len(err.splitlines()) == 1 and "not installed" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.dot"]


def test_dot_creates_missing_parent_directories(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    out_dot = tmp_path / "a" / "b" / "out.dot"
    rc, _, _ = rfw(capsys, "graph", "dot", RAPTOR_DIR / "chapter4_graph.json", "-o", out_dot)
    assert rc == 0 and out_dot.is_file()


def test_failed_dot_leaves_nothing_behind(capsys, tmp_path):
    bad = write(tmp_path / "bad.toml", 'name = "x"\n[[pass]\n')
    out_dot = tmp_path / "out.dot"
    assert_error(*rfw(capsys, "graph", "dot", bad, "-o", out_dot), str(bad))
    assert not out_dot.exists()
    assert not (tmp_path / "out.svg").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_failed_dot_keeps_an_existing_output_intact(capsys, tmp_path):
    bad = write(tmp_path / "bad.json", "{")
    out_dot = write(tmp_path / "out.dot", "old\n")
    assert_error(*rfw(capsys, "graph", "dot", bad, "-o", out_dot), str(bad))
    assert out_dot.read_text(encoding="utf-8") == "old\n"
    assert leftovers(tmp_path) == []


def test_unwritable_output_fails_cleanly_and_leaves_no_temp(capsys, tmp_path):
    target = tmp_path / "adir"
    target.mkdir()  # os.replace onto a directory fails
    rc, out, err = rfw(capsys, "graph", "convert", RAPTOR_DIR / "chapter4_graph.json",
                       "-o", target)
    assert rc == 2 and out == "" and "Traceback" not in err
    assert len(err.splitlines()) == 1 and err.startswith("rfw: error:")
    assert leftovers(tmp_path) == []
    assert list(target.iterdir()) == []


def test_unwritable_output_error_names_the_target(capsys, tmp_path):
    target = tmp_path / "adir"
    target.mkdir()
    rc, _, err = rfw(capsys, "graph", "convert", RAPTOR_DIR / "chapter4_graph.json",
                     "-o", target)
    assert rc == 2
    assert ".tmp" not in err
    assert str(target) in err


def test_written_files_honour_the_umask(capsys, tmp_path):
    old = os.umask(0o022)
    try:
        rc, _, _ = rfw(capsys, "graph", "convert", RAPTOR_DIR / "chapter4_graph.json",
                       "-o", tmp_path / "x.toml")
    finally:
        os.umask(old)
    assert rc == 0
    assert (tmp_path / "x.toml").stat().st_mode & 0o777 == 0o644


# ---------------------------------------------------------------------------------------------
# rfw graph convert


@pytest.mark.parametrize("name", ["chapter4_graph", "chapter10_graph",
                                  "chapter15_graph_ray_tracing"])
def test_convert_round_trip_plans_alike(capsys, tmp_path, name):
    src = RAPTOR_DIR / f"{name}.json"
    toml = tmp_path / "x.toml"
    rc, out, err = rfw(capsys, "graph", "convert", src, "-o", toml)
    assert rc == 0, err
    assert str(toml) in out
    assert toml.read_text(encoding="utf-8").strip()
    direct = plan_json(capsys, src)
    converted = plan_json(capsys, toml, "--lenient")
    direct.pop("diagnostics")
    converted.pop("diagnostics")
    assert converted == direct
    assert leftovers(tmp_path) == []


def test_convert_to_stdout_matches_file(capsys, tmp_path):
    src = RAPTOR_DIR / "chapter4_graph.json"
    rc, out, _ = rfw(capsys, "graph", "convert", src)
    assert rc == 0
    rfw(capsys, "graph", "convert", src, "-o", tmp_path / "x.toml")
    assert out == (tmp_path / "x.toml").read_text(encoding="utf-8")


def test_convert_bad_input_writes_nothing(capsys, tmp_path):
    bad = write(tmp_path / "bad.json", '{"passes": [')
    out = tmp_path / "x.toml"
    assert_error(*rfw(capsys, "graph", "convert", bad, "-o", out), str(bad))
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


# ---------------------------------------------------------------------------------------------
# rfw run


def test_run_renders_the_default_config_on_the_default_scene(capsys, tmp_path):
    out_dir = tmp_path / "out"
    rc, out, err = rfw(capsys, "run", "--size", "160x90", "--out", out_dir)
    assert rc == 0, err
    assert sorted(p.name for p in out_dir.iterdir()) == ["timings.json", "tonemap.ldr.png"]
    timings = json.loads((out_dir / "timings.json").read_text())
    assert timings["config"] == "deferred" and timings["size"] == [160, 90]
    assert [p["name"] for p in timings["passes"]] == ["gbuffer", "lighting", "tonemap"]
    for word in ("gbuffer", "lighting", "tonemap", "gpu ms", "wrote"):
        assert word in out


def test_run_with_overrides_and_a_mesh_file(capsys, tmp_path):
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    rc, _, err = rfw(capsys, "run", DEFERRED_TOML, "--scene", obj, "--size", "64x48",
                       "--set", "shadow.enabled=true", "--frames", "2",
                       "--out", tmp_path / "o")
    assert rc == 0, err
    timings = json.loads((tmp_path / "o" / "timings.json").read_text())
    assert timings["frames"] == 2 and timings["passes"][0]["name"] == "shadow"


def test_run_bad_set_is_one_line(capsys, tmp_path):
    assert_error(*rfw(capsys, "run", "--set", "lighting.ambeint=2", "--out", tmp_path),
                 "deferred.toml", "did you mean 'ambient'")
    assert list(tmp_path.iterdir()) == []


def test_run_missing_config(capsys, tmp_path):
    path = tmp_path / "nope.toml"
    assert_error(*rfw(capsys, "run", path), str(path), "not found")


def test_no_command_is_an_argparse_error(capsys):
    rc, out, err = rfw(capsys)
    assert rc == 2 and out == "" and "usage" in err


# ---------------------------------------------------------------------------------------------
# the installed entry point


def _console_script() -> list[str]:
    exe = Path(sys.executable).parent / "rfw"
    if exe.is_file() and os.access(exe, os.X_OK):
        return [str(exe)]
    return [sys.executable, "-m", "rfw.cli"]


def test_console_script_entry_point(tmp_path):
    src = RAPTOR_DIR / "chapter4_graph.json"
    done = subprocess.run([*_console_script(), "graph", "plan", str(src), "--json"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert set(json.loads(done.stdout)) == PLAN_KEYS

    bad = write(tmp_path / "bad.json", "{")
    done = subprocess.run([*_console_script(), "graph", "plan", str(bad)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2
    assert done.stdout == ""
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error:") and str(bad) in lines[0]


def test_plan_prints_the_pyramid_barriers_between_its_levels(tmp_path):
    """configs/meshlet.toml: the depth pyramid's levels are steps; the plan shows the barrier
    on mip L - 1 before level L, as text and as JSON."""
    from rfw.config import build, load_config

    config = ROOT / "configs" / "meshlet.toml"
    levels = build(load_config(config)).passes["hiz"].params.levels
    done = subprocess.run([*_console_script(), "graph", "plan", str(config)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    steps = [line for line in done.stdout.splitlines() if line.startswith("  hiz step ")]
    assert steps == [f"  hiz step {lv} (level {lv}) / hiz.pyramid mip {lv - 1}: GENERAL -> "
                     "GENERAL; COMPUTE_SHADER:SHADER_STORAGE_WRITE -> "
                     "COMPUTE_SHADER:SHADER_STORAGE_READ" for lv in range(1, levels)]
    done = subprocess.run([*_console_script(), "graph", "plan", str(config), "--json"],
                          capture_output=True, text=True, timeout=120, check=False)
    plan = json.loads(done.stdout)
    assert [(b["step"], b["mips"]) for b in plan["step_barriers"] if b["pass"] == "hiz"] == \
        [(lv, [lv - 1, 1]) for lv in range(1, levels)]

    # the barriers follow the declaration: a two-level pyramid has one
    text = config.read_text()
    assert text.count('use = "depth_pyramid"\n') == 1
    two = write(tmp_path / "meshlet.toml",
                text.replace('use = "depth_pyramid"\n',
                             'use = "depth_pyramid"\nsettings = { levels = 2 }\n'))
    done = subprocess.run([*_console_script(), "graph", "plan", str(two)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert [line.split(":")[0] for line in done.stdout.splitlines()
            if line.startswith("  hiz step ")] == ["  hiz step 1 (level 1) / hiz.pyramid mip 0"]
