"""``rfw run --exr``: float outputs as OpenEXR with the executor's float readback bit for bit;
8-bit outputs stay PNG only; a run with no float output is refused in one line (issue 14,
item 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.config import load_config
from rfw.fileio import read_exr, write_exr
from rfw.render import render

from .cli.warm import warm_cli
from .golden_util import changed_share

ROOT = Path(__file__).resolve().parents[1]

# lighting.hdr (rgba16float: values above 1 on the lit courtyard), gbuffer.depth
# (depth32float, read back as float32) and tonemap.ldr (rgba8unorm)
HDR = """\
name = "hdr"
scene = "default"
size = [32, 18]
outputs = ["lighting.hdr", "gbuffer.depth", "tonemap.ldr"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", emissive = "gbuffer.emissive", depth = "gbuffer.depth" }

[[pass]]
name = "tonemap"
inputs = { hdr = "lighting.hdr" }
"""


def bits(a: np.ndarray) -> np.ndarray:
    return a.view({2: np.uint16, 4: np.uint32}[a.dtype.itemsize])


@pytest.fixture(scope="module")
def hdr_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("exr")
    (root / "hdr.toml").write_text(HDR)
    done = warm_cli("run", "hdr.toml", "--exr", "--out", "out", cwd=root)
    assert done.returncode == 0, done.stderr
    return root, done


def test_float_outputs_written_bit_for_bit(hdr_run):
    root, done = hdr_run
    out = root / "out"
    assert sorted(p.name for p in out.iterdir()) == [
        "gbuffer.depth.exr", "gbuffer.depth.png", "lighting.hdr.exr", "lighting.hdr.png",
        "timings.json", "tonemap.ldr.png"]
    assert "tonemap.ldr: rgba8unorm, not float: PNG only (--exr)" in done.stdout
    # the executor's float readback of the same config (lavapipe is deterministic)
    ref = render(load_config(root / "hdr.toml")).images
    hdr, depth = read_exr(out / "lighting.hdr.exr"), read_exr(out / "gbuffer.depth.exr")
    assert hdr.dtype == np.float16 and hdr.shape == (18, 32, 4)
    assert depth.dtype == np.float32 and depth.shape == (18, 32, 1)
    assert np.array_equal(bits(hdr), bits(ref["lighting.hdr"]))
    assert np.array_equal(bits(depth), bits(ref["gbuffer.depth"]))
    # what the EXR keeps and the PNG cannot: values above 1 (the lit stone and sky)
    assert float(ref["lighting.hdr"][..., :3].max()) > 1.0
    assert 0.0 < float(depth.min()) < 1.0

    # negative controls: the comparison sees one ulp of one channel of one pixel, and the
    # 8-bit PNG of the same output (clamped, quantized) does not pass for the floats
    nudged = ref["lighting.hdr"].copy()
    nudged.view(np.uint16)[9, 16, 1] += 1
    assert not np.array_equal(bits(hdr), bits(nudged))
    from PIL import Image

    png = np.asarray(Image.open(out / "lighting.hdr.png")).astype(np.float32) / 255
    assert not np.allclose(png, ref["lighting.hdr"].astype(np.float32), atol=1 / 512)


def test_write_exr_keeps_every_float32_bit(tmp_path):
    # specials (signed zeros, infinities, NaNs) and subnormals survive: the file is the array
    a = np.array([[[0.0, -0.0, np.inf, -np.inf]], [[1e-40, 3.4e38, np.pi, -1.5]],
                  [[np.nan, -np.nan, 65504.0, 6e-8]]], np.float32)
    write_exr(tmp_path / "a.exr", a)
    b = read_exr(tmp_path / "a.exr")
    assert b.dtype == np.float32 and np.array_equal(bits(a), bits(b))
    # an EXR written as half loses float32 precision: the same check sees it
    with np.errstate(over="ignore"):  # 3.4e38 becomes inf in half
        write_exr(tmp_path / "h.exr", a.astype(np.float16))
        # and half NaNs, infinities and the largest half survive too
        write_exr(tmp_path / "h16.exr", a[2:].astype(np.float16))
    assert np.array_equal(bits(a[2:].astype(np.float16)), bits(read_exr(tmp_path / "h16.exr")))
    assert not np.array_equal(bits(a), bits(read_exr(tmp_path / "h.exr").astype(np.float32)))


def test_write_exr_refuses_8bit(tmp_path):
    with pytest.raises(ValueError, match="float16 or float32"):
        write_exr(tmp_path / "a.exr", np.zeros((2, 2, 4), np.uint8))
    assert list(tmp_path.iterdir()) == []


def test_exr_without_float_outputs_is_one_line(tmp_path):
    out = tmp_path / "out"
    done = warm_cli("run", str(ROOT / "configs" / "flat.toml"), "--size", "32x18", "--exr",
                    "--out", str(out), cwd=tmp_path)
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr
    assert lines[0].startswith("rfw: error: ") and "flat.toml: --exr:" in lines[0]
    assert "flat.color: rgba8unorm" in lines[0]
    # nothing that could pass for this run's results, nothing outside --out
    assert not (out / "timings.json").exists() and not (out / "flat.color.png").exists()
    assert {p.name for p in tmp_path.iterdir()} <= {"out"}
    # the same config without --exr runs: the refusal is --exr's
    done = warm_cli("run", str(ROOT / "configs" / "flat.toml"), "--size", "32x18", "--out",
                    str(out), cwd=tmp_path)
    assert done.returncode == 0, done.stderr


def test_stale_exr_removed_by_a_run_without_exr(hdr_run, tmp_path):
    # a run without --exr into a folder with an earlier run's EXRs removes them: they could
    # pass for this run's
    root, _ = hdr_run
    out = tmp_path / "out"
    out.mkdir()
    (out / "lighting.hdr.exr").write_bytes((root / "out" / "lighting.hdr.exr").read_bytes())
    done = warm_cli("run", str(root / "hdr.toml"), "--out", str(out), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not (out / "lighting.hdr.exr").exists() and (out / "lighting.hdr.png").exists()


def test_exr_flag_only_for_run(tmp_path):
    done = warm_cli("view", "--exr", cwd=tmp_path)
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1
    assert "unrecognized arguments: --exr" in done.stderr


def test_save_every_writes_each_frames_float_outputs_as_exr_too(tmp_path):
    (tmp_path / "hdr.toml").write_text(HDR)
    done = warm_cli("run", "hdr.toml", "--exr", "--frames", "3", "--save-every", "1", "--set",
                    "camera.path=orbit", "--out", "out", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    frames = tmp_path / "out" / "frames"
    names = sorted(p.name for p in frames.iterdir())
    # float outputs get an EXR per saved frame beside the PNG; the 8-bit one PNG only
    for k in range(3):
        for out in ("lighting.hdr", "gbuffer.depth"):
            assert f"{out}.{k:04d}.exr" in names and f"{out}.{k:04d}.png" in names
        assert f"tonemap.ldr.{k:04d}.png" in names and f"tonemap.ldr.{k:04d}.exr" not in names
    # the last saved frame is the run's last frame: the same bits as OUT/<output>.exr
    for out in ("lighting.hdr", "gbuffer.depth"):
        last = read_exr(frames / f"{out}.0002.exr")
        assert np.array_equal(bits(last), bits(read_exr(tmp_path / "out" / f"{out}.exr")))
        # negative control: the first frame, from another camera of the orbit, differs
        # (measured: 80 % of the HDR pixels and all of the depth by more than 0.001)
        first = read_exr(frames / f"{out}.0000.exr")
        assert changed_share(first, last, over=1e-3) > 0.25, out
    # a run without --exr leaves no EXR of an earlier run among its frames
    done = warm_cli("run", "hdr.toml", "--frames", "2", "--save-every", "1", "--out", "out",
                    cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not list(frames.glob("*.exr"))
