"""SHA-256 of every config's output images on each backend (not a test): the record that a
refactor (issue 22) leaves every image bit-identical.

    .venv/bin/python benchmarks/image_hashes.py [--size 96x54] [--backends wgpu,vk]
        [--out out/image_hashes.json] [--root TREE]

Each config in ``configs/`` runs through the real CLI (``python -m rfw.cli run CONFIG
--backend B --size S --frames 1``) from ``--root`` (default: this tree; another checkout's
root measures that tree with this machine's venv). A config a backend cannot run is
recorded with its exit code and error line. Compare two files with ``--compare A B``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def hashes(root: Path, size: str, backends: list[str]) -> dict[str, dict]:
    out: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for config in sorted((root / "configs").glob("*.toml")):
            for backend in backends:
                key = f"{config.stem}@{backend}"
                folder = Path(tmp) / key
                p = subprocess.run([sys.executable, "-m", "rfw.cli", "run", str(config),
                                    "--backend", backend, "--size", size, "--frames", "1",
                                    "--out", str(folder)], cwd=root, capture_output=True,
                                   text=True)
                if p.returncode:
                    lines = p.stderr.strip().splitlines()
                    out[key] = {"exit": p.returncode, "error": lines[-1] if lines else ""}
                    continue
                out[key] = {"exit": 0, "images": {
                    png.name: hashlib.sha256(png.read_bytes()).hexdigest()
                    for png in sorted(folder.glob("*.png"))}}
                print(key, "ok", flush=True)
    return out


def compare(a: Path, b: Path) -> int:
    old, new = json.loads(a.read_text()), json.loads(b.read_text())
    differ = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
    for k in differ:
        print(f"differs: {k}: {old.get(k)} -> {new.get(k)}")
    same = len(set(old) & set(new)) - len([k for k in differ if k in old and k in new])
    print(f"{same} of {len(set(old) | set(new))} config@backend entries identical")
    return 1 if differ else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="96x54")
    ap.add_argument("--backends", default="wgpu,vk")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "image_hashes.json")
    ap.add_argument("--root", type=Path, default=ROOT)
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    a = ap.parse_args()
    if a.compare:
        sys.exit(compare(*a.compare))
    result = hashes(a.root.resolve(), a.size, a.backends.split(","))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
