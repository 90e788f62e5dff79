"""The raster peers render rfw's ``flat`` technique: same mesh, camera, size and shading.

``benchmarks/peers/run.py`` (what ``rfw bench --peers`` runs) renders each installed raster
peer at 192x108 on the courtyard, and ``rfw run configs/flat.toml`` renders rfw's image; the
two must agree within ``PSNR_DB``. Measured on lavapipe (Mesa 25.0.7, llvmpipe), wgpu backend:
moderngl 50.6 dB, pyvista/VTK 50.5 dB, pygfx 50.2 dB; every pixel within 1 level but one or
two, where coincident surfaces tie in depth and each renderer resolves the tie its own way
(109 levels; the peers disagree among themselves on such pixels too). At 320x180 no pixel is over 1 level
(80.3, 67.9 and 61.9 dB). pygfx stores colour through an sRGB texture, which costs it up to a
level near white. Negative control: the sun turned 5 degrees about the vertical axis drops
every peer to 35.5 dB.

A peer that is not installed in this environment, or cannot open its context here, is
skipped with the reason (``pip install -e '.[peers]'`` brings moderngl and pygfx; pyvista
is one of rfw's dependencies).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.peers import RASTER

from ..cli.warm import warm_cli
from ..golden_util import read_png

ROOT = Path(__file__).resolve().parents[2]
SIZE = "192x108"
PSNR_DB = 45.0
OVER2_SHARE = 0.001  # pixels more than 2 levels off: depth ties on silhouettes
MODULES = {"moderngl": "moderngl", "pygfx": "pygfx", "pyvista": "vtk"}


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two 8-bit RGB images (inf where identical)."""
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def over2(a: np.ndarray, b: np.ndarray) -> float:
    """The share of pixels more than 2 levels off in some channel."""
    return float((np.abs(a.astype(int) - b.astype(int)).max(-1) > 2).mean())


@pytest.fixture(scope="module")
def flat(tmp_path_factory) -> np.ndarray:
    out = tmp_path_factory.mktemp("flat")
    done = warm_cli("run", "configs/flat.toml", "--size", SIZE, "--frames", "1", "--out", out,
                    cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    return read_png(out / "flat.color.png")[..., :3]


def peer_image(peer: str, out: Path, *sun: str) -> np.ndarray:
    """The peer's image through benchmarks/peers/run.py; skips where the peer cannot run."""
    if importlib.util.find_spec(MODULES[peer]) is None:
        pytest.skip(f"{peer} is not installed (pip install -e '.[peers]')")
    done = subprocess.run([sys.executable, "benchmarks/peers/run.py", peer, "--size", SIZE,
                           "--frames", "1", "--warmup", "0", *sun, "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    record = json.loads((out / "record.json").read_text())
    if not record["available"]:
        pytest.skip(f"{peer} cannot run here: {record['reason']}")
    return read_png(out / "image.png")[..., :3]


def turned_sun() -> str:
    """The courtyard's sun turned 5 degrees about the vertical axis, as --sun DX,DY,DZ."""
    from benchmarks.peers.common import load_scene, sun_direction

    d = np.asarray(sun_direction(load_scene("default")), np.float64)
    a = np.radians(5.0)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return ",".join(f"{v:.6f}" for v in turn @ d)


def test_every_raster_peer_is_covered():
    assert set(MODULES) == set(RASTER)


@pytest.mark.parametrize("peer", RASTER)
def test_peer_renders_rfws_flat_image(peer, flat, tmp_path):
    image = peer_image(peer, tmp_path)
    assert image.shape == flat.shape
    assert flat.std() > 20  # a picture, not a flat field
    assert psnr(image, flat) >= PSNR_DB, f"{peer}: {psnr(image, flat):.2f} dB"
    assert over2(image, flat) <= OVER2_SHARE, f"{peer}: {over2(image, flat):.4f}"


@pytest.mark.parametrize("peer", RASTER)
def test_another_sun_falls_below_the_bound(peer, flat, tmp_path):
    # negative control: the same peer lit from 5 degrees away is another picture
    image = peer_image(peer, tmp_path, "--sun", turned_sun())
    assert psnr(image, flat) < PSNR_DB, f"{peer}: {psnr(image, flat):.2f} dB"


def test_bench_report_states_each_peers_psnr_against_flat(tmp_path):
    peer = next((p for p in RASTER if importlib.util.find_spec(MODULES[p])), None)
    if peer is None:
        pytest.skip("no raster peer is installed (pip install -e '.[peers]')")

    def report(config: str) -> str:
        out = tmp_path / config
        done = warm_cli("bench", config, "--size", "96x54", "--frames", "1", "--warmup", "0",
                        "--repeat", "1", "--peers", peer, "--no-progress", "--out", out, cwd=ROOT)
        assert done.returncode == 0, done.stdout + done.stderr
        return (out / "report.md").read_text()

    text = report("flat")
    if f"| {peer} | -" in text:  # the peer's row without a wall time: it could not run
        pytest.skip(f"{peer} cannot run here")
    line = "PSNR of each peer's image against flat@wgpu's"
    assert line in text
    table = text[text.index(line):].splitlines()[2:5]
    assert table[0] == f"| {peer} |" and table[2].endswith(" dB |"), table
    # negative control: without a flat variant there is nothing to compare with
    assert "PSNR of each peer" not in report("forward")
