"""What a benchmark records about itself: the commit (``RFW_COMMIT`` over git), the CPU model
and the GPU clocks where nvidia-smi reports them (none on lavapipe: the report says why)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rfw.bench.report import _clocks
from rfw.bench.runner import NO_CLOCKS, environment, gpu_clocks, parse_clocks
from rfw.errors import RfwError

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
# what nvidia-smi --query-gpu=index,name,clocks.sm,clocks.mem,clocks.max.sm,clocks.max.mem
# --format=csv,noheader,nounits prints on a one-GPU machine
SMI_LINE = "0, NVIDIA H200, 1980, 3201, 1980, 3201"


def fake_smi(folder: Path, stdout: str, rc: int = 0) -> Path:
    """A folder holding an executable ``nvidia-smi`` that prints ``stdout``."""
    folder.mkdir(parents=True, exist_ok=True)
    exe = folder / "nvidia-smi"
    exe.write_text(f"#!/bin/sh\ncat <<'EOF'\n{stdout}\nEOF\nexit {rc}\n")
    exe.chmod(0o755)
    return folder


def head() -> str:
    """git's HEAD, or "" where the copy has no git metadata (as on the GPU machine)."""
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True, check=False).stdout.strip()
    except OSError:
        return ""


def test_commit_from_rfw_commit_when_set(monkeypatch):
    monkeypatch.setenv("RFW_COMMIT", "81badde")
    env = environment()
    assert env["rfw_commit"] == "81badde" and env["rfw_commit_source"] == "RFW_COMMIT"


def test_commit_from_git_when_unset(monkeypatch):
    monkeypatch.delenv("RFW_COMMIT", raising=False)
    env = environment()
    if not head():  # no git here: said so, not guessed
        assert (env["rfw_commit"], env["rfw_commit_source"]) == ("unknown", "none")
    else:
        assert env["rfw_commit_source"] == "git"
        assert env["rfw_commit"].removesuffix("+dirty") == head()
    # negative control: the env var really wins over git
    monkeypatch.setenv("RFW_COMMIT", "0" * 40)
    assert environment()["rfw_commit"] != env["rfw_commit"]


@pytest.mark.parametrize("bad", ["abc def", "a\nb", "-rf", "x" * 101])
def test_a_bad_rfw_commit_is_refused(monkeypatch, bad):
    monkeypatch.setenv("RFW_COMMIT", bad)
    with pytest.raises(RfwError, match=r"^RFW_COMMIT: expected a commit"):
        environment()


def test_cpu_model_is_the_one_proc_cpuinfo_names(monkeypatch):
    names = [line.split(":", 1)[1].strip()
             for line in Path("/proc/cpuinfo").read_text().splitlines()
             if line.startswith("model name")]
    assert names, "no model name in /proc/cpuinfo"
    env = environment()
    assert env["cpu"] == names[0] and env["cpus"] == os.cpu_count()


def test_clocks_parsed_from_nvidia_smi(tmp_path, monkeypatch):
    smi = fake_smi(tmp_path / "bin", SMI_LINE + "\n1, NVIDIA H200, [N/A], 3201, 1980, 3201")
    monkeypatch.setenv("PATH", f"{smi}{os.pathsep}{os.environ['PATH']}")
    clocks = gpu_clocks()
    assert clocks == [
        {"index": 0, "name": "NVIDIA H200", "sm_mhz": 1980, "mem_mhz": 3201,
         "max_sm_mhz": 1980, "max_mem_mhz": 3201},
        {"index": 1, "name": "NVIDIA H200", "sm_mhz": None, "mem_mhz": 3201,
         "max_sm_mhz": 1980, "max_mem_mhz": 3201}]
    assert environment()["gpu_clocks_start"] == clocks


@pytest.mark.parametrize("garbled", [
    "",  # nothing
    "index, name, clocks.current.sm [MHz], clocks.current.memory [MHz]",  # a header line
    "0, NVIDIA H200, 1980, 3201",  # fields missing
    "Failed to initialize NVML: Driver/library version mismatch",
])
def test_garbled_nvidia_smi_gives_no_clocks(garbled):
    assert parse_clocks(garbled) is None
    assert parse_clocks(SMI_LINE) is not None  # positive control


def test_failing_or_missing_nvidia_smi_gives_no_clocks(tmp_path, monkeypatch):
    smi = fake_smi(tmp_path / "bin", SMI_LINE, rc=9)
    monkeypatch.setenv("PATH", str(smi))
    assert gpu_clocks() is None  # it printed a good line, but failed
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert gpu_clocks() is None
    env = environment()
    assert env["gpu_clocks_start"] is None and env["gpu_clocks_note"] == NO_CLOCKS


def test_report_row_of_clocks():
    runs = [{"gpu_clocks": parse_clocks(SMI_LINE)},
            {"gpu_clocks": parse_clocks(SMI_LINE.replace(" 1980, 3201, 1980", " 1755, 3201, 1980"))},
            {"gpu_clocks": parse_clocks(SMI_LINE)}]
    row = _clocks(runs)
    assert row.startswith("GPU 0 NVIDIA H200: SM 1980 MHz (1755-1980) of max 1980 MHz")
    assert _clocks([{"gpu_clocks": None, "gpu_clocks_note": NO_CLOCKS}]) == NO_CLOCKS


def test_the_cli_records_commit_cpu_and_clocks(tmp_path):
    """A real tiny run as on the GPU machine: RFW_COMMIT set, nvidia-smi present."""
    smi = fake_smi(tmp_path / "bin", SMI_LINE)
    path = f"{smi}{os.pathsep}{os.environ['PATH']}"
    done = warm_cli("bench", "deferred", "--size", "32x18", "--frames", "1", "--warmup", "1",
                    "--repeat", "1", "--no-progress", "--out", "b", cwd=tmp_path,
                    env={"RFW_COMMIT": "cafe123", "PATH": path}, safe_path=True)
    assert done.returncode == 0, done.stderr
    (run,) = [json.loads(x) for x in (tmp_path / "b" / "results.jsonl").read_text().splitlines()]
    assert run["rfw_commit"] == "cafe123" and run["rfw_commit_source"] == "RFW_COMMIT"
    assert run["gpu_clocks"] == parse_clocks(SMI_LINE) == run["gpu_clocks_start"]
    assert run["cpu"] == environment()["cpu"]
    text = (tmp_path / "b" / "report.md").read_text()
    assert "`cafe123` (from RFW_COMMIT)" in text
    assert "SM 1980 MHz of max 1980 MHz" in text


def test_the_cli_refuses_a_bad_rfw_commit_before_any_run(tmp_path):
    done = warm_cli("bench", "deferred", "--size", "32x18", "--frames", "1", "--repeat", "1",
                    "--no-progress", "--out", "b", cwd=tmp_path, env={"RFW_COMMIT": "two words"},
                    safe_path=True)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "rfw: error: RFW_COMMIT: expected a commit (one word of letters, digits "
        "and ._+/-, at most 100), not 'two words'"]
    assert not (tmp_path / "b").exists()


def test_bench_meshlets_records_the_same(tmp_path, monkeypatch):
    """benchmarks/bench_meshlets.py's records: RFW_COMMIT, the CPU and the clocks too."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import bench_meshlets
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    smi = fake_smi(tmp_path / "bin", SMI_LINE)
    monkeypatch.setenv("PATH", f"{smi}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("RFW_COMMIT", "feed42")
    env = bench_meshlets.environment()
    assert env["commit"] == "feed42" and env["cpu"] == environment()["cpu"]
    assert env["gpu_clocks_start"] == parse_clocks(SMI_LINE)
    monkeypatch.delenv("RFW_COMMIT")
    short = bench_meshlets.environment()["commit"].removesuffix("-dirty")
    assert short == "unknown" if not head() else len(short) >= 7 and head().startswith(short)
