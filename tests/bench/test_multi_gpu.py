"""Issue 25's CPU side: Ray tasks on several GPUs, each run on the GPU Ray gave it, proven by
the device UUID it records. One lavapipe plays N GPUs (``RFW_FAKE_GPUS``, synthetic UUIDs),
a fake ``nvidia-smi`` names Ray's GPUs by those UUIDs, and one local Ray with ``num_gpus=2``
(shared by this module's Ray tests) hands them out. Every check has its negative control."""

from __future__ import annotations

import json
import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.backend import fake_uuid
from rfw.bench import gpus
from rfw.bench.ray_executor import check_device
from rfw.golden import mismatch

from ..conftest import ROOT, rfw_cli
from .synthetic import record

TINY = ["--size", "32x18", "--frames", "2", "--warmup", "1", "--no-progress"]
NOBODY = "uuid:" + "0123456789abcdef" * 2


def _dashed(hex32: str) -> str:
    """NVML's spelling of a UUID: GPU-8-4-4-4-12."""
    h = hex32
    return f"GPU-{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"


def _fake_smi(folder: Path, table: list[str]) -> Path:
    """An ``nvidia-smi`` that prints ``index, uuid`` lines from ``table.csv`` beside it."""
    folder.mkdir(parents=True, exist_ok=True)
    smi = folder / "nvidia-smi"
    smi.write_text('#!/bin/sh\ncat "$(dirname "$0")/table.csv"\n')
    smi.chmod(0o755)
    (folder / "table.csv").write_text("".join(f"{i}, {u}\n" for i, u in enumerate(table)))
    return folder


# ---------------------------------------------------------------------------------------------
# the UUID sources of a Ray task (no Ray, no GPU)


def _no_cuda() -> dict[int, str]:
    raise RuntimeError("CUDA is not available (the test hides it)")


def test_nvidia_smi_names_rays_gpu_and_the_sources_fall_through(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pynvml", None)  # no NVML here
    monkeypatch.setattr(gpus, "_cuda", _no_cuda)  # nor CUDA (a GPU machine has it)
    table = [_dashed(fake_uuid(i)) for i in range(4)]
    monkeypatch.setenv("PATH", f"{_fake_smi(tmp_path, table)}{os.pathsep}/usr/bin:/bin")
    assert gpus.uuid_of_gpu("2") == (fake_uuid(2), "nvidia-smi")
    # a GPU the table lacks, then junk where a UUID should be: no guess, and every source's why
    uuid, why = gpus.uuid_of_gpu("7")
    assert uuid is None and "nvidia-smi: no GPU 7 among 4" in why and "nvml:" in why
    assert "cuda: CUDA is not available" in why
    (tmp_path / "table.csv").write_text("0, not-a-uuid\n")
    uuid, why = gpus.uuid_of_gpu("0")
    assert uuid is None and "nvidia-smi gave 'not-a-uuid', not a UUID" in why
    # CUDA_VISIBLE_DEVICES naming GPUs by UUID: Ray's id is the UUID itself
    assert gpus.uuid_of_gpu(_dashed(fake_uuid(5))) == (fake_uuid(5), "ray")


def test_nvml_comes_first_and_cuda_counts_the_visible_devices(monkeypatch):
    handles = {i: f"GPU-{fake_uuid(10 + i)}".encode() for i in range(3)}
    nvml = types.SimpleNamespace(nvmlInit=lambda: None, nvmlShutdown=lambda: None,
                                 nvmlDeviceGetCount=lambda: 3,
                                 nvmlDeviceGetHandleByIndex=lambda i: i,
                                 nvmlDeviceGetUUID=lambda h: handles[h])
    monkeypatch.setitem(sys.modules, "pynvml", nvml)
    assert gpus.uuid_of_gpu("1") == (fake_uuid(11), "nvml")
    # without NVML and nvidia-smi: CUDA, whose ordinal 0 is the first visible device
    monkeypatch.setitem(sys.modules, "pynvml", None)
    monkeypatch.setenv("PATH", "/nonexistent")

    class Driver:
        def devices(self) -> int:
            return 2

        def uuid(self, ordinal: int) -> bytes:
            return bytes.fromhex(fake_uuid(20 + ordinal))

    import rfw.interop

    monkeypatch.setattr(rfw.interop, "cuda", lambda: Driver())
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3,1")
    assert gpus.uuid_of_gpu("1") == (fake_uuid(21), "cuda")  # GPU 1 is ordinal 1 here
    assert gpus.uuid_of_gpu("3") == (fake_uuid(20), "cuda")
    # negative control: the same ordinals without CUDA_VISIBLE_DEVICES are the indices
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    assert gpus.uuid_of_gpu("1") == (fake_uuid(21), "cuda")
    assert gpus.uuid_of_gpu("3")[0] is None


def test_a_run_on_another_device_than_rays_is_an_error():
    def rec(ids: dict) -> dict:
        return {"device_ids": ids, "ray": {"gpu_ids": ["1"], "uuid_asked": fake_uuid(1)}}

    ok = rec({"vk": {"uuid": fake_uuid(1), "index": 1}})
    check_device(ok)
    assert "error" not in ok and ok["ray"]["uuid_rendered"] == {"vk": fake_uuid(1)}
    # negative control: a deliberately wrong device (a mapping that went astray) is caught
    wrong = rec({"vk": {"uuid": fake_uuid(0), "index": 0}})
    check_device(wrong)
    assert wrong["error"] == (f"rendered on another device than Ray's GPU 1 (UUID "
                              f"{fake_uuid(1)}): vk on {fake_uuid(0)}")
    # wgpu reports no UUID: noted as unchecked, not passed off as checked
    blind = rec({"wgpu": {"uuid": None, "uuid_note": "no UUID", "uuid_via": fake_uuid(1)}})
    check_device(blind)
    assert "error" not in blind and blind["ray"]["unchecked"] == {"wgpu": "no UUID"}
    empty = rec({})
    check_device(empty)
    assert "error" in empty  # a record without device ids proves nothing


# ---------------------------------------------------------------------------------------------
# choosing a device by UUID (the CLI, both backends, on two fake devices)


def test_a_uuid_names_one_device_of_either_kind():
    from rfw.backend import pick_gpu
    from rfw.errors import RfwError

    devices = [("cpu", ("llvmpipe", "aa" * 16)), ("gpu", ("H200", "bb" * 16)),
               ("gpu", ("H200", "cc" * 16))]
    uuid_of = lambda d: d[1]  # noqa: E731
    assert pick_gpu(devices, "uuid:" + "cc" * 16, "", uuid_of=uuid_of)[1] == "cc" * 16
    assert pick_gpu(devices, "uuid:" + "aa" * 16, "", uuid_of=uuid_of)[0] == "llvmpipe"
    assert pick_gpu(devices, 1, "", uuid_of=uuid_of)[1] == "cc" * 16  # an index: GPUs only
    with pytest.raises(RfwError, match="no device has UUID dd"):
        pick_gpu(devices, "uuid:" + "dd" * 16, "", uuid_of=uuid_of)
    with pytest.raises(RfwError, match="report no UUID"):  # a backend that cannot tell
        pick_gpu(devices, "uuid:" + "cc" * 16, "H200, H200")


@pytest.mark.parametrize("backend", ["vk", "wgpu"])
def test_a_uuid_picks_its_device_and_one_nobody_has_is_one_line(tmp_path, backend):
    def run(gpu: str, out: str):
        return rfw_cli("run", ROOT / "configs" / "flat.toml", "--size", "32x18", "--backend",
                       backend, "--out", tmp_path / out, tree=True,
                       env={"RFW_GPU": gpu, "RFW_FAKE_GPUS": "2"})

    done = run(f"uuid:{fake_uuid(1)}", "one")
    assert done.returncode == 0, done.stderr
    timings = json.loads((tmp_path / "one" / "timings.json").read_text())
    if backend == "vk":
        assert timings["uuid"] == fake_uuid(1)
    else:  # wgpu has no UUID: it says so, and which index the UUID led to
        assert timings["uuid"] is None and "no device UUID" in timings["uuid_note"]
        assert timings["index"] == 1 and timings["uuid_via"] == fake_uuid(1)
    bad = run(NOBODY, "bad")
    lines = bad.stderr.strip().splitlines()
    assert bad.returncode == 2 and len(lines) == 1, bad.stderr
    assert f"RFW_GPU: no device has UUID {NOBODY[5:]}" in lines[0]
    assert fake_uuid(0) in lines[0] and "Traceback" not in bad.stderr
    assert not (tmp_path / "bad").exists()


# ---------------------------------------------------------------------------------------------
# the report's device-to-device ratios (synthetic records)


def _two_gpu_results(folder: Path, slower: float) -> Path:
    """a@wgpu on GPUs 0 and 1 (4 runs each), GPU 1 ``slower`` times GPU 0's frame; the two
    devices draw the same noise, so at ``slower=1`` they measured the same."""
    lines = []
    for r in range(8):
        gpu = r % 2
        rec = record("a@wgpu", r // 2, {"p": 2.0 * (slower if gpu else 1.0)})
        rec.update(repeat=r, executor="ray", ray={"node": "n", "host": "h", "gpu_ids": [str(gpu)]},
                   device_ids={"wgpu": {"uuid": fake_uuid(gpu)}})
        lines.append(json.dumps(rec) + "\n")
    folder.mkdir(parents=True)
    (folder / "results.jsonl").write_text("".join(lines))
    return folder


def _ratio_row(md: str) -> list[str]:
    section = md.split("### Device against device")[1]
    line = next(x for x in section.splitlines() if x.startswith("| a@wgpu |"))
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_the_ratio_table_says_whether_devices_differ_beyond_their_cis(tmp_path):
    from rfw.bench.report.write import write_report

    same = _two_gpu_results(tmp_path / "same", 1.0)
    write_report(same)
    md = (same / "report.md").read_text()
    row = _ratio_row(md)
    assert row[1] == "synthetic @ h GPU 1" and row[2] == "synthetic @ h GPU 0"
    lo, hi = (float(x) for x in row[4].strip("[]").split(","))
    assert lo < 1.0 < hi and row[5] == "within the noise"
    assert "No variant's devices differ beyond their CIs" in md
    assert f"wgpu: {fake_uuid(1)}" in md  # which UUID each device column rendered on
    # negative control: GPU 1 5 % slower, against 1 % frame noise, is beyond the CIs
    slow = _two_gpu_results(tmp_path / "slow", 1.05)
    write_report(slow)
    md = (slow / "report.md").read_text()
    row = _ratio_row(md)
    assert abs(float(row[3]) - 1.05) < 0.01 and row[5] == "differs"
    assert "Devices differ beyond their CIs: a@wgpu on synthetic @ h GPU 1 (1.05" in md


# ---------------------------------------------------------------------------------------------
# rfw bench --executor ray on a local Ray with two fake GPUs


@pytest.fixture(scope="module")
def two_gpus(tmp_path_factory):
    """A local Ray instance with ``num_gpus=2``, whose workers see two fake GPUs and a fake
    ``nvidia-smi`` naming them; ``rfw bench --ray-address`` sends its tasks there."""
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'rfw[scale]')")
    smi = _fake_smi(tmp_path_factory.mktemp("bin"), [_dashed(fake_uuid(i)) for i in range(2)])
    with pytest.MonkeyPatch.context() as mp:  # the raylet's environment, which workers inherit
        mp.setenv("PATH", f"{smi}{os.pathsep}{os.environ['PATH']}")
        mp.setenv("RFW_FAKE_GPUS", "2")
        mp.setenv("PYTHONPATH", os.pathsep.join(
            [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
        mp.delenv("RFW_GPU", raising=False)
        ray.init(address="local", num_gpus=2, num_cpus=2, include_dashboard=False,
                 log_to_driver=False, logging_level="ERROR")
    try:
        yield ray.get_runtime_context().gcs_address, smi
    finally:
        ray.shutdown()


def test_each_ray_task_renders_on_the_gpu_it_was_given(tmp_path, two_gpus):
    # one test for both backends: under xdist, a module's tests may land on two workers,
    # and each would start a Ray of its own
    address, smi = two_gpus
    for backend in ("vk", "wgpu"):
        _bench_on_two_gpus(tmp_path / backend, address, backend)
    # negative control: nvidia-smi naming Ray's GPUs by UUIDs no device has (a mapping gone
    # wrong): every run is an error saying so, none renders on some other device
    table = (smi / "table.csv").read_text()
    try:
        (smi / "table.csv").write_text(f"0, {_dashed(NOBODY[5:])}\n1, {_dashed(NOBODY[5:])}\n")
        done = rfw_cli("bench", "flat@vk", "--executor", "ray", "--ray-address", address,
                       "--repeat", "2", "--out", "o", *TINY, cwd=tmp_path, tree=True)
    finally:
        (smi / "table.csv").write_text(table)
    assert "Traceback" not in done.stderr
    recs = [json.loads(x) for x in (tmp_path / "o" / "results.jsonl").read_text().splitlines()]
    assert len(recs) == 2 and all(f"no device has UUID {NOBODY[5:]}" in r["error"]
                                  for r in recs), [r.get("error") for r in recs]
    assert not any((tmp_path / "o" / r["image"]).is_file() for r in recs if r.get("image"))


def _bench_on_two_gpus(tmp_path: Path, address: str, backend: str) -> None:
    """One variant, two runs submitted at once to two GPUs: one run on each."""
    tmp_path.mkdir()
    done = rfw_cli("bench", f"flat@{backend}", "--executor", "ray", "--ray-address", address,
                   "--repeat", "2", "--out", "o", *TINY, cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "o"
    recs = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    table = {str(i): fake_uuid(i) for i in range(2)}
    for r in recs:
        assert not r.get("error"), r.get("error")
        where = r["ray"]
        assert where["uuid_source"] == "nvidia-smi"
        assert where["uuid_asked"] == table[where["gpu_ids"][0]]
        ids = r["device_ids"][backend]
        if backend == "vk":  # the device it rendered on is the one Ray gave it
            assert where["uuid_rendered"] == {"vk": table[where["gpu_ids"][0]]}
        else:  # wgpu: no UUID to prove it; the index the UUID led to, and that it is unchecked
            assert ids["uuid"] is None and ids["uuid_via"] == where["uuid_asked"]
            assert ids["index"] == int(where["gpu_ids"][0]) and "wgpu" in where["unchecked"]
    # two tasks at once on two GPUs: one each, so the same variant ran on both devices
    assert sorted(r["ray"]["gpu_ids"][0] for r in recs) == ["0", "1"]
    # negative control: the same records against a swapped mapping fail the check above
    swapped = {"0": table["1"], "1": table["0"]}
    assert all(r["ray"]["uuid_asked"] != swapped[r["ray"]["gpu_ids"][0]] for r in recs)
    # the images of the variant agree across the devices (the golden scheme's bounds) ...
    a, b = (np.asarray(Image.open(out / r["image"]).convert("RGB")) for r in recs)
    assert mismatch(a, b) == ""
    # ... and the scheme rejects a changed picture (negative control)
    changed = a.copy()
    changed[4:14, 8:24] = 255 - changed[4:14, 8:24]
    assert mismatch(changed, b) != ""
    md = (out / "report.md").read_text()
    assert "## Per device" in md and "### Device against device" in md
    row = _ratio_row(md.replace(f"| flat@{backend} |", "| a@wgpu |"))
    assert row[3] == "-" and row[5] == "n=2<6"  # 2 frames, 1 run a device: it says why not


# ---------------------------------------------------------------------------------------------
# benchmarks/bench_gpu_matrix.py's arithmetic (its sessions run on the fake layer by hand)


def test_the_matrix_bench_splits_the_fixed_cost_and_names_the_fake_gpus(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_gpu_matrix",
                                                  ROOT / "benchmarks" / "bench_gpu_matrix.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    recs = [{"elapsed_s": 3.0, "process_s": 2.0, "frame": {"wall_ms": [100.0, 400.0]}},
            {"elapsed_s": 5.0, "process_s": 3.0, "frame": {"wall_ms": [500.0]}},
            {"error": "exit 1", "elapsed_s": 99.0}]  # a failed run counts for nothing
    cost = mod.fixed_cost(recs)
    assert cost == {"fixed_s": 3.5, "start_s": 1.5, "setup_s": 2.0, "runs": 2}
    # its fake nvidia-smi names the GPUs as the fake device layer does
    smi = mod.fake_smi(tmp_path, 3)
    assert gpus.parse_smi((smi / "table.csv").read_text()) == {i: fake_uuid(i) for i in range(3)}
