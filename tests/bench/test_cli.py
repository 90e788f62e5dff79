"""``rfw bench`` as users run it: a subprocess in another directory, relative paths, exit codes
(0 all ran, 1 some run failed, 2 bad input) and one line per failed run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from rfw.bench.runner import _slug
from rfw.errors import IDENTIFIER

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--size", "64x36", "--frames", "2", "--warmup", "1", "--repeat", "1", "--no-progress"]


@pytest.fixture
def elsewhere(tmp_path) -> Path:
    """A working directory outside the repository with a config copy, a broken scene, and a
    folder named rfw that the runs, started here, must not import."""
    shutil.copy(ROOT / "configs" / "forward.toml", tmp_path / "fwd.toml")
    (tmp_path / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00 cut short")
    (tmp_path / "rfw").mkdir()
    (tmp_path / "rfw" / "__init__.py").write_text("raise SystemExit('the wrong rfw')\n")
    return tmp_path


def records(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]


def test_relative_paths_from_another_directory_and_a_failed_run(elsewhere):
    done = warm_cli("bench", "fwd.toml", "--scene", "default", "--scene", "broken.glb", "--out",
                    "results", *TINY, cwd=elsewhere, safe_path=True)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    out = elsewhere / "results"
    ran = records(out)
    assert [r["variant"] for r in ran] == ["fwd@wgpu default", "fwd@wgpu broken"]
    good, bad = ran
    assert not good.get("error") and good["config_path"] == str(elsewhere / "fwd.toml")
    assert (out / good["image"]).is_file()
    assert bad["error"].startswith("SceneError: ") and str(elsewhere / "broken.glb") in bad["error"]
    assert bad["image"] is None
    # the summary: a count, then one line per failed run, naming the run and why
    tail = done.stderr.strip().splitlines()[-2:]
    assert tail[0] == "rfw bench: 1 of 2 runs failed:"
    assert tail[1].startswith("  fwd@wgpu broken #1: SceneError: ")
    # the report of the run that worked is written, and lists the failure
    text = (out / "report.md").read_text()
    assert "### fwd@wgpu default" in text and "| fwd@wgpu broken | 1 of 1 |" in text
    # compare resolves its folders from the working directory too
    same = warm_cli("bench", "compare", "results", "results/results.jsonl", cwd=elsewhere,
                    safe_path=True)
    assert same.returncode == 0, same.stderr
    assert "0 regression(s), 0 improvement(s)" in same.stdout


def test_all_runs_failing_exits_1_and_leaves_no_stale_image(elsewhere):
    ok = warm_cli("bench", "fwd.toml", "--out", "o", *TINY, cwd=elsewhere, safe_path=True)
    assert ok.returncode == 0, ok.stderr  # negative control of the exit code below
    image = elsewhere / "o" / records(elsewhere / "o")[0]["image"]
    assert image.is_file()
    # the same variant (same run folder) now fails: its old image must not pass for new
    failed = warm_cli("bench", "fwd.toml", "--set", "scene=broken.glb", "--out", "o", *TINY,
                      cwd=elsewhere, safe_path=True)
    assert failed.returncode == 1
    assert "Traceback" not in failed.stderr
    assert "rfw bench: all 1 of 1 runs failed:" in failed.stderr
    (rec,) = records(elsewhere / "o")
    assert rec["error"] and rec["image"] is None
    assert not image.exists()
    assert (elsewhere / "o" / "report.md").is_file()


BAD = {
    "unknown config": (["nosuch"], "nosuch: config: not found"),
    "typo of a config": (["forwrd"], "did you mean 'forward'"),
    "bad --vary": (["fwd.toml", "--vary", "ao"], "--vary: expected KEY=V1,V2,..., not 'ao'"),
    "empty --vary key": (["fwd.toml", "--vary", "=a,b"], "expected KEY=V1,V2"),
    "--repeat 0": (["fwd.toml", "--repeat", "0"], "--repeat: '--repeat' must be between 1"),
    "--frames -1": (["fwd.toml", "--frames", "-1"], "--frames: '--frames' must be between 1"),
    "--frames two": (["fwd.toml", "--frames", "two"], "--frames: invalid int value"),
    "--warmup -1": (["fwd.toml", "--warmup", "-1"], "--warmup: '--warmup' must be between 0"),
    "--timeout nan": (["fwd.toml", "--timeout", "nan"], "--timeout: '--timeout' must be finite"),
    "--reference typo": (["fwd.toml", "--reference", "fwd@wgpv"], "did you mean 'fwd@wgpu'"),
    "--reference index": (["fwd.toml", "--reference", "4"], "--reference: '--reference' must be between"),
    "missing scene": (["fwd.toml", "--scene", "none.glb"], "none.glb: --scene: scene file not"),
    # a name goes through rfw.scene.names, as rfw run's --scene does
    "unknown scene name": (["fwd.toml", "--scene", "dragn"], "did you mean 'dragon'"),
    "bad backend pin": (["fwd.toml@gl"], "expected CONFIG@wgpu or CONFIG@vk"),
    "--out is a file": (["fwd.toml", "--out", "fwd.toml"], "fwd.toml: --out: not a folder"),
    "compare missing": (["compare", "old", "new"], "no results.jsonl here"),
    "compare threshold": (["compare", ".", ".", "--threshold", "-1"], "argument --threshold: must be a finite number at least 0"),
    "report garbage": (["report", "."], "line 1: not JSON"),
    "--ray-address alone": (["fwd.toml", "--ray-address", "auto"],
                            "--ray-address: --ray-address needs --executor ray"),
    "dead ray address": (["fwd.toml", "--executor", "ray", "--ray-address", "127.0.0.1:1"],
                         "--ray-address: nothing answers at 127.0.0.1:1"),
    "bad ray address": (["fwd.toml", "--executor", "ray", "--ray-address", "nohost"],
                        "expected auto, HOST:PORT or ray://HOST:PORT"),
    "bad executor": (["fwd.toml", "--executor", "dask"], "--executor: invalid choice"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_arguments_are_one_line(elsewhere, case):
    args, expected = BAD[case]
    (elsewhere / "results.jsonl").write_text("{not json\n")
    before = sorted(p.name for p in elsewhere.iterdir())
    out = () if "--out" in args else ("--out", "bench_out")
    done = warm_cli("bench", *args, *out, cwd=elsewhere, safe_path=True)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    assert expected in lines[0]
    assert done.stdout == ""  # refused before the "rfw bench: N variant(s)" header
    assert sorted(p.name for p in elsewhere.iterdir()) == before  # nothing written


@pytest.mark.parametrize("label", ["../../etc/x@wgpu", "/abs/path@vk", "..@wgpu", "9 lives!@vk",
                                   "-rf@wgpu", "a\nb@wgpu", "...", ""])
def test_run_folder_names_are_identifiers(label):
    name = _slug(label)
    assert IDENTIFIER.fullmatch(name) and ".." not in name and "/" not in name
