"""Peak memory and wall time of ``rfw run`` on small texture-heavy glTF files (not a test).

    .venv/bin/python benchmarks/bench_texture_memory.py [--backends vk,wgpu]
        [--cases baseline,16x4096,1x16384,400x4096] [--size 64x64] [--config forward]
        [--work /tmp/rfw-texmem] [--out out/bench_texture_memory.json]

Each case is a glTF under 1 MB (JSON plus its PNGs) whose images are highly compressible:
``16x4096`` (16 distinct 4096x4096 PNGs, one per quad: 2^28 texels, the old limit),
``8x4096`` (8 of them: 2^27), ``1x16384`` (one 16384x16384 PNG), ``1x16384x8192`` (one
16384x8192 PNG: 2^27), ``400x4096`` (400 textures naming one 4096x4096 PNG) and
``baseline`` (the same quad untextured: the process's own floor). Every run is the real CLI
(``python -m rfw.cli run CONFIG --backend B --scene S --size WxH --frames 1``) in a child of
a small wrapper, whose ``RUSAGE_CHILDREN`` ru_maxrss is that child's peak RSS alone. A
refused case prints its one error line. On lavapipe, device memory is host memory, so the
peak includes every texture and its mip chain.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.scene.test_limits import quad_doc, textured  # noqa: E402

_WRAPPER = """
import resource, subprocess, sys
r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
print(r.stderr, end="", file=sys.stderr)
print(f"peak-rss-kib {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}", file=sys.stderr)
sys.exit(r.returncode)
"""


def _png(path: Path, width: int, height: int, k: int) -> None:
    # compressible, but distinct per k (its sha256 differs), with some structure for the mips
    px = np.zeros((height, width, 3), np.uint8)
    px[:, :, 0] = k
    px[::64, :, 1] = 255
    px[:, ::64, 2] = 255
    Image.fromarray(px).save(path, optimize=False, compress_level=9)


def build(case: str, work: Path) -> Path:
    """The case's glTF in its own folder under ``work`` (made once, then reused)."""
    folder = work / case
    scene = folder / "scene.gltf"
    if scene.exists():
        return scene
    folder.mkdir(parents=True, exist_ok=True)
    if case == "baseline":
        doc = quad_doc(1)
    elif case in ("16x4096", "8x4096"):
        n = int(case.split("x")[0])
        for k in range(n):
            _png(folder / f"t{k}.png", 4096, 4096, k)
        doc = textured(quad_doc(n), [f"t{k}.png" for k in range(n)], list(range(n)))
    elif case == "1x16384":
        _png(folder / "big.png", 16384, 16384, 1)
        doc = textured(quad_doc(1), ["big.png"], [0])
    elif case == "1x16384x8192":
        _png(folder / "big.png", 16384, 8192, 1)
        doc = textured(quad_doc(1), ["big.png"], [0])
    elif case == "400x4096":
        _png(folder / "one.png", 4096, 4096, 1)
        doc = textured(quad_doc(400), ["one.png"], [0] * 400)
    else:
        raise SystemExit(f"bench_texture_memory: no case {case!r}")
    scene.write_text(json.dumps(doc))
    return scene


def run(scene: Path, backend: str, size: str, config: str, out: Path) -> dict:
    argv = [sys.executable, "-m", "rfw.cli", "run", f"configs/{config}.toml", "--backend",
            backend, "--scene", str(scene), "--size", size, "--frames", "1", "--out", str(out)]
    start = time.monotonic()
    r = subprocess.run([sys.executable, "-c", _WRAPPER, *argv], cwd=ROOT, capture_output=True,
                       text=True)
    wall = time.monotonic() - start
    lines = r.stderr.splitlines()
    peak = int(lines[-1].split()[1]) / 1024 if lines and lines[-1].startswith("peak-rss") \
        else float("nan")
    errors = [x for x in lines[:-1] if x.startswith("rfw: error:")]
    return {"exit": r.returncode, "peak_mb": round(peak), "wall_s": round(wall, 1),
            "error": errors[0] if errors else (lines[-2] if r.returncode and len(lines) > 1
                                               else "")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backends", default="vk,wgpu")
    ap.add_argument("--cases", default="baseline,16x4096,1x16384,400x4096")
    ap.add_argument("--size", default="64x64")
    ap.add_argument("--config", default="forward")
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "rfw-texmem")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_texture_memory.json")
    a = ap.parse_args()
    rows = []
    print(f"{'case':<14} {'backend':<6} {'input KB':>8} {'exit':>4} {'peak MB':>8} "
          f"{'wall s':>6}  error")
    for case in a.cases.split(","):
        scene = build(case, a.work)
        kb = sum(p.stat().st_size for p in scene.parent.iterdir()) / 1024
        for backend in a.backends.split(","):
            r = run(scene, backend, a.size, a.config, a.work / f"out-{case}-{backend}")
            rows.append({"case": case, "backend": backend, "input_kb": round(kb), **r})
            print(f"{case:<14} {backend:<6} {kb:8.0f} {r['exit']:4} {r['peak_mb']:8} "
                  f"{r['wall_s']:6}  {r['error'][:150]}", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
