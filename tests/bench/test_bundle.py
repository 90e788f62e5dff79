"""Benchmark bundles through the real CLI on lavapipe: ``rfw bench`` writes ``bundle.tar``,
``rfw bench replay`` re-runs it bit-identically on the same adapter (and names the pixels a
changed config moves), a damaged bundle is refused in one line, and ``rfw bench report
BUNDLE`` writes the bench's report again byte for byte (and another one for another
timestamp)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from rfw.bench.bundle import pack, read_bundle

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--size", "48x48", "--frames", "2", "--warmup", "1", "--repeat", "1",
        "--no-progress"]


@pytest.fixture(scope="module")
def bench(tmp_path_factory) -> Path:
    """One bench of two variants of a copied config, run from a folder of its own."""
    work = tmp_path_factory.mktemp("bundle")
    shutil.copy(ROOT / "configs" / "flat.toml", work / "mini.toml")
    done = warm_cli("bench", "mini.toml", "--vary", "flat.ambient=0.1,0.4", "--out", "b",
                    *TINY, cwd=work, safe_path=True)
    assert done.returncode == 0, done.stderr
    assert (work / "b" / "bundle.tar").is_file()
    return work


def _files(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*")}


def test_bundle_holds_what_defines_the_run(bench):
    b = read_bundle(bench / "b" / "bundle.tar")
    m = b.manifest
    assert m["schema"] == "rfw.bench.bundle" and m["version"] == 1
    assert m["plan"]["size"] == [48, 48] and m["plan"]["frames"] == 2
    job = m["jobs"][0]
    # the config as bytes, not a path; the settings of each variant; the scene by name
    assert b.members[job["config"]["member"]] == (bench / "mini.toml").read_bytes()
    assert [j["sets"] for j in m["jobs"]] == [["flat.ambient=0.1"], ["flat.ambient=0.4"]]
    assert job["scene"]["kind"] == "builtin" and job["scene"]["rfw_version"]
    assert any(name.startswith("passes/flat/flat.frag.glsl") for name in m["spirv"])
    assert m["rfw"]["commit"] and len(m["images"]) == 2
    assert b.members["results.jsonl"] == (bench / "b" / "results.jsonl").read_bytes()


def test_replay_on_the_same_adapter_is_bit_identical(bench):
    before = _files(bench) - _files(bench / "b")
    done = warm_cli("bench", "replay", "b/bundle.tar", "--out", "r", "--no-progress",
                    cwd=bench, safe_path=True)
    assert done.returncode == 0, done.stdout + done.stderr
    verdict = json.loads((bench / "r" / "replay.json").read_text())
    assert verdict["agree"] and len(verdict["images"]) == 2
    assert {i["rule"] for i in verdict["images"]} == {"bit-identical"}
    assert "2 of 2 image(s) agree" in done.stdout
    assert "rfw bench compare" in done.stdout  # timings through compare
    # nothing written outside --out
    after = _files(bench) - _files(bench / "b") - _files(bench / "r") - {bench / "r"}
    assert after == before


def test_a_changed_config_in_a_copy_of_the_bundle_is_found(bench, tmp_path):
    b = read_bundle(bench / "b" / "bundle.tar")
    member = b.manifest["jobs"][0]["config"]["member"]
    # negative control: the same bundle with a narrower camera in its config
    b.members[member] += b"\n[camera]\nyfov = 0.2\n"
    pack(tmp_path / "changed.tar", b.manifest, b.members)
    done = warm_cli("bench", "replay", tmp_path / "changed.tar", "--out", tmp_path / "r",
                    "--no-progress", cwd=tmp_path, safe_path=True)
    assert done.returncode == 1, done.stdout + done.stderr
    verdict = json.loads((tmp_path / "r" / "replay.json").read_text())
    bad = [i for i in verdict["images"] if not i["agree"]]
    assert len(bad) == 2 and all(i["pixels"] > 0.05 * i["of"] for i in bad)
    assert "pixels differ" in done.stdout and "first at (" in done.stdout
    assert "config changed" in done.stdout  # compare names the input too


def test_a_damaged_bundle_is_refused_in_one_line(bench, tmp_path):
    data = bytearray((bench / "b" / "bundle.tar").read_bytes())
    at = data.index(b'"variant": ')  # inside results.jsonl's bytes
    data[at + 1] ^= 0x20
    (tmp_path / "flipped.tar").write_bytes(bytes(data))
    (tmp_path / "cut.tar").write_bytes(bytes(data[:3000]))
    for name, why in (("flipped.tar", "damaged: results.jsonl does not match its sha256"),
                      ("cut.tar", "not a readable bundle")):
        done = warm_cli("bench", "replay", name, "--out", "r", cwd=tmp_path, safe_path=True)
        assert done.returncode == 2, done.stdout + done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and why in lines[0], done.stderr
        assert not (tmp_path / "r").exists()
    done = warm_cli("bench", "report", "flipped.tar", "--out", "r", cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 2 and "Traceback" not in done.stderr


def test_report_from_the_bundle_is_byte_identical(bench, tmp_path):
    done = warm_cli("bench", "report", bench / "b" / "bundle.tar", "--out", tmp_path / "a",
                    cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stdout + done.stderr
    for name in ("report.md", "report.html"):
        assert (tmp_path / "a" / name).read_bytes() == (bench / "b" / name).read_bytes()
    # negative control: one frame's GPU time changed in a copy of the bundle
    b = read_bundle(bench / "b" / "bundle.tar")
    lines = b.members["results.jsonl"].decode().splitlines()
    record = json.loads(lines[0])
    record["passes"][0]["gpu_ms"][0] *= 3.0
    record["frame"]["gpu_ms"][0] *= 3.0
    b.members["results.jsonl"] = ("\n".join([json.dumps(record), *lines[1:]]) + "\n").encode()
    pack(tmp_path / "changed.tar", b.manifest, b.members)
    done = warm_cli("bench", "report", tmp_path / "changed.tar", "--out", tmp_path / "c",
                    cwd=tmp_path, safe_path=True)
    assert done.returncode == 1 and "DIFFERS from the bench's" in done.stdout, done.stdout
    assert (tmp_path / "c" / "report.md").read_bytes() != (bench / "b" / "report.md").read_bytes()
