"""The report's tables of numbers: the environment (with the GPU clocks), frame time per
variant, per pass, memory and culling counters, and the failed and unavailable variants."""

from __future__ import annotations

from typing import Any

from ..summary import VariantSummary, mib
from .devices import device_of
from .document import Doc, ci, ms, spread


def _clocks(records: list[dict[str, Any]]) -> str:
    """SM and memory clocks after each run's frames (median and range over runs, per GPU),
    the maximum the driver allows, or why there are none."""
    by_gpu: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        for g in r.get("gpu_clocks") or []:
            by_gpu.setdefault(f"GPU {g.get('index')} {g.get('name')}", []).append(g)
    if not by_gpu:
        first = records[0] if records else {}
        return first.get("gpu_clocks_note") or "not recorded"

    def mhz(values: list[Any]) -> str:
        v = sorted(x for x in values if isinstance(x, int))
        if not v:
            return "n/a"
        mid = v[len(v) // 2]
        return f"{mid} MHz" + (f" ({v[0]}-{v[-1]})" if v[0] != v[-1] else "")

    parts = [f"{name}: SM {mhz([g.get('sm_mhz') for g in gs])} of max "
             f"{mhz([g.get('max_sm_mhz') for g in gs])}, memory "
             f"{mhz([g.get('mem_mhz') for g in gs])}, after each run's frames "
             f"({len(gs)} runs)" for name, gs in sorted(by_gpu.items())]
    return "; ".join(parts)


def _environment(doc: Doc, records: list[dict[str, Any]], rfw: list[VariantSummary]) -> None:
    first = records[0] if records else {}
    devices = sorted({f"{r.get('device')} — {r.get('driver')} ({r.get('backend')})"
                      for v in rfw for r in v.records})
    source = first.get("rfw_commit_source")
    rows = [["rfw commit", f"`{first.get('rfw_commit', '?')}`"
                           + (f" (from {source})" if source else "")],
            ["device — driver (backend)", "; ".join(devices) or "-"],
            ["GPU clocks", _clocks(records)],
            ["CPU", f"{first.get('cpu', '?')} ({first.get('cpus', '?')} threads)"],
            ["host / python", f"{first.get('host', '?')} / {first.get('python', '?')} / "
                              f"{first.get('platform', '?')}"],
            ["size", "x".join(str(v) for v in first.get("size", []))],
            ["frames per run / warm-up / per peer run",
             f"{first.get('frames')} / {first.get('warmup')} / "
             f"{first.get('peer_frames', first.get('frames'))}"],
            ["repeats (processes per variant)", str(first.get("repeats"))],
            ["order", f"{first.get('order')}: each repeat runs every variant once, "
                      "the order rotated so drift hits every variant alike"],
            ["scene", ", ".join(sorted({str(r.get('scene')) for v in rfw for r in v.records}))
             or "-"],
            ["runs", f"{len(records)} ({sum(1 for r in records if r.get('error'))} failed), "
                     f"first {records[0].get('time', '?')}, last "
                     f"{records[-1].get('time', '?')}" if records else "0"]]
    doc.table(["what", "value"], rows)
    doc.bullets(list(first.get("notes", [])))


def _frame_table(doc: Doc, rfw: list[VariantSummary]) -> None:
    doc.h(2, "Frame time per variant")
    doc.p("GPU ms: medians over all frames of all repeats (the sum of the passes' timestamp "
          "times); `p5-p95`: the spread of single frames. Wall ms/frame: each run's total wall "
          "time of its timed frames (record, submit, the waits for frames in flight, the last "
          "frame's wait for all of them, on the host) / frames; median and 95% CI across "
          "runs. Single frames' wall times are not used: with frames in flight one frame's "
          "clock absorbs the wait for an earlier one, so they spread from near 0 to twice a "
          "frame. `runs x frames`: what the statistics rest on. How the CIs are made and when "
          "a difference is marked: see \"How this was measured\"; a CI noted `(n=3<6)` or `(1 run)` "
          "rests on too few samples to be a 95% interval, and differences from it get no mark.")
    rows = []
    for v in rfw:
        if not v.ok:
            continue
        m = v.get("memory") or {}
        gpu, wall, cpu = v.frame.get("gpu_ms"), v.frame.get("wall_ms"), v.frame.get("cpu_ms")
        alloc = m.get("transient_allocated_bytes", m.get("plan_transient_bytes"))
        devices = ", ".join(dict.fromkeys(device_of(r) for r in v.records))
        rows.append([v.label, devices, v.get("backend"), ms(gpu), ci(gpu), spread(gpu),
                     ms(wall), ci(wall), ms(cpu),
                     f"{mib(alloc)} / {mib(m.get('unaliased_bytes'))}"
                     + (" (plan)" if m.get("source") == "plan" else ""), _samples_text(v)])
    doc.table(["variant", "device", "backend", "GPU ms", "95% CI", "p5-p95", "wall ms/frame",
               "wall 95% CI", "CPU record ms", "transient MiB aliased / not", "runs x frames"],
              rows)


def _samples_text(v: VariantSummary) -> str:
    """``3 x 10``: runs and timed frames per run (``3 x 8-10`` where runs differ)."""
    frames = sorted({len((r.get("frame") or {}).get("gpu_ms") or (r.get("frame") or {}).get(
        "wall_ms") or []) for r in v.records})
    each = f"{frames[0]}" if len(frames) == 1 else f"{frames[0]}-{frames[-1]}"
    return f"{len(v.records)} x {each}"


def _pass_tables(doc: Doc, rfw: list[VariantSummary]) -> None:
    doc.h(2, "Per pass")
    doc.p("Medians over all frames of all repeats, with the 95% CI of each (see the frame "
          "table) and the spread of single frames.")
    for v in rfw:
        if not v.ok:
            continue
        doc.h(3, v.label)
        total = (v.frame.get("gpu_ms") or {}).get("median") or 0.0
        rows = []
        for p in v.passes:
            g, c = p["gpu_ms"], p["cpu_ms"]
            share = f"{100 * g['median'] / total:.1f}%" if g and total else "-"
            rows.append([p["name"], ms(g), ci(g), spread(g), share, ms(c), ci(c), spread(c)])
        doc.table(["pass", "GPU ms", "95% CI", "p5-p95", "share", "CPU record ms", "95% CI",
                   "p5-p95"], rows)


def _counters(doc: Doc, rfw: list[VariantSummary]) -> None:
    mem = [v for v in rfw if v.ok and v.get("memory")]
    if mem:
        doc.h(2, "Memory")
        doc.p("Transient resources of the compiled graph: bytes allocated with aliasing, the "
              "plan's bytes and the bytes with every transient in its own allocation. The vk "
              "backend allocates the plan for real (fitted to the driver); on wgpu the plan's "
              "numbers are shown (WebGPU allocates each texture itself).")
        rows = []
        for v in mem:
            m = v.get("memory")
            rows.append([v.label, f"{m.get('transient_allocated_bytes', '-'):,}"
                         if isinstance(m.get("transient_allocated_bytes"), int) else "-",
                         f"{m.get('plan_transient_bytes', 0):,}",
                         f"{m.get('unaliased_bytes', 0):,}",
                         {True: "yes", False: "no"}.get(m.get("alias"), "plan only")])
        doc.table(["variant", "allocated B", "plan B", "unaliased B", "aliased"], rows)
    cull = [v for v in rfw if v.ok and v.get("culling")]
    if cull:
        doc.h(2, "Culling counters")
        keys: list[str] = []
        for v in cull:
            keys.extend(k for k in v.get("culling") if k not in keys)
        doc.table(["variant", *keys], [[v.label, *(_num(v.get("culling").get(k)) for k in keys)]
                                       for v in cull])
    rays = [v for v in rfw if v.ok and v.get("rays")]
    if rays:
        doc.h(2, "Ray counts")
        doc.table(["variant", "rays"], [[v.label, str(v.get("rays"))] for v in rays])


def _temporal(doc: Doc, rfw: list[VariantSummary]) -> None:
    """The flicker index of the runs along a camera path or with a jittered camera."""
    rows = []
    for v in rfw:
        runs = [r["temporal"] for r in v.records if r.get("temporal")]
        if not runs:
            continue
        values = sorted(t["flicker"] for t in runs if t.get("flicker") is not None)
        shares = [t.get("still_share") for t in runs if t.get("still_share") is not None]
        why = next((t["why"] for t in runs if t.get("why")), "")
        rows.append([v.label, f"{values[len(values) // 2]:.5f}" if values else "-",
                     f"{values[0]:.5f}-{values[-1]:.5f}" if len(values) > 1 else "-",
                     f"{100 * sum(shares) / len(shares):.1f}%" if shares else "-",
                     f"{len(runs)} x {runs[0].get('frames', '-')}", why or
                     runs[0].get("still", "")])
    if not rows:
        return
    doc.h(2, "Temporal stability")
    doc.p("Flicker index: the mean absolute change of linear luminance (display range 0-1) "
          "between consecutive timed frames, over the pixels that do not move (along a "
          "camera path: the G-buffer's motion vectors and depth say which; on a still camera "
          "every pixel), from an untimed replay of each run (`rfw.bench.temporal`). 0 is a "
          "still image; a temporal resolve's first frames, while its history fills, count "
          "too.")
    doc.table(["variant", "flicker (median)", "range over runs", "still pixels",
               "runs x frames", "pixels counted"], rows)


def _num(x: Any) -> str:
    return "-" if x is None else f"{x:,}" if isinstance(x, int) else str(x)


def _failures(doc: Doc, variants: list[VariantSummary]) -> None:
    bad = [v for v in variants if v.errors]
    if not bad:
        return
    doc.h(2, "Failed and unavailable")
    doc.table(["variant", "runs failed", "reason"],
              [[v.label, f"{len(v.errors)} of {len(v.errors) + len(v.records)}",
                "; ".join(dict.fromkeys(v.errors))] for v in bad])
