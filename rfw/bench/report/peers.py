"""The report's "Peers" section: the other renderers' frame times, rfw's ratios to them, their
images and how close the raster peers' images are to rfw's ``flat`` one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...fileio import inside
from ..images import load_png, psnr
from ..summary import RAYCAST_PEERS, VariantSummary
from .document import Cell, Doc, Img, ci, ms


def _peers(doc: Doc, out_dir: Path, rfw: list[VariantSummary],
           peers: list[VariantSummary]) -> None:
    if not peers:
        return
    doc.h(2, "Peers")
    doc.p("The same scene (all instances baked into one mesh), camera and resolution, each "
          "peer in its own process, interleaved with rfw's runs. Ratio = rfw ÷ peer (below 1: "
          "rfw is faster). Where a peer has GPU timer queries the GPU ratio uses rfw's "
          "timestamp total; wall ratios use rfw's frame wall time (record, submit and the "
          "wait for its slot).")
    done = [v for v in rfw if v.ok]
    raster = [p for p in peers if _kind(p) == "raster"]
    cast = [p for p in peers if _kind(p) == "raycast"]
    if raster:
        doc.h(3, "Rasterization")
        rows = []
        for p in raster:
            if not p.ok:
                rows.append([p.label.removeprefix("peer:"), "-", "-", "-", "-", "-",
                             p.errors[0] if p.errors else "no runs"])
                continue
            f, g = p.frame.get("frame_ms"), p.frame.get("gpu_ms")
            timing = p.get("timing")
            if f and g and g["median"] < 0.2 * f["median"]:
                # e.g. llvmpipe's GL: the query closes before the deferred rasterisation runs
                timing += "; the GPU query covers under 20% of the wall time: use the wall ratio"
            rows.append([p.label.removeprefix("peer:"), p.get("device"), ms(f), ci(f), ms(g),
                         timing, p.get("version")])
        doc.table(["peer", "device", "wall ms", "95% CI", "GPU ms", "timing", "version"], rows)
        ok = [p for p in raster if p.ok]
        if ok and done:
            headers = ["rfw variant"]
            for p in ok:
                name = p.label.removeprefix("peer:")
                headers.append(f"÷ {name} (wall)")
                if p.frame.get("gpu_ms"):
                    headers.append(f"÷ {name} (GPU)")
            rows = []
            for v in done:
                row: list[Cell] = [v.label]
                for p in ok:
                    row.append(_ratio(v.frame.get("wall_ms"), p.frame.get("frame_ms")))
                    if p.frame.get("gpu_ms"):
                        row.append(_ratio(v.frame.get("gpu_ms"), p.frame.get("gpu_ms")))
                rows.append(row)
            doc.table(headers, rows)
        imgs = [p for p in raster if p.ok and p.image]
        if imgs:
            doc.table([p.label.removeprefix("peer:") for p in imgs],
                      [[Img(p.image, p.label) for p in imgs]])
            _peer_psnr(doc, out_dir, done, imgs)
    if cast:
        doc.h(3, "Ray casting (primary rays, closest hit)")
        own = next((p for p in cast if p.label == "peer:rfw_raycast" and p.ok), None)
        rows = []
        for p in cast:
            name = p.label.removeprefix("peer:")
            if not p.ok:
                rows.append([name, "-", "-", "-", "-", "-", "-", p.errors[0] if p.errors
                             else "no runs"])
                continue
            f = p.frame.get("frame_ms")
            mr = p.frame.get("mrays_per_s")
            ratio = "-" if own is None or p is own else _ratio(own.frame.get("frame_ms"), f)
            rows.append([name, p.get("device"), f"{p.get('rays'):,}", ms(f), ci(f),
                         "-" if mr is None else f"{mr:.2f}", ratio, p.get("timing")])
        doc.table(["peer", "device", "rays", "ms", "95% CI", "Mrays/s", "rfw ÷ peer",
                   "timing"], rows)
        if own is None:
            cause = next((p.errors[0] for p in cast if p.label == "peer:rfw_raycast"
                          and p.errors), "rfw_raycast was not in --peers")
            doc.p(f"No rfw ratio for ray casting: {cause}.")
        else:
            hits = {p.label.removeprefix("peer:"): p.get("hits") for p in cast if p.ok}
            doc.p("Hits per peer (same rays, so they should agree up to edge cases): "
                  + ", ".join(f"{k} {v:,}" for k, v in hits.items() if v is not None) + ".")
        imgs = [p for p in cast if p.ok and p.image]
        if imgs:
            doc.table([p.label.removeprefix("peer:") + " (hit distance)" for p in imgs],
                      [[Img(p.image, p.label) for p in imgs]])


def _peer_psnr(doc: Doc, out_dir: Path, rfw: list[VariantSummary],
               imgs: list[VariantSummary]) -> None:
    """How close each raster peer's image is to rfw's ``flat`` one, the shading they share."""
    flat = next((v for v in rfw if v.get("config") == "flat" and v.image), None)
    if flat is None:
        return
    ref = load_png(inside(out_dir, flat.image))
    cells = []
    for p in imgs:
        img = load_png(inside(out_dir, p.image))
        cells.append("size differs" if img.shape != ref.shape else f"{psnr(ref, img):.1f} dB")
    doc.p(f"The raster peers shade as rfw's `flat` technique does (one sun, Lambert per "
          f"vertex, base colours, no tonemap curve): PSNR of each peer's image against "
          f"{flat.label}'s.")
    doc.table([p.label.removeprefix("peer:") for p in imgs], [cells])


def _kind(p: VariantSummary) -> str:
    """"raster" or "raycast": from a run's record, else from the peer's name."""
    for r in [*p.records, *p.failed]:
        if r.get("peer_kind"):
            return r["peer_kind"]
    return "raycast" if p.label.removeprefix("peer:") in RAYCAST_PEERS else "raster"


def _ratio(a: dict[str, Any] | None, b: dict[str, Any] | None) -> str:
    if not a or not b or not b["median"]:
        return "-"
    return f"{a['median'] / b['median']:.2f}x"
