"""RFW_GPU (RunOptions.gpu): which of the machine's devices a backend opens, as a Ray
task of ``rfw bench --executor ray`` sets it to the GPU Ray gave it. Index 0 renders what the
default does on both backends, and an index past the machine's devices (99; lavapipe has one
CPU device, an H200 machine one GPU or more) is refused in one line; the choice among
several GPUs is checked on a fake device list."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.backend import pick_gpu
from rfw.errors import RfwError

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp: Path, backend: str, gpu: str | None, out: str) -> subprocess.CompletedProcess:
    return warm_cli("run", ROOT / "configs" / "flat.toml", "--size", "32x18", "--backend",
                    backend, "--out", tmp / out, env={"RFW_GPU": gpu})


@pytest.mark.parametrize("backend", ["wgpu", "vk"])
def test_the_chosen_device_renders_and_a_missing_one_is_one_line(tmp_path, backend):
    default = _run(tmp_path, backend, None, "default")
    chosen = _run(tmp_path, backend, "0", "zero")
    assert default.returncode == 0 and chosen.returncode == 0, chosen.stderr
    a = np.asarray(Image.open(tmp_path / "default" / "flat.color.png"))
    b = np.asarray(Image.open(tmp_path / "zero" / "flat.color.png"))
    assert np.array_equal(a, b)
    for bad, says in (("99", r"asks for device 99, and this machine has \d+ (GPU|CPU) "
                             r"device\(s\): \S"),
                      ("gpu0", r"expected a device index \(from 0\), uuid:<32 hex digits> "
                               r"or GPU-<uuid>, not 'gpu0'")):
        done = _run(tmp_path, backend, bad, f"bad{bad}")
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2, done.stderr
        assert len(lines) == 1 and "RFW_GPU" in lines[0] and re.search(says, lines[0]), \
            done.stderr
        assert "Traceback" not in done.stderr
        assert not (tmp_path / f"bad{bad}").exists()


def test_gpus_are_counted_before_cpu_devices_in_the_drivers_order():
    devices = [("cpu", "llvmpipe"), ("gpu", "H200 #0"), ("gpu", "H200 #1")]
    assert pick_gpu(devices, 0, "") == "H200 #0"
    assert pick_gpu(devices, 1, "") == "H200 #1"
    with pytest.raises(RfwError, match="has 2 GPU device"):
        pick_gpu(devices, 2, "")
    # negative control: without GPUs, the CPU devices are what is counted
    assert pick_gpu([("cpu", "llvmpipe")], 0, "") == "llvmpipe"
