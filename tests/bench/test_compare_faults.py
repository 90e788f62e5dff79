"""``rfw bench compare`` judges only what it can judge: faulty result files are one error line
naming file and line, bad timings are refused naming the field, passes measured on one side
only are listed with their cost, changed inputs are named, and a gate with nothing to compare
fails. Every case runs the real CLI in a subprocess on hand-built results.jsonl files."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.cli.warm import warm_cli

from .synthetic import record
from .test_review_fixes import listing, one_error_line

ROOT = Path(__file__).resolve().parents[2]
BASE = {"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.0, "tonemap": 0.5}}
SHA = {k: c * 64 for k, c in (("config", "a"), ("graph", "b"), ("scene", "c"),
                              ("shaders", "d"))}


def compare(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return warm_cli("bench", "compare", *args, cwd=cwd, tree=True, safe_path=True)


def lines_of(variants: dict[str, dict[str, float]] = BASE, *, repeats: int = 3, seed: int = 0,
             **extra) -> list[dict]:
    return [record(v, r, p, seed=seed, **extra) for r in range(repeats)
            for v, p in variants.items()]


def write(folder: Path, records: list[dict] | None = None, *, text: str | None = None,
          data: bytes | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    if data is None:
        data = (text if text is not None else
                "".join(json.dumps(r) + "\n" for r in records or [])).encode()
    (folder / "results.jsonl").write_bytes(data)
    return folder


# ---------------------------------------------------------------------------------------------
# 1. files that are empty, cut short, garbled, not UTF-8 or nested too deep


def _good_text() -> str:
    return "".join(json.dumps(r) + "\n" for r in lines_of(seed=2))


def _lines(*which: int) -> bytes:
    good = _good_text().encode().split(b"\n")
    return b"".join(good[i] + b"\n" for i in which)


FILES = {
    "empty": (b"", "NEW: no run records (the file is empty)"),
    "blank lines only": (b"\n  \n\n", "NEW: no run records"),
    "last line cut mid-JSON": (_good_text().encode()[:-40], "line 3: cut short"),
    "a garbled line": (("{not json\n" + _good_text()).encode(), "line 1: not JSON"),
    "garbage in the middle": (_lines(0, 1) + b"}{\n" + _lines(2), "line 3: not JSON"),
    "not UTF-8 on line 3": (_lines(0, 1) + b'{"variant": "d\xff"}\n', "line 3: not UTF-8"),
    "nested 100000 deep": (b"[" * 100000 + b"]" * 100000 + b"\n", "line 1: nested too deeply"),
    "a JSON list": (b"[1, 2]\n", "line 1: expected a run record (a JSON object), not a list"),
    "no variant": (b'{"passes": []}\n', "line 1: variant: not a run record (no 'variant')"),
    "a number as variant": (b'{"variant": 3}\n', "variant: expected a variant name, not 3"),
    "unknown kind": (b'{"variant": "x", "kind": "gpu"}\n', "kind: expected 'rfw' or 'peer'"),
}


@pytest.mark.parametrize("case", list(FILES))
def test_faulty_results_file_is_one_line_naming_file_and_line(tmp_path, case):
    data, expected = FILES[case]
    old = write(tmp_path / "old", lines_of(seed=1))
    new = write(tmp_path / "new", data=data)
    before = listing(tmp_path)
    done = compare(tmp_path, "old", "new", "--out", "cmp")
    one_error_line(done, f"rfw: error: {Path('new') / 'results.jsonl'}: ", expected)
    assert done.stdout == ""
    assert listing(tmp_path) == before  # refused before anything is written
    assert old.is_dir() and new.is_dir()


def test_the_old_side_is_named_too(tmp_path):
    write(tmp_path / "old", text="")
    write(tmp_path / "new", lines_of())
    one_error_line(compare(tmp_path, "old", "new"), "old/results.jsonl: OLD: no run records")
    # a results file given as a file, with a cut line
    (tmp_path / "cut.jsonl").write_text(_good_text()[:-1][:-30])
    one_error_line(compare(tmp_path, "cut.jsonl", "new"), "cut.jsonl: line 3: cut short")


def test_a_results_file_that_is_no_regular_file_is_refused(tmp_path):
    write(tmp_path / "old", lines_of())
    (tmp_path / "new").mkdir()
    os.mkfifo(tmp_path / "new" / "results.jsonl")  # a read would block forever
    one_error_line(compare(tmp_path, "old", "new"), "new/results.jsonl: NEW: not a regular file")
    (tmp_path / "new" / "results.jsonl").unlink()
    (tmp_path / "new" / "results.jsonl").mkdir()
    one_error_line(compare(tmp_path, "old", "new"), "not a regular file")


# ---------------------------------------------------------------------------------------------
# 2. timings that are not finite numbers of ms, or not where a list of them belongs


def _with(path: str, value: object) -> list[dict]:
    """BASE's records with ``value`` put at ``path`` of the second one (line 2)."""
    recs = lines_of(seed=2)
    target = recs[1]
    keys = path.split(".")
    for k in keys[:-1]:
        target = target[int(k)] if k.isdigit() else target[k]
    last = keys[-1]
    if last.isdigit():
        target[int(last)] = value
    else:
        target[last] = value
    return recs


TIMINGS = {
    "a string": ("passes.1.gpu_ms.4", "2.0",
                 "line 2: pass 'lighting': gpu_ms[4]: expected a number, not '2.0'"),
    "a bool": ("passes.0.cpu_ms.0", True,
               "line 2: pass 'gbuffer': cpu_ms[0]: expected a number, not true"),
    "NaN": ("passes.1.gpu_ms.0", float("nan"), "gpu_ms[0]: expected a finite number, not nan"),
    "Infinity": ("frame.gpu_ms.3", float("inf"),
                 "line 2: frame.gpu_ms[3]: expected a finite number, not inf"),
    "negative": ("passes.2.gpu_ms.1", -0.25,
                 "pass 'tonemap': gpu_ms[1]: expected a time in ms, at least 0, not -0.25"),
    "a number for a list": ("passes.1.gpu_ms", 2.0,
                            "pass 'lighting': gpu_ms: expected a list of times in ms, not 2.0"),
    "a list of lists": ("passes.1.gpu_ms.0", [2.0, 2.1],
                        "gpu_ms[0]: expected a number, not a list of 2 items"),
    "an object for a list": ("frame.wall_ms", {"median": 3.0},
                             "frame.wall_ms: expected a list of times in ms, not an object"),
    "wall ms a string": ("frame.wall_ms.0", "fast", "frame.wall_ms[0]: expected a number"),
    "passes not a list": ("passes", {"gbuffer": 1.0}, "line 2: passes: expected a list of passes"),
    "a pass without name": ("passes.1", {"gpu_ms": [1.0]},
                            "line 2: passes[1]: expected {name, gpu_ms, cpu_ms}"),
    "a pass listed twice": ("passes.1.name", "gbuffer",
                            "passes[1]: pass 'gbuffer' is listed twice"),
    "no frame": ("frame", None, "line 2: frame: expected {gpu_ms, cpu_ms, wall_ms}, not nothing"),
    "image a number": ("image", 5, "line 2: image: expected a file name, not 5"),
}


@pytest.mark.parametrize("case", list(TIMINGS))
def test_bad_timings_are_refused_naming_file_line_and_field(tmp_path, case):
    path, value, expected = TIMINGS[case]
    write(tmp_path / "old", lines_of(seed=1))
    recs = _with(path, value)
    (tmp_path / "new").mkdir()
    (tmp_path / "new" / "results.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in recs))  # json writes NaN, Infinity as such
    done = compare(tmp_path, "old", "new", "--fail-on-regression")
    one_error_line(done, "new/results.jsonl: ", expected)
    assert "not judged" not in done.stdout and done.stdout == ""


@pytest.mark.parametrize("literal, expected", [
    ("1e400", "expected a finite number, not inf (JSON's Infinity, or a number too large"),
    ("-1e400", "expected a finite number, not -inf"),
    ("1" * 401, "expected a finite number, not an integer of 401 digits"),
])
def test_numbers_json_reads_as_infinite_are_refused(tmp_path, literal, expected):
    write(tmp_path / "old", lines_of(seed=1))
    text = _good_text().replace('"gpu_ms": [', f'"gpu_ms": [{literal}, ', 1)
    write(tmp_path / "new", text=text)
    one_error_line(compare(tmp_path, "old", "new"),
                   f"new/results.jsonl: line 1: pass 'gbuffer': gpu_ms[0]: {expected}")


def test_failed_runs_are_not_read_for_times(tmp_path):
    # negative control: a failed run's record holds no times, and that is no error
    recs = lines_of(seed=2)
    recs.append({"variant": "deferred@wgpu", "kind": "rfw", "repeat": 3,
                 "error": "timed out after 600 s", "passes": "garbage"})
    write(tmp_path / "old", lines_of(seed=1))
    write(tmp_path / "new", recs)
    done = compare(tmp_path, "old", "new", "--fail-on-regression")
    assert done.returncode == 0, done.stderr
    assert "0 regression(s)" in done.stdout


# ---------------------------------------------------------------------------------------------
# 3. --threshold and nothing to compare


@pytest.mark.parametrize("value", ["nan", "inf", "-0.1", "-inf", "five"])
def test_threshold_must_be_finite_and_not_negative(tmp_path, value):
    write(tmp_path / "old", lines_of(seed=1))
    write(tmp_path / "new", lines_of(seed=2))
    done = compare(tmp_path, "old", "new", f"--threshold={value}")  # -inf is no option
    one_error_line(done, "rfw bench: argument --threshold: ", value)
    # negative control: a finite threshold, 0 included, compares
    assert compare(tmp_path, "old", "new", "--threshold", "0").returncode == 0


def test_fail_on_regression_fails_when_nothing_is_measured_on_both_sides(tmp_path):
    write(tmp_path / "old", lines_of({"forward@wgpu": {"forward": 4.0}}))
    write(tmp_path / "new", lines_of(BASE))
    done = compare(tmp_path, "old", "new", "--fail-on-regression")
    one_error_line(done, "--fail-on-regression: nothing to compare: no pass or frame time "
                   "was measured on both OLD and NEW", quiet=False)
    # the report still says what each side measured, with its cost
    assert "forward@wgpu: only in OLD" in done.stdout
    assert re.search(r"forward@wgpu frame\.gpu_ms +[34]\.\d{3} +- +- +removed", done.stdout)
    assert re.search(r"deferred@wgpu frame\.gpu_ms +- +12\.\d{3} +- +added", done.stdout)
    # without the gate it is a report, exit 0
    done = compare(tmp_path, "old", "new")
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert "0 regression(s), 0 improvement(s), 0 unchanged of 0 compared" in done.stdout


def test_fail_on_regression_fails_when_every_new_run_failed(tmp_path):
    write(tmp_path / "old", lines_of())
    write(tmp_path / "new", [{"variant": "deferred@wgpu", "kind": "rfw", "repeat": r,
                              "error": "SceneError: broken.glb: not glTF"} for r in range(3)])
    done = compare(tmp_path, "old", "new", "--fail-on-regression")
    one_error_line(done, "--fail-on-regression: nothing to compare", quiet=False)
    assert "deferred@wgpu: every run failed in NEW (3 run(s); first: SceneError: broken.glb" \
        in done.stdout


def test_valid_pair_compares_and_a_real_regression_is_still_flagged(tmp_path):
    # negative controls: the checks refuse nothing a bench writes
    write(tmp_path / "old", lines_of(seed=1))
    write(tmp_path / "same", lines_of(seed=2))
    done = compare(tmp_path, "old", "same", "--fail-on-regression", "--out", "cmp")
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert "0 regression(s), 0 improvement(s)" in done.stdout
    assert "measured in" not in done.stdout and "added" not in done.stdout
    write(tmp_path / "slow", lines_of({"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.6,
                                                         "tonemap": 0.5}}, seed=2))
    done = compare(tmp_path, "old", "slow", "--fail-on-regression")
    assert done.returncode == 1, done.stdout + done.stderr
    assert re.search(r"deferred@wgpu lighting\.gpu_ms +\d\.\d{3} +2\.\d{3} +\+\d\d\.\d% +"
                     r"regression", done.stdout)


# ---------------------------------------------------------------------------------------------
# 4. passes on one side only: listed with their cost and CI, also without --all


def test_added_and_removed_passes_are_listed_with_cost_and_ci(tmp_path):
    write(tmp_path / "old", lines_of({"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.0,
                                                        "fxaa": 0.3}}, seed=1))
    write(tmp_path / "new", lines_of({"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.0,
                                                        "ssao": 1.84}}, seed=2))
    done = compare(tmp_path, "old", "new", "--out", "cmp")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    added = re.search(r"deferred@wgpu ssao\.gpu_ms +- +(1\.8\d\d) +- +added  "
                      r"\[new (\d\.\d{3})-(\d\.\d{3})\]", out)
    assert added, out
    median, lo, hi = map(float, added.groups())
    assert lo <= median <= hi and abs(median - 1.84) < 0.03
    assert re.search(r"deferred@wgpu fxaa\.gpu_ms +0\.\d{3} +- +- +removed  \[old ", out)
    assert "ssao.cpu_ms" not in out  # the cost only, without --all
    assert "1 measured in NEW only, 1 in OLD only" in out.splitlines()[-1]
    md = (tmp_path / "cmp" / "compare.md").read_text()
    row = next(x for x in md.splitlines() if x.startswith("| deferred@wgpu | ssao | gpu_ms |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3:5] == ["-", "-"] and cells[5] == f"{median:.3f}" and cells[-1] == "added"
    assert cells[6] == f"{lo:.3f}-{hi:.3f}"
    assert "| deferred@wgpu | fxaa | gpu_ms |" in md and "removed |" in md
    page = (tmp_path / "cmp" / "compare.html").read_text()
    assert "ssao" in page and "added" in page and "removed" in page
    # --all lists every metric of them
    assert "deferred@wgpu ssao.cpu_ms" in compare(tmp_path, "old", "new", "--all").stdout


def test_a_variant_on_one_side_is_listed_with_its_frame_cost(tmp_path):
    write(tmp_path / "old", lines_of(BASE, seed=1))
    write(tmp_path / "new", lines_of({**BASE, "deferred[ao=on]@wgpu": {"gbuffer": 10.0,
                                                                      "ssao": 1.5}}, seed=2))
    done = compare(tmp_path, "old", "new")
    assert done.returncode == 0, done.stderr
    assert "deferred[ao=on]@wgpu: only in NEW" in done.stdout
    assert re.search(r"deferred\[ao=on\]@wgpu frame\.gpu_ms +- +11\.\d{3} +- +added", done.stdout)


def test_a_metric_one_side_did_not_measure_is_said(tmp_path):
    old = lines_of(seed=1)
    for r in old:  # no timestamps in OLD: CPU times only
        for p in r["passes"]:
            p["gpu_ms"] = []
        r["frame"]["gpu_ms"] = []
    write(tmp_path / "old", old)
    write(tmp_path / "new", lines_of(seed=2))
    done = compare(tmp_path, "old", "new")
    assert re.search(r"deferred@wgpu lighting\.gpu_ms +- +\d\.\d{3} +- +not measured in OLD",
                     done.stdout), done.stdout


# ---------------------------------------------------------------------------------------------
# 5. inputs: what changed between OLD and NEW is named


def _inputs(**changed: str) -> dict:
    files = {"passes/tonemap/tonemap.comp.glsl": "1" * 64, "shaders/common/color.glsl": "2" * 64}
    files.update({k: v for k, v in changed.items() if "/" in k})
    return {"inputs": {**SHA, **{k: v for k, v in changed.items() if "/" not in k}},
            "config_path": str(ROOT / "configs" / "deferred.toml"), "shader_files": files}


def test_changed_inputs_are_reported(tmp_path):
    write(tmp_path / "old", lines_of(seed=1, **_inputs()))
    write(tmp_path / "same", lines_of(seed=2, **_inputs()))
    write(tmp_path / "new", lines_of(seed=2, **_inputs(
        config="e" * 64, shaders="f" * 64, **{"shaders/common/color.glsl": "3" * 64})))
    done = compare(tmp_path, "old", "new", "--out", "cmp")
    assert done.returncode == 0, done.stderr
    assert "  input: config changed: configs/deferred.toml (sha aaaaaaaaaaaa -> eeeeeeeeeeee)" \
        in done.stdout
    assert "  input: shaders changed: shaders/common/color.glsl (sha dddddddddddd -> " \
        "ffffffffffff)" in done.stdout
    assert "graph changed" not in done.stdout and "scene changed" not in done.stdout
    md = (tmp_path / "cmp" / "compare.md").read_text()
    assert "- config changed: configs/deferred.toml (sha aaaaaaaaaaaa -> eeeeeeeeeeee)" in md
    # negative control: the same inputs are no change
    done = compare(tmp_path, "old", "same")
    assert "  input: unchanged (config, graph, scene, shaders)" in done.stdout
    assert "changed:" not in done.stdout


def test_graph_and_scene_changes_name_the_variant_and_the_scene(tmp_path):
    write(tmp_path / "old", lines_of(seed=1, **_inputs()))
    write(tmp_path / "new", lines_of(seed=2, **_inputs(graph="9" * 64, scene="8" * 64)))
    out = compare(tmp_path, "old", "new").stdout
    assert "input: graph changed: deferred@wgpu (sha bbbbbbbbbbbb -> 999999999999)" in out
    assert "input: scene changed: courtyard (sha cccccccccccc -> 888888888888)" in out


def test_records_without_inputs_say_inputs_not_recorded(tmp_path):
    write(tmp_path / "old", lines_of(seed=1))  # written before inputs were hashed
    write(tmp_path / "new", lines_of(seed=2, **_inputs()))
    done = compare(tmp_path, "old", "new")
    assert done.returncode == 0, done.stderr
    assert "input: inputs not recorded in OLD" in done.stdout
    assert "not recorded in NEW" not in done.stdout and "unchanged (config" not in done.stdout


def test_inputs_that_changed_during_a_bench_are_said(tmp_path):
    recs = lines_of(seed=2, **_inputs())
    recs[-1] = {**recs[-1], "inputs": {**SHA, "shaders": "7" * 64}}
    write(tmp_path / "old", lines_of(seed=1, **_inputs()))
    write(tmp_path / "new", recs)
    out = compare(tmp_path, "old", "new").stdout
    assert "deferred@wgpu: shaders differs between the runs of NEW" in out


def test_an_input_hash_that_is_not_a_string_is_refused(tmp_path):
    write(tmp_path / "old", lines_of(seed=1))
    write(tmp_path / "new", lines_of(seed=2, inputs={**SHA, "graph": 5}))
    one_error_line(compare(tmp_path, "old", "new"),
                   "line 1: inputs.graph: expected a sha256, not 5")


# ---------------------------------------------------------------------------------------------
# 6. real runs: the worker hashes its inputs, and compare names a config edited between them


def test_real_bench_records_inputs_and_compare_names_an_edited_config(tmp_path):
    config = tmp_path / "deferred.toml"
    shutil.copy(ROOT / "configs" / "deferred.toml", config)
    tiny = ["--size", "32x18", "--frames", "2", "--warmup", "1", "--no-progress"]
    done = warm_cli("bench", "deferred.toml", *tiny, "--repeat", "2", "--out", "A", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    recs = [json.loads(x) for x in (tmp_path / "A" / "results.jsonl").read_text().splitlines()]
    assert len(recs) == 2
    for r in recs:
        assert sorted(r["inputs"]) == ["config", "graph", "scene", "shaders"]
        assert all(re.fullmatch(r"[0-9a-f]{64}", h) for h in r["inputs"].values())
        assert {"passes/tonemap/tonemap.comp.glsl", "passes/gbuffer/gbuffer.vert.glsl",
                "shaders/common/color.glsl"} <= set(r["shader_files"])  # includes too
    assert recs[0]["inputs"] == recs[1]["inputs"]
    # the tonemap's exposure set in the config copy: its bytes and the graph change
    config.write_text(config.read_text().replace('name = "tonemap"\n',
                                                 'name = "tonemap"\nsettings = { exposure = 1.5 }\n'))
    done = warm_cli("bench", "deferred.toml", *tiny, "--repeat", "1", "--out", "B", cwd=tmp_path,
                    tree=True, safe_path=True)
    assert done.returncode == 0, done.stderr
    same = compare(tmp_path, "A", "A")
    assert "input: unchanged (config, graph, scene, shaders)" in same.stdout  # control
    done = compare(tmp_path, "A", "B")
    assert done.returncode == 0, done.stderr
    (new,) = [json.loads(x) for x in (tmp_path / "B" / "results.jsonl").read_text().splitlines()]
    old = recs[0]["inputs"]
    assert f"input: config changed: deferred.toml (sha {old['config'][:12]} -> " \
        f"{new['inputs']['config'][:12]})" in done.stdout
    assert "input: graph changed: deferred@wgpu" in done.stdout
    assert "scene changed" not in done.stdout and "shaders changed" not in done.stdout
