"""Which device a run measured, and a variant's rows per device: several devices get one row
each (pooled numbers would mix them) and the "Per device" section shows them side by side."""

from __future__ import annotations

from typing import Any

from ..stats import difference, no_mark, significant
from ..summary import VariantSummary, summarize_results
from .document import Cell, Doc, ci, ms


def device_of(record: dict[str, Any]) -> str:
    """The device a run measured: its adapter, with the Ray node and GPU where it ran as a
    Ray task (several identical GPUs stay apart)."""
    name = str(record.get("device") or "?")
    where = record.get("ray") or {}
    if where:
        gpus = ",".join(str(g) for g in where.get("gpu_ids") or [])
        name += f" @ {where.get('host', '?')}" + (f" GPU {gpus}" if gpus else "")
    return name


def _by_device(v: VariantSummary) -> list[tuple[str, VariantSummary]]:
    """``v`` split by device (the whole of ``v`` when all its runs had one)."""
    devices = list(dict.fromkeys(device_of(r) for r in v.records))
    if len(devices) <= 1:
        return [(devices[0] if devices else "", v)]
    out = []
    for d in devices:
        part = summarize_results([r for r in v.records if device_of(r) == d])
        out.append((d, part[0]))
    return out


Parts = dict[int, list[tuple[str, VariantSummary]]]  # id(variant): its _by_device


def split_devices(variants: list[VariantSummary], *,
                  parts: Parts | None = None) -> list[VariantSummary]:
    """One row per (variant, device) where a variant's runs measured more than one device,
    labelled ``variant [device]`` with statistics over that device's runs only (pooled
    numbers would mix devices); a variant measured on one device stays as it is. ``parts``:
    each variant's :func:`_by_device` where the caller has it already."""
    out = []
    for v in variants:
        parts_of = parts[id(v)] if parts is not None else _by_device(v)
        if len(parts_of) == 1:
            out.append(v)
            continue
        for device, part in parts_of:
            part.label, part.base, part.device = f"{v.label} [{device}]", v.label, device
            out.append(part)
    return out


def _report_devices(rfw: list[VariantSummary]) -> list[str]:
    """Every device the rfw runs measured, in first-run order."""
    return list(dict.fromkeys(device_of(r) for v in rfw for r in v.records))


def _devices(doc: Doc, rfw: list[VariantSummary], *, parts: Parts) -> None:
    """Per-device tables side by side: one column group per device, one row per variant and
    pass; shown when the runs measured more than one device."""
    done = [v for v in rfw if v.ok]
    devices = _report_devices(done)
    if len(devices) < 2:  # "How this was measured" points here only then
        return
    split = {v.label: dict(parts[id(v)]) for v in done}
    doc.h(2, "Per device")
    doc.p("The same variants measured on each device (GPU ms, median and 95% CI); "
          "`-`: not run there.")
    headers = ["variant", "pass"]
    for d in devices:
        headers += [f"{d}: GPU ms", f"{d}: 95% CI"]
    rows = []
    for v in done:
        names = ["frame", *(p["name"] for p in v.passes)]
        for name in names:
            row: list[Cell] = [v.label, name]
            for d in devices:
                part = split[v.label].get(d)
                s = None
                if part is not None:
                    s = part.frame.get("gpu_ms") if name == "frame" else next(
                        (p["gpu_ms"] for p in part.passes if p["name"] == name), None)
                row += [ms(s), ci(s)]
            rows.append(row)
    doc.table(headers, rows)
    _ratios(doc, done, devices, split)
    _uuids(doc, [r for v in done for r in v.records])


def device_ratios(variant: str, devices: list[str], split: dict[str, VariantSummary]
                  ) -> list[dict[str, Any]]:
    """Each device's frame GPU ms against the first device's (``devices``' order) for one
    variant: ``ratio``, ``lo``, ``hi`` (Welch's 95% CI of the ratio of run medians,
    :func:`rfw.bench.stats.difference`) and ``verdict``: ``differs`` (the CI excludes 1 with
    enough samples and runs), ``within the noise``, or why there is no verdict."""
    present = [d for d in devices if d in split]
    if len(present) < 2:
        return []
    base_dev = present[0]
    base = split[base_dev].frame.get("gpu_ms")
    out = []
    for d in present[1:]:
        own = split[d].frame.get("gpu_ms")
        diff = difference(base, own)
        why = "no GPU times" if not base or not own else no_mark(base, own)
        if why is None and diff is None:
            why = "fewer than 2 runs a device"
        verdict = why or ("differs" if significant(base, own) else "within the noise")
        out.append({"variant": variant, "device": d, "against": base_dev, "verdict": verdict,
                    **({k: diff[k] for k in ("ratio", "lo", "hi")} if diff else {})})
    return out


def _ratios(doc: Doc, done: list[VariantSummary], devices: list[str],
            split: dict[str, dict[str, VariantSummary]]) -> None:
    """The device-to-device ratio table: per variant, each device against the first."""
    rows: list[list[Cell]] = []
    differ = []
    for v in done:
        for r in device_ratios(v.label, devices, split[v.label]):
            has = "ratio" in r
            rows.append([v.label, r["device"], r["against"],
                         f"{r['ratio']:.3f}" if has else "-",
                         f"[{r['lo']:.3f}, {r['hi']:.3f}]" if has else "-", r["verdict"]])
            if r["verdict"] == "differs":
                differ.append(f"{v.label} on {r['device']} ({r['ratio']:.3f}x)")
    if not rows:
        return
    doc.h(3, "Device against device")
    doc.p("Frame GPU ms on each device over the first device's, per variant: the ratio of "
          "the run medians' geometric means with its 95% CI (Welch's t-test of the log run "
          "medians, as the variant comparisons); `differs` where the CI excludes 1.")
    doc.table(["variant", "device", "against", "frame GPU ms ratio", "95% CI", "verdict"],
              rows)
    doc.p("Devices differ beyond their CIs: " + "; ".join(differ) + "." if differ else
          "No variant's devices differ beyond their CIs (or too few runs to tell).")


def _uuids(doc: Doc, records: list[dict[str, Any]]) -> None:
    """Which device UUID each device column rendered on, from the runs' records."""
    seen: dict[str, set[str]] = {}
    for r in records:
        for backend, d in (r.get("device_ids") or {}).items():
            uuid = d.get("uuid") or (f"none ({d['uuid_note']}; picked by {d['uuid_via']})"
                                     if d.get("uuid_via") else d.get("uuid_note"))
            if uuid:
                seen.setdefault(device_of(r), set()).add(f"{backend}: {uuid}")
    if seen:
        doc.p("The device UUID each column's runs rendered on, as their records say "
              "(docs/multi-gpu.md):")
        doc.bullets([f"{dev}: {', '.join(sorted(u))}" for dev, u in seen.items()])
