"""Predicted against allocated transient bytes: ``rfw graph plan`` with a device profile
(no GPU) against the vk executor's heaps (the driver's sizes and alignments). Not a test.

    .venv/bin/python benchmarks/bench_memplan.py [--profile lavapipe|nvidia] \
        [--sizes 1280x720,1920x1080,3840x2160] [--raptor DIR] [--out DIR]

For every run config in ``configs/`` (its auto variants resolved for the device; a config
that needs a capability the device lacks is skipped with one line) and every Raptor graph
(``../shared/data/raptor-graphs/*.json``), at each size:

- allocated: the executor's path without rendering. Configs go through
  ``vkext.fitting.fit_graph`` (what ``rfw run --backend vk`` calls) and ``plan_heaps``
  (the executor's ``_allocate``): real images and buffers bound into real heaps, readback on.
  Raptor graphs have no pass classes, so they are compiled without a capability check and
  placed with ``vkext.memory.memory_options`` + ``place``: the same steps fit_graph takes.
- predicted: the same compile, placed by ``rfw.graph.memory_model.predict`` with the
  profile (``rfw graph plan --device-profile``), and ``generic``: the compiler's own estimate
  (texel bytes, 64 KiB images), what ``rfw graph plan`` prints without a profile.

Writes memplan.md and memplan.json into ``$OUT`` (or ``--out``): one row per graph and size
with both relative errors, the resources whose modelled requirements differ from the
driver's (for calibrating a profile), and a probe of the driver's requirements over heights.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.config import apply_overrides, build, load_config, missing_caps, resolve_auto  # noqa: E402
from rfw.graph import MemoryOptions, compile, load_graph  # noqa: E402
from rfw.graph.compile import place  # noqa: E402
from rfw.graph.memory_model import predict, profile  # noqa: E402
from rfw.graph.memory_model import requirements as modelled  # noqa: E402

SIZES = "1280x720,1920x1080,3840x2160"
# beside the checkout (/work/main -> /work/shared), a worktree's grandparent, inside it, or
# the tests' copy of the same 28 files
RAPTOR = [*(base / "shared" / "data" / "raptor-graphs"
            for base in (ROOT.parent, ROOT.parent.parent, ROOT)), ROOT / "tests" / "data" / "raptor"]


def _size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def _default_profile(device) -> str:
    return "lavapipe" if device.driver_name == "llvmpipe" else "nvidia"


def allocate(plan, device) -> tuple[int, int]:
    """(heap bytes, sum of driver sizes) of the plan's transients, really allocated."""
    from vkext.memory import plan_heaps

    tm = plan_heaps(plan, device, readback=True)
    try:
        return tm.allocated_bytes, sum(p.size for p in tm.placements.values())
    finally:
        tm.destroy()


def measure(kind: str, name: str, base, fitted, device, prof) -> dict:
    """One row: the allocation of ``fitted`` against the predictions from ``base``."""
    from vkext.memory import requirements as driver

    allocated, driver_sum = allocate(fitted, device)
    predicted = predict(base, prof)
    drv, mod = driver(base, device, readback=True), modelled(base, prof, readback=True)
    differ = []
    for r in base.resources:
        if r.name in drv and drv[r.name] != mod[r.name]:
            differ.append({"resource": r.name, "format": r.format, "kind": r.kind,
                           "width": r.width, "height": r.height, "mips": r.mips,
                           "layers": r.layers, "samples": r.samples,
                           "usages": sorted(r.usages), "driver": list(drv[r.name]),
                           "model": list(mod[r.name])})
    return {"_base": base, "kind": kind, "graph": name, "size": f"{base.size[0]}x{base.size[1]}",
            "allocated": allocated, "driver_sizes": driver_sum,
            "predicted": predicted.transient_bytes, "generic": base.transient_bytes,
            "error": (predicted.transient_bytes - allocated) / allocated if allocated else 0.0,
            "generic_error": ((base.transient_bytes - allocated) / allocated
                              if allocated else 0.0),
            "transients": len(drv), "differ": differ}


def config_rows(device, prof, sizes, skips: list[str]) -> list[dict]:
    from vkext.fitting import fit_graph

    rows = []
    for path in sorted((ROOT / "configs").glob("*.toml")):
        cfg = load_config(path)
        cfg, _ = resolve_auto(cfg, device.caps)
        missing = missing_caps(cfg, frozenset(device.caps))
        if missing:
            need = sorted({c for cs in missing.values() for c in cs})
            skips.append(f"{path.name}: the device lacks {', '.join(need)} "
                         f"(passes {', '.join(sorted(missing))})")
            continue
        for w, h in sizes:
            try:
                graph = build(apply_overrides(cfg, [f"size={w}x{h}"])).graph
                fitted, _ = fit_graph(graph, device, readback=True)
                base = compile(graph, caps=device.caps, backend="vk")
                rows.append(measure("config", path.stem, base, fitted, device, prof))
            except Exception as e:  # one line per graph the device refuses
                skips.append(f"{path.name} at {w}x{h}: {type(e).__name__}: "
                             f"{str(e).splitlines()[0]}")
                break
    return rows


def raptor_rows(device, prof, sizes, folder: Path | None, skips: list[str]) -> list[dict]:
    from vkext.memory import memory_options

    if folder is None:
        skips.append("Raptor graphs: no folder (--raptor DIR; looked in "
                     + ", ".join(str(p) for p in RAPTOR) + ")")
        return []
    rows = []
    for path in sorted(folder.glob("*.json")):
        graph = load_graph(path)
        for w, h in sizes:
            try:
                base = compile(replace(graph, size=(w, h)), backend="vk")
                fitted = place(base, memory_options(base, device, base=MemoryOptions(),
                                                    readback=True))
                rows.append(measure("raptor", path.stem, base, fitted, device, prof))
            except Exception as e:
                skips.append(f"{path.name} at {w}x{h}: {type(e).__name__}: "
                             f"{str(e).splitlines()[0]}")
                break
    return rows


def probe(device, prof) -> list[dict]:
    """The driver's requirements over heights and formats the graphs use: what a profile's
    block-height and padding rules are fitted to."""
    from vkext.consts import vk
    from vkext.images import image_create_info, image_usage_flags, vk_format
    from vkext.memory import _requirements2

    out = []
    cases = [("rgba8unorm", ("color", "sampled", "transfer_src")),
             ("rgba16float", ("sampled", "storage", "transfer_src")),
             ("depth32float", ("depth", "sampled", "transfer_src")),
             ("rg16float", ("color", "sampled", "transfer_src"))]
    heights = (1, 7, 8, 9, 16, 17, 32, 33, 64, 65, 100, 128, 129, 200, 256, 257, 720, 800,
               1080, 2160)
    for fmt, usages in cases:
        for w in (1280, 1920, 3840):
            for h in heights:
                try:
                    info = image_create_info(vk_format(fmt, device, usages=usages), w, h,
                                             image_usage_flags(usages))
                    req = _requirements2()
                    vk.vkGetDeviceImageMemoryRequirements(
                        device.device, vk.VkDeviceImageMemoryRequirements(
                            pCreateInfo=info, planeAspect=0), req)
                except Exception as e:
                    out.append({"format": fmt, "error": f"{type(e).__name__}: {e}"})
                    break
                mr = req.memoryRequirements
                out.append({"format": fmt, "usages": list(usages), "width": w, "height": h,
                            "driver": [int(mr.size), int(mr.alignment)],
                            "model": list(prof.image(fmt, w, h, usages=usages))})
    return out


# parameters a profile's fit tries (every combination): what the driver may do differently
GRID = {"nvidia": {"max_block_gobs": (1, 2, 4, 8, 16, 32), "page": (4096, 65536, 131072,
                                                                   2 << 20)},
        "lavapipe": {"cacheline": (32, 64, 128)}}


def fit(rows: list[dict], prof) -> dict:
    """The grid's parameters of ``prof`` with the smallest max |error| over ``rows``: what
    to put in a ``--device-profile FILE.json`` when the defaults are off on a device."""
    import itertools

    grid = {k: sorted(v, key=lambda x, k=k: x != getattr(prof, k))  # ties keep the defaults
            for k, v in GRID.get(prof.name.split(":")[0], {}).items()}
    best = None
    for values in itertools.product(*grid.values()):
        params = dict(zip(grid, values, strict=True))
        cand = replace(prof, **params)
        worst = max((abs(predict(r["_base"], cand).transient_bytes - r["allocated"])
                     / r["allocated"] for r in rows if r["allocated"]), default=0.0)
        if best is None or worst < best["max_error"]:
            best = {"base": prof.name.split(":")[0], **params, "max_error": worst}
    return best or {}


def markdown(result: dict) -> str:
    rows = result["rows"]
    lines = [f"# Predicted vs allocated transient bytes ({result['device']})", "",
             f"profile `{result['profile']}`; {len(rows)} graph sizes; max |error| "
             f"{result['max_error']:.3%} (generic estimate: {result['max_generic_error']:.3%}); "
             f"{result['seconds']:.1f} s", "",
             "| kind | graph | size | allocated B | predicted B | error | generic B | "
             "generic error | resources off |", "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['kind']} | {r['graph']} | {r['size']} | {r['allocated']:,} | "
                     f"{r['predicted']:,} | {r['error']:+.3%} | {r['generic']:,} | "
                     f"{r['generic_error']:+.3%} | {len(r['differ'])}/{r['transients']} |")
    if result.get("fit"):
        f = dict(result["fit"])
        lines += ["", f"Best fit of the profile's parameters over these rows: "
                  f"{json.dumps({k: v for k, v in f.items() if k != 'max_error'})} "
                  f"(max |error| {f['max_error']:.3%}; save it without max_error as a .json "
                  "for --device-profile)"]
    if result["skipped"]:
        lines += ["", "Skipped:", ""] + [f"- {s}" for s in result["skipped"]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", help="device profile (default: lavapipe on llvmpipe, "
                    "else nvidia)")
    ap.add_argument("--sizes", default=SIZES, help=f"WxH,... (default {SIZES})")
    ap.add_argument("--raptor", type=Path, help="folder of Raptor graphs")
    ap.add_argument("--out", type=Path, help="folder for memplan.md/json (default: $OUT, "
                    "else out/memplan)")
    ap.add_argument("--no-probe", action="store_true", help="skip the requirements probe")
    ap.add_argument("--no-fit", action="store_true", help="skip fitting the profile's "
                    "parameters to the rows")
    args = ap.parse_args(argv)
    from vkext import VkDevice

    start = time.perf_counter()
    sizes = [_size(s) for s in args.sizes.split(",") if s]
    folder = args.raptor or next((p for p in RAPTOR if p.is_dir()), None)
    out = args.out or Path(os.environ.get("OUT") or ROOT / "out" / "memplan")
    device = VkDevice(validation=False, label="bench-memplan")
    try:
        prof = profile(args.profile or _default_profile(device))
        skips: list[str] = []
        rows = config_rows(device, prof, sizes, skips) + \
            raptor_rows(device, prof, sizes, folder, skips)
        result = {"device": device.name, "driver": device.describe(), "profile": prof.name,
                  "sizes": [f"{w}x{h}" for w, h in sizes], "rows": rows, "skipped": skips,
                  "max_error": max((abs(r["error"]) for r in rows), default=0.0),
                  "max_generic_error": max((abs(r["generic_error"]) for r in rows),
                                           default=0.0),
                  "probe": [] if args.no_probe else probe(device, prof),
                  "fit": {} if args.no_fit else fit(rows, prof)}
        for r in rows:
            del r["_base"]
    finally:
        device.destroy()
    result["seconds"] = time.perf_counter() - start
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(result)
    (out / "memplan.md").write_text(text)
    (out / "memplan.json").write_text(json.dumps(result, indent=1) + "\n")
    print(text)
    print(f"wrote {out / 'memplan.md'} and memplan.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
