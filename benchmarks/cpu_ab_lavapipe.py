"""Per-pass CPU record time of an earlier tree and this one, runs alternating (not a test).

    .venv/bin/python benchmarks/cpu_ab_lavapipe.py OLD_TREE [--runs 4] [--frames 200]
        [--size 64x36] [--backend wgpu] [--configs flat,deferred_ssao_shadows]

OLD_TREE is a checkout or ``git archive`` of the earlier commit. This machine's venv has
this tree's rfw installed, whose entry points name this tree's modules; the old tree's runs
get a stand-in ``rfw`` distribution first on PYTHONPATH, its entry points read from the old
tree's pyproject.toml. Runs alternate old/new (then new/old), so drift in the machine's
state falls on both sides. Prints the median over runs of each pass's median cpu_ms, in µs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def stand_in(tree: Path, folder: Path) -> Path:
    """A dist-info folder naming ``tree``'s entry points (its pyproject.toml's)."""
    project = tomllib.loads((tree / "pyproject.toml").read_text())["project"]
    info = folder / f"rfw-{project['version']}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: rfw\nVersion: "
                                   f"{project['version']}\n")
    lines = []
    for group, points in project.get("entry-points", {}).items():
        lines.append(f"[{group}]")
        lines += [f"{k} = {v}" for k, v in points.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    return folder


def run(tree: Path, path: str, config: str, args: argparse.Namespace) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as out:
        p = subprocess.run([sys.executable, "-m", "rfw.cli", "run",
                            str(tree / "configs" / f"{config}.toml"), "--backend", args.backend,
                            "--size", args.size, "--frames", str(args.frames), "--out", out],
                           cwd=tree, env={**os.environ, "PYTHONPATH": path},
                           capture_output=True, text=True)
        if p.returncode:
            sys.exit(f"{tree}: {config}: {p.stderr.strip().splitlines()[-1]}")
        timings = json.loads((Path(out) / "timings.json").read_text())
    return {q["name"]: q["cpu_ms"] for q in timings["passes"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--size", default="64x36")
    ap.add_argument("--backend", default="wgpu")
    ap.add_argument("--configs", default="flat,deferred_ssao_shadows")
    args = ap.parse_args()
    old = args.old.resolve()
    configs = args.configs.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"old": (old, f"{stand_in(old, Path(tmp))}{os.pathsep}{old}"),
                 "new": (ROOT, str(ROOT))}
        got: dict[tuple[str, str], list[dict[str, float]]] = {}
        for k in range(args.runs):
            for side in ("old", "new") if k % 2 == 0 else ("new", "old"):
                for config in configs:
                    got.setdefault((side, config), []).append(run(*trees[side], config, args))
    for config in configs:
        for side in ("old", "new"):
            rows = got[(side, config)]
            print(side, config, {n: round(statistics.median(r[n] for r in rows) * 1e3, 1)
                                 for n in rows[0]})


if __name__ == "__main__":
    main()
