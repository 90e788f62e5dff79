"""Cells per hour of a benchmark matrix with 1 GPU and with all of a host's GPUs, in one
session, with the fixed cost per cell (issue 25, item 2).

A cell is one variant x setting x scene of ``rfw bench``; each runs ``--repeat`` times. The
script starts a local Ray instance with ``num_gpus=1``, runs the matrix through
``rfw bench --executor ray --ray-address`` (each task opens its GPU by UUID,
docs/multi-gpu.md), stops it, then does the same with ``num_gpus=N`` (all GPUs, or
``--gpus N``). All runs share one SPIR-V cache (``RFW_CACHE_SPIRV=OUT/spirv``), warmed by an
untimed pass over the matrix first (local executor, one run a cell), so no timed session
pays for compiling shaders and both pay the same; the warm-up's own fixed cost is reported
as the cold one.

The fixed cost per cell comes from the runs' records: ``elapsed_s`` (the worker process,
start to exit) less the timed frames' wall time, split into the process's own start and
finish (``elapsed_s - process_s``: the interpreter, imports, the record) and the render's
set-up (``process_s`` less the timed frames: device, pipelines, scene load, warm-up frames).

    .venv/bin/python benchmarks/bench_gpu_matrix.py --fake 2 --out out/gpu_matrix   # here
    python3 benchmarks/bench_gpu_matrix.py --out $OUT -- --vary ao=off,ssao         # a GPU host

``--fake N`` runs on the fake multi-device layer (``RFW_FAKE_GPUS=N``, one lavapipe shown N
times, a fake ``nvidia-smi`` naming them): it checks the script and the routing, and its
numbers are lavapipe's on this machine's CPUs, shared by every "GPU", never GPU numbers.
Arguments after ``--`` go to ``rfw bench`` as they are (``--vary``, ``--scene``, ``--set``).
Writes ``OUT/gpu_matrix.json`` and ``OUT/gpu_matrix.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from rfw.backend import fake_uuid  # noqa: E402

DEFAULT_CELLS = ["flat@vk", "forward@vk", "deferred@vk", "flat@wgpu"]


def fake_smi(folder: Path, n: int) -> Path:
    """A folder with an ``nvidia-smi`` that names ``n`` GPUs by the fake layer's UUIDs."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = []
    for i in range(n):
        h = fake_uuid(i)
        lines.append(f"{i}, GPU-{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}\n")
    (folder / "table.csv").write_text("".join(lines))
    smi = folder / "nvidia-smi"
    smi.write_text('#!/bin/sh\ncat "$(dirname "$0")/table.csv"\n')
    smi.chmod(0o755)
    return folder


def host_gpus() -> int:
    """The GPUs nvidia-smi lists here (0 without it)."""
    exe = shutil.which("nvidia-smi")
    if exe is None:
        return 0
    done = subprocess.run([exe, "-L"], capture_output=True, text=True, check=False)
    return sum(line.startswith("GPU ") for line in done.stdout.splitlines())


def bench(cells: list[str], out: Path, args: argparse.Namespace, extra: list[str], *,
          executor: str, address: str | None = None, repeat: int | None = None
          ) -> tuple[float, list[dict[str, Any]], str]:
    """One ``rfw bench`` of the matrix: its wall seconds, records and stderr's tail."""
    cmd = [sys.executable, "-m", "rfw.cli", "bench", *cells, "--out", str(out),
           "--size", args.size, "--frames", str(args.frames), "--warmup", str(args.warmup),
           "--repeat", str(repeat or args.repeat), "--executor", executor, "--no-progress",
           *(["--ray-address", address] if address else []), *extra]
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=ROOT)
    wall = time.perf_counter() - t
    results = out / "results.jsonl"
    recs = [json.loads(x) for x in results.read_text().splitlines()] if results.is_file() else []
    return wall, recs, (done.stderr.strip().splitlines() or [""])[-1]


def fixed_cost(recs: list[dict[str, Any]]) -> dict[str, float | None]:
    """Medians over the runs: the whole fixed cost, the process's start and finish, and the
    render's set-up (seconds)."""
    fixed, start, setup = [], [], []
    for r in recs:
        if r.get("error") or "elapsed_s" not in r or "process_s" not in r:
            continue
        frames_s = sum(r.get("frame", {}).get("wall_ms") or []) / 1e3
        fixed.append(r["elapsed_s"] - frames_s)
        start.append(r["elapsed_s"] - r["process_s"])
        setup.append(r["process_s"] - frames_s)

    def med(xs: list[float]) -> float | None:
        return statistics.median(xs) if xs else None

    return {"fixed_s": med(fixed), "start_s": med(start), "setup_s": med(setup),
            "runs": len(fixed)}


def session(gpus: int, cells: list[str], out: Path, args: argparse.Namespace,
            extra: list[str]) -> dict[str, Any]:
    """The matrix on a local Ray instance that has ``gpus`` GPUs."""
    import ray

    ray.init(address="local", num_gpus=gpus, include_dashboard=False, log_to_driver=False,
             logging_level="ERROR")
    try:
        address = ray.get_runtime_context().gcs_address
        wall, recs, tail = bench(cells, out / f"gpus{gpus}", args, extra, executor="ray",
                                 address=address)
    finally:
        ray.shutdown()
    n_cells = len({r.get("variant") for r in recs}) or len(cells)
    used = sorted({g for r in recs for g in (r.get("ray") or {}).get("gpu_ids") or []})
    errors = [r["error"] for r in recs if r.get("error")]
    return {"gpus": gpus, "cells": n_cells, "runs": len(recs), "wall_s": wall,
            "cells_per_hour": n_cells / wall * 3600, "runs_per_hour": len(recs) / wall * 3600,
            "gpu_ids_used": used, "errors": errors[:5], "stderr_tail": tail,
            "uuids": sorted({u for r in recs for u in ((r.get("ray") or {}).get(
                "uuid_rendered") or {}).values() if u}),
            **fixed_cost(recs)}


def markdown(result: dict[str, Any]) -> str:
    s = result["sessions"]
    base = s[0]["wall_s"]
    lines = ["# Cells per hour: 1 GPU against all", "",
             f"{result['host']}; {result['gpus']} GPU(s)"
             + (" on the FAKE layer (one lavapipe shown N times): not GPU numbers"
                if result["fake"] else "") + f"; command: `{result['command']}`", "",
             "| GPUs | cells | runs | wall s | cells/h | runs/h | speed-up | fixed s/cell | "
             "start s | set-up s | GPUs used | errors |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for x in s:
        def f(v: float | None) -> str:
            return "-" if v is None else f"{v:.2f}"
        lines.append(f"| {x['gpus']} | {x['cells']} | {x['runs']} | {x['wall_s']:.1f} | "
                     f"{x['cells_per_hour']:.0f} | {x['runs_per_hour']:.0f} | "
                     f"{base / x['wall_s']:.2f}x | {f(x['fixed_s'])} | {f(x['start_s'])} | "
                     f"{f(x['setup_s'])} | {','.join(x['gpu_ids_used']) or '-'} | "
                     f"{len(x['errors'])} |")
    w = result["warmup"]
    lines += ["", f"Cold SPIR-V cache (the untimed warm-up, one run a cell, local executor): "
              f"fixed {w['fixed_s'] or 0:.2f} s/cell (start {w['start_s'] or 0:.2f}, "
              f"set-up {w['setup_s'] or 0:.2f}); the sessions above share the warmed cache "
              f"({result['spirv_warmed']} SPIR-V modules; the sessions compiled "
              f"{result['spirv_compiled_in_sessions']} more).",
              "", "Wall s is the whole `rfw bench` command (its start, Ray's connection and the "
              "report included); speed-up is the 1-GPU session's wall time over each "
              "session's; the target with 2 GPUs is >= 1.8x (issue 25). Fixed s/cell: a "
              "run's worker process less its timed frames (median over the runs); start: "
              "the process outside the render; set-up: device, pipelines, scene load and "
              "warm-up frames."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    own = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("cells", nargs="*", default=DEFAULT_CELLS, help="variants (rfw bench's)")
    p.add_argument("--out", default="out/gpu_matrix")
    p.add_argument("--gpus", type=int, help="GPUs of the second session (default: all)")
    p.add_argument("--fake", type=int, metavar="N", help="the fake layer with N GPUs")
    p.add_argument("--size", default="64x36")
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args(own)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    n = args.fake or host_gpus()
    if args.gpus:
        n = min(n, args.gpus) if n else 0
    if n < 1:
        print("no GPUs here (nvidia-smi lists none): run with --fake N", file=sys.stderr)
        return 2
    # what the Ray workers (and their bench workers) inherit from the raylets started here
    os.environ["RFW_CACHE_SPIRV"] = str(out / "spirv")
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    if args.fake:
        os.environ["RFW_FAKE_GPUS"] = str(args.fake)
        os.environ["PATH"] = f"{fake_smi(out / 'fake_bin', args.fake)}{os.pathsep}" \
            f"{os.environ['PATH']}"
    _, warm, _ = bench(args.cells, out / "warmup", args, extra, executor="local", repeat=1)
    cache = out / "spirv"
    warmed = len(list(cache.glob("*.spv")))
    sessions = [session(g, args.cells, out, args, extra) for g in dict.fromkeys([1, n])]
    # a warm cache: the sessions compiled nothing the warm-up had not
    compiled = len(list(cache.glob("*.spv"))) - warmed
    result = {"host": f"{platform.node()} ({os.cpu_count()} CPUs)", "gpus": n,
              "fake": bool(args.fake), "command": " ".join(["benchmarks/bench_gpu_matrix.py",
                                                             *argv]),
              "warmup": fixed_cost(warm), "spirv_warmed": warmed,
              "spirv_compiled_in_sessions": compiled, "sessions": sessions}
    (out / "gpu_matrix.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "gpu_matrix.md").write_text(markdown(result))
    print(markdown(result))
    return 0 if all(not x["errors"] for x in sessions) else 1


if __name__ == "__main__":
    sys.exit(main())
