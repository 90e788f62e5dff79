"""``report.md`` and ``report.html`` from a ``results.jsonl``: tables, charts, images, peers.

The two files say the same: a small document model is rendered to Markdown and to HTML.
Images (outputs, differences, charts) are PNG files beside the reports; ``report.md`` links
them relatively, ``report.html`` embeds them as data URIs, so that one file can be sent or
attached on its own. ``results.csv`` (beside ``results.jsonl``) holds the summary numbers.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import check_identifier
from ..fileio import atomic_write, inside
from .images import compare, diff_legend, load_png, psnr, save_png, scale_text, scaled_diff
from .path_chart import path_charts
from .runner import load_results
from .stats import MIN_RUNS, MIN_SAMPLES, change_text, no_mark
from .summary import RAYCAST_PEERS, VariantSummary, mib, summarize_results


@dataclass
class Img:
    path: str  # relative to the report
    alt: str = ""
    width: int = 240


@dataclass
class Cells:
    items: list[Any]  # Img or str, stacked in one table cell


Cell = Any  # str | float | Img | Cells | None


class Doc:
    """Headings, paragraphs, tables and image rows; rendered as Markdown and as HTML."""

    def __init__(self) -> None:
        self.blocks: list[tuple[str, Any]] = []

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", (level, text)))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def bullets(self, items: list[str]) -> None:
        if items:
            self.blocks.append(("ul", items))

    def table(self, headers: list[str], rows: list[list[Cell]]) -> None:
        self.blocks.append(("table", (headers, rows)))

    def image(self, img: Img) -> None:
        self.blocks.append(("img", img))

    def markdown(self) -> str:
        out: list[str] = []
        for kind, value in self.blocks:
            if kind == "h":
                out.append("#" * value[0] + " " + value[1])
            elif kind == "p":
                out.append(value)
            elif kind == "ul":
                out.append("\n".join(f"- {i}" for i in value))
            elif kind == "img":
                out.append(f"![{value.alt}]({value.path})")
            else:
                headers, rows = value
                lines = ["| " + " | ".join(headers) + " |",
                         "|" + "|".join(" --- " for _ in headers) + "|"]
                lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
                out.append("\n".join(lines))
        return "\n\n".join(out) + "\n"

    def html(self, title: str, base: Path) -> str:
        """One self-contained page: every image (paths relative to ``base``) is embedded."""
        base = Path(base)
        out = [f"<!doctype html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
               f"<style>{CSS}</style></head><body>"]
        for kind, value in self.blocks:
            if kind == "h":
                out.append(f"<h{value[0]}>{_e(value[1])}</h{value[0]}>")
            elif kind == "p":
                out.append(f"<p>{_inline(value)}</p>")
            elif kind == "ul":
                out.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in value) + "</ul>")
            elif kind == "img":
                out.append(f"<p>{_html_img(value, base, full=True)}</p>")
            else:
                headers, rows = value
                # a wide table scrolls inside its box instead of widening the page
                out.append("<div class='wide'><table><tr>"
                           + "".join(f"<th>{_e(h)}</th>" for h in headers)
                           + "</tr>" + "".join("<tr>" + "".join(
                               f"<td>{_html_cell(c, base)}</td>" for c in r) + "</tr>" for r in rows)
                           + "</table></div>")
        out.append("</body></html>")
        return "\n".join(out) + "\n"


CSS = ("body{font-family:system-ui,sans-serif;margin:2em;max-width:1400px}"
       ".wide{max-width:100%;overflow-x:auto;margin:0.5em 0 1.5em}"
       "table{border-collapse:collapse}img{max-width:100%;height:auto}"
       "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right;vertical-align:top}"
       "th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}"
       "img{image-rendering:pixelated}code{background:#f3f3f3;padding:0 3px}")


def _e(text: str) -> str:
    return html.escape(str(text))


def _inline(text: str) -> str:
    # the markdown we write inline: `code` and **bold**
    parts = str(text).split("`")
    return "".join(_bold(_e(p)) if i % 2 == 0 else f"<code>{_e(p)}</code>"
                   for i, p in enumerate(parts))


def _bold(text: str) -> str:
    parts = text.split("**")
    return "".join(p if i % 2 == 0 else f"<b>{p}</b>" for i, p in enumerate(parts))


def _md_cell(c: Cell) -> str:
    if isinstance(c, Cells):
        return " ".join(_md_cell(i) for i in c.items)
    if isinstance(c, Img):
        return f"![{c.alt}]({c.path})"
    return "-" if c is None else str(c).replace("|", "\\|").replace("\n", " ")


def data_uri(path: Path) -> str:
    """A PNG file as a ``data:`` URI."""
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def _html_img(img: Img, base: Path, *, full: bool = False) -> str:
    style = "max-width:100%" if full else f"width:{img.width}px;max-width:100%"
    return (f"<img src='{data_uri(inside(base, img.path))}' alt='{_e(img.alt)}' "
            f"title='{_e(img.path)}' style='{style}'>")


def _html_cell(c: Cell, base: Path) -> str:
    if isinstance(c, Cells):
        return "<br>".join(_html_cell(i, base) for i in c.items)
    if isinstance(c, Img):
        return _html_img(c, base)
    return "-" if c is None else _inline(str(c))


# ---------------------------------------------------------------------------------------------
# numbers as text


def ms(s: dict[str, Any] | None, key: str = "median") -> str:
    return "-" if not s else f"{s[key]:.3f}"


def ci(s: dict[str, Any] | None) -> str:
    """``lo-hi``; ``lo-hi (n=2<6)`` where too few samples or runs make it no 95% CI."""
    if not s:
        return "-"
    why = no_mark(s)
    return f"{s['ci_lo']:.3f}-{s['ci_hi']:.3f}" + (f" ({why})" if why else "")


# how every CI of the reports is made and when a difference gets a mark, said once
CI_METHOD = ("95% CI of the median: a percentile bootstrap (2000 resamples, seeded) that "
             "resamples runs, then frames in each run, so run-to-run noise widens it (wall ms: "
             "the runs' numbers resampled). A difference is marked `*` when the two CIs do not overlap, `(n.s.)` when they do "
             f"(within the noise). Below {MIN_SAMPLES} samples or {MIN_RUNS} runs there is no "
             "mark (e.g. `(n=3<6: no mark)`, `(1 run: no mark)`) and the CI carries that note: "
             f"under {MIN_SAMPLES} samples no 95% interval of a median exists without assuming a "
             "distribution (even the samples' full range covers the median with probability "
             "1 - 2·0.5^n, 94% at n=5) and the bootstrap returns about that range; one run does "
             "not measure the noise between runs.")


def spread(s: dict[str, Any] | None) -> str:
    return "-" if not s else f"{s['p5']:.3f}-{s['p95']:.3f}"


def db(v: float | None) -> str:
    if v is None:
        return "-"
    return "∞ (identical)" if math.isinf(v) else f"{v:.2f} dB"


# ---------------------------------------------------------------------------------------------
# the report


def write_report(out_dir: Path, *, reference: str | int | None = None,
                 diff_scale: str = "own") -> tuple[Path, Path]:
    """Read ``out_dir/results.jsonl``, write the charts, image comparisons, ``report.md`` and
    ``report.html`` into ``out_dir``; returns the two report paths. ``diff_scale``: ``own``
    draws each difference image from 0 to its own largest difference, ``shared`` all of
    them to the largest of the report."""
    out_dir = Path(out_dir)
    records = load_results(out_dir)
    variants = summarize_results(records)
    pooled = [v for v in variants if v.kind == "rfw"]
    parts = {id(v): _by_device(v) for v in pooled}  # each device's runs summarized once
    rfw = split_devices(pooled, parts=parts)  # several devices: one row per device
    peers = [v for v in variants if v.kind == "peer"]
    doc = Doc()
    doc.h(1, "rfw benchmark")
    partial = out_dir / "PARTIAL.txt"  # an interrupted bench's runs (rfw.bench.cli)
    if partial.is_file():
        doc.p("Partial results: " + " ".join(partial.read_text(errors="replace").split()))
    _environment(doc, records, pooled)
    _frame_table(doc, rfw)
    charts = _charts(out_dir, rfw)
    charts += path_charts(out_dir, rfw, Img)  # runs along a camera path: GPU ms per frame
    if charts:
        doc.h(2, "Charts")
        for c in charts:
            doc.image(c)
    _pass_tables(doc, rfw)
    _images(doc, out_dir, rfw, reference, pooled, diff_scale=diff_scale, parts=parts)
    _counters(doc, rfw)
    _peers(doc, out_dir, rfw, peers)
    _devices(doc, pooled, parts=parts)
    _failures(doc, variants)
    _method(doc, records, _report_devices(pooled))
    md, page = out_dir / "report.md", out_dir / "report.html"
    # whole or not at all: 'rfw bench report' rewrites them in place
    atomic_write(md, lambda f: f.write(doc.markdown().encode("utf-8")))
    atomic_write(page, lambda f: f.write(doc.html("rfw benchmark", out_dir).encode("utf-8")))
    write_csv(out_dir / "results.csv", [*rfw, *peers])
    return md, page


CSV_FIELDS = ("variant", "kind", "device", "backend", "pass", "metric", "n", "runs", "median",
              "ci_lo", "ci_hi", "p5", "p95", "mean")


def write_csv(path: Path, variants: list[VariantSummary]) -> Path:
    """One row per variant, device, pass (``frame`` for whole frames) and metric: the
    summary numbers of the report (ms), for plotting elsewhere."""
    rows = []
    for v in variants:
        for dev, part in _by_device(v):
            for metric, s in part.frame.items():
                if isinstance(s, dict):
                    rows.append(_csv_row(part, dev, "frame", metric, s))
            for p in part.passes:
                for metric in ("gpu_ms", "cpu_ms"):
                    if p.get(metric):
                        rows.append(_csv_row(part, dev, p["name"], metric, p[metric]))
    with path.open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_FIELDS)
        w.writerows(rows)
    return path


def _csv_row(v: VariantSummary, device: str, name: str, metric: str,
             s: dict[str, Any]) -> list[Any]:
    return [v.label, v.kind, device, v.get("backend", ""), name, metric, s["n"], s["runs"],
            *(round(s[k], 6) for k in ("median", "ci_lo", "ci_hi", "p5", "p95", "mean"))]


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


def _charts(out_dir: Path, rfw: list[VariantSummary]) -> list[Img]:
    done = [v for v in rfw if v.ok]
    if not done:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    charts = out_dir / "charts"
    charts.mkdir(exist_ok=True)
    names: list[str] = []
    for v in done:
        names.extend(p["name"] for p in v.passes if p["name"] not in names)
    cmap = plt.get_cmap("tab20")
    colors = {n: cmap(i % 20) for i, n in enumerate(names)}
    labels = [v.label for v in done]
    height = max(2.5, 0.45 * len(done) + 1.5)
    fig, axes = plt.subplots(1, 2, figsize=(14, height), sharey=True)
    for ax, metric, title in ((axes[0], "gpu_ms", "GPU ms per pass (median, 95% CI)"),
                              (axes[1], "cpu_ms", "CPU record ms per pass (median, 95% CI)")):
        ax.set_title(title)
        left = [0.0] * len(done)
        for n in names:
            widths, err, has = [], [[], []], []
            for i, v in enumerate(done):
                p = next((p for p in v.passes if p["name"] == n), None)
                s = p and p[metric]
                widths.append(s["median"] if s else 0.0)
                if s:  # a variant without this pass gets no bar
                    lo, hi = stacked_error(s)
                    err[0].append(lo)
                    err[1].append(hi)
                    has.append(i)
            ax.barh(labels, widths, left=left, color=colors[n], label=n)
            # each segment's CI drawn at its right end, where its median ends the stack
            ends = [a + b for a, b in zip(left, widths, strict=True)]
            if has:
                ax.errorbar([ends[i] for i in has], [labels[i] for i in has], xerr=err,
                            fmt="none", ecolor="black", elinewidth=0.8, capsize=2)
            left = ends
        ax.set_xlabel("ms")
    axes[0].invert_yaxis()  # shared: the first variant on top, as in the tables
    axes[1].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    fig.tight_layout()
    passes = charts / "passes.png"
    fig.savefig(passes, dpi=100)
    plt.close(fig)
    fig, axes = plt.subplots(1, 2, figsize=(14, height), sharey=True)
    for ax, metric, title in ((axes[0], "gpu_ms", "frame GPU ms (all frames, all repeats)"),
                              (axes[1], "wall_ms", "wall ms per frame (one per run)")):
        data = [[x for run in v.samples.get(metric, []) for x in run] or [math.nan]
                for v in done]
        ax.boxplot(data, orientation="horizontal", tick_labels=labels, whis=(5, 95), showfliers=True,
                   flierprops={"markersize": 3})
        ax.set_title(title + " — whiskers p5-p95")
        ax.set_xlabel("ms")
    axes[0].invert_yaxis()
    fig.tight_layout()
    dist = charts / "distributions.png"
    fig.savefig(dist, dpi=100)
    plt.close(fig)
    return [Img("charts/passes.png", "stacked per-pass medians"),
            Img("charts/distributions.png", "frame time distributions")]


def stacked_error(s: dict[str, Any] | None) -> tuple[float, float]:
    """The error bar of one stacked segment: distances from its median down to the CI's low
    end and up to its high end (zero for no samples)."""
    if not s:
        return 0.0, 0.0
    return max(0.0, s["median"] - s["ci_lo"]), max(0.0, s["ci_hi"] - s["median"])


def _pick_reference(rfw: list[VariantSummary], reference: str | int | None) -> VariantSummary:
    done = [v for v in rfw if v.ok and v.image]
    if reference is None:
        return done[0]
    if isinstance(reference, int) or str(reference).isdigit():
        i = int(reference)
        if not 0 <= i < len(rfw):
            raise ValueError(f"--reference {i}: there are {len(rfw)} variants (0..{len(rfw) - 1})")
        return rfw[i]
    for v in rfw:
        if v.label == reference:
            return v
    raise ValueError(f"--reference '{reference}': no such variant "
                     f"({', '.join(v.label for v in rfw)})")


def image_camera(v: VariantSummary) -> tuple[Any, str]:
    """The camera of ``v``'s image (its run's last timed frame): a key that is equal for two
    runs that rendered the same view, and the camera in words."""
    record = next((r for r in v.records if r.get("image")), v.first)
    return camera_of(record)


def camera_of(record: dict[str, Any]) -> tuple[Any, str]:
    """The camera a run's image was rendered from, as :func:`image_camera` gives it: along a
    camera path the path's last frame (``camera_path`` of the record), else the static camera
    (the config's ``[camera]`` and the run's ``camera.*`` settings, on the run's scene)."""
    scene = record.get("scene")
    path = record.get("camera_path") or {}
    frames = path.get("frames") or []
    if frames:
        last = frames[-1]
        key = ("path", scene, *(tuple(round(float(x), 5) for x in last.get(k) or ())
                                for k in ("position", "target")),
               round(float(last.get("yfov") or 0.0), 4))
        return key, (f"{path.get('kind', 'camera')} path, last frame, "
                     f"t={float(last.get('t', 1.0)):.3g}")
    table = _static_camera(record)
    shown = ", ".join(f"{k}={_short(v)}" for k, v in table.items())
    return ("static", scene, json.dumps(table, sort_keys=True)), (
        "static camera" + (f" ({shown})" if shown else ""))


def _short(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ",".join(_short(x) for x in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _static_camera(record: dict[str, Any]) -> dict[str, Any]:
    """The static camera's keys of a run: its config's ``[camera]`` with the run's
    ``camera.*`` settings applied, without the path (the config read as the run read it;
    where it cannot be read any more, the settings as written)."""
    sets = [s for s in record.get("settings") or []
            if s.partition("=")[0].strip() == "camera"
            or s.partition("=")[0].strip().startswith("camera.")]
    if record.get("config_path"):
        from ..config import apply_overrides, load_config

        try:
            cfg = apply_overrides(load_config(record["config_path"]), sets)
        except (OSError, ValueError):  # moved or changed since: the settings are all we have
            pass
        else:
            return {k: v for k, v in (cfg.camera or {}).items() if k != "path"}
    out: dict[str, Any] = {}
    for s in sets:
        key, _, value = s.partition("=")
        key = key.strip()
        if key != "camera.path" and not key.startswith("camera.path."):
            out[key.removeprefix("camera.") or key] = value.strip()
    return out


def image_comparisons(out_dir: Path, rfw: list[VariantSummary],
                      reference: str | int | None = None,
                      pooled: list[VariantSummary] | None = None, *,
                      diff_scale: str = "own"
                      ) -> tuple[VariantSummary | None, list[dict[str, Any]]]:
    """Each variant's output against the reference: PSNR, FLIP, difference PNGs (written to
    ``out_dir/images``). Variants whose image has another shape, or was rendered from another
    camera (:func:`image_camera`), are compared with nothing (``camera`` says which).
    ``rfw`` may hold per-device rows (:func:`split_devices`); ``--reference`` then names or
    numbers a variant of ``pooled``, the variants as run. ``diff_scale``: see
    :func:`write_report`; each row's ``scale`` is the top of its difference image's scale."""
    if not any(v.ok and v.image for v in rfw):
        return None, []
    ref = _pick_reference(pooled if pooled is not None else rfw, reference)
    if not ref.image:
        return ref, []
    ref_img = load_png(inside(out_dir, ref.image))
    ref_cam, ref_text = image_camera(ref)
    rows = []
    for i, v in enumerate(rfw):
        if not v.image:
            continue
        img = load_png(inside(out_dir, v.image))
        row: dict[str, Any] = {"variant": v, "image": v.image}
        cam, text = image_camera(v)
        if cam != ref_cam:  # another view: a PSNR would measure the views, not the technique
            row["camera"] = (f"different {'scenes' if cam[1] != ref_cam[1] else 'cameras'}: "
                             f"not compared (reference: {ref_text}; this: {text})")
        elif img.shape == ref_img.shape:
            c = compare(ref_img, img)
            name = check_identifier("variant id", v.records[0].get("variant_id"))
            if v.base:  # one device's row: its files apart from the variant's other rows
                name += f".{i}"
            row.update(psnr=c["psnr"], diff_max=c["diff_max"], flip=c.get("flip"),
                       ssim=c.get("ssim"), name=name, abs_diff=c["abs_diff"])
            if "flip_map" in c:
                fmap = Path("images") / f"{name}.flip.png"
                save_png(inside(out_dir, fmap), c["flip_map"])
                row["flip_map"] = str(fmap)
        rows.append(row)
    write_diffs(out_dir, rows, diff_scale)
    return ref, rows


def write_diffs(out_dir: Path, rows: list[dict[str, Any]], diff_scale: str) -> None:
    """Each compared row's difference image and legend (``images/<name>.diff.png`` and
    ``.diff_legend.png``, or the row's ``files``): from 0 to its own largest difference
    (``own``), or to the largest of all ``rows`` (``shared``); sets the row's ``diff``,
    ``legend`` and ``scale``."""
    if diff_scale not in ("own", "shared"):
        raise ValueError(f"diff_scale: expected 'own' or 'shared', not {diff_scale!r}")
    compared = [r for r in rows if "abs_diff" in r]
    shared = max((r["diff_max"] for r in compared), default=0)
    for r in compared:
        top = shared if diff_scale == "shared" else r["diff_max"]
        own = r["diff_max"] if diff_scale == "shared" else None
        diff, legend = r.get("files") or (Path("images") / f"{r['name']}.diff.png",
                                          Path("images") / f"{r['name']}.diff_legend.png")
        save_png(inside(out_dir, diff), scaled_diff(r.pop("abs_diff"), top))
        diff_legend(inside(out_dir, legend), top, own_max=own)
        r.update(diff=str(diff), legend=str(legend), scale=scale_text(top, own_max=own))


def diff_cell(r: dict[str, Any]) -> Cell:
    """A row's difference image with its legend and its scale in words."""
    return Cells([Img(r["diff"], "diff"), Img(r["legend"], "legend", 160), r["scale"]])


def _images(doc: Doc, out_dir: Path, rfw: list[VariantSummary],
            reference: str | int | None, pooled: list[VariantSummary], *,
            diff_scale: str = "own", parts: Parts) -> None:
    ref, rows = image_comparisons(out_dir, rfw, reference, pooled, diff_scale=diff_scale)
    if ref is None:
        return
    doc.h(2, "Images")
    has_flip = any(r.get("flip") is not None for r in rows)
    devices = _report_devices(pooled)
    # the reference's statistics on each device it ran on (a per-device row: its one)
    ref_on = dict(parts[id(ref)] if id(ref) in parts else _by_device(ref))
    scale = ("colour-mapped from black (0) to the largest difference of all the report's "
             "images (`--diff-scale shared`: colours compare across rows; each legend states "
             "the scale and the image's own largest difference)"
             if diff_scale == "shared" else
             "colour-mapped from black (0) to the largest difference of that image: each "
             "image has its own scale, stated below it (`scale 0-4/255`), so the same colour "
             "means different differences in different rows (`--diff-scale shared` draws "
             "them all on one scale)")
    doc.p(f"Reference: **{ref.label}**; image differences next to the time differences "
          f"(frame GPU ms, median). Difference: |reference - variant|, max over RGB, {scale}. "
          "`vs reference`: `*` where the 95% CIs of the two medians do not overlap, "
          f"`(n.s.)` where they do (not a result), no mark below {MIN_SAMPLES} samples or "
          f"{MIN_RUNS} runs (e.g. `(n=3<6: no mark)`). "
          + ("The runs measured several devices: each row is compared with the reference's "
             "runs on the same device; where the reference has none there, the change has no "
             "mark. " if len(devices) > 1 else "")
          + ("FLIP: NVIDIA's perceptual error (LDR, 67 pixels per degree; 0 = identical), "
             "magma error map." if has_flip else "SSIM from scikit-image (FLIP is not "
                                                 "installed)."))
    if any(r.get("camera") for r in rows):
        doc.p("**Different cameras:** a row marked `different cameras: not compared` rendered "
              "another view than the reference (a camera path's last frame, another static "
              "camera or another scene; from `camera_path` and the camera settings in "
              "`results.jsonl`). A PSNR or FLIP between two views measures the views, not the "
              "technique, so none is given; compare it with a variant run from the same "
              "camera (`--reference`).")
    headers = ["variant", "image", "difference", *(["FLIP map"] if has_flip else []), "PSNR",
               "FLIP" if has_flip else "SSIM", "GPU ms", "vs reference"]
    ref_gpu = ref.frame.get("gpu_ms")
    table = []
    for r in rows:
        label = r["variant"].label
        own_gpu = r["variant"].frame.get("gpu_ms")
        own_ms = (own_gpu or {}).get("median")
        cells: list[Cell] = [label, Img(r["image"], label)]
        cells.append(r["camera"] if r.get("camera") else
                     diff_cell(r) if r.get("diff") else "other size")
        if has_flip:
            cells.append(Img(r["flip_map"], "flip") if r.get("flip_map") else "-")
        cells.append("not compared" if r.get("camera") else db(r.get("psnr")))
        metric = r.get("flip") if has_flip else r.get("ssim")
        cells.append("not compared" if r.get("camera") else
                     "-" if metric is None else f"{metric:.4f}")
        cells.append("-" if own_ms is None else f"{own_ms:.3f}")
        if r["variant"] is ref or r["variant"].base == ref.label:
            cells.append("reference")
        elif len(devices) == 1:
            cells.append(change_text(ref_gpu, own_gpu))
        else:  # against the reference on this row's device only
            device = device_of(r["variant"].first)
            same = ref_on.get(device)
            if same is None:
                change = change_text(ref_gpu, own_gpu).split(" ")[0]
                cells.append(f"{change} (reference not run on {device}: no mark)")
            else:
                cells.append(change_text(same.frame.get("gpu_ms"), own_gpu))
        table.append(cells)
    doc.table(headers, table)


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


def _num(x: Any) -> str:
    return "-" if x is None else f"{x:,}" if isinstance(x, int) else str(x)


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


def _failures(doc: Doc, variants: list[VariantSummary]) -> None:
    bad = [v for v in variants if v.errors]
    if not bad:
        return
    doc.h(2, "Failed and unavailable")
    doc.table(["variant", "runs failed", "reason"],
              [[v.label, f"{len(v.errors)} of {len(v.errors) + len(v.records)}",
                "; ".join(dict.fromkeys(v.errors))] for v in bad])


def _method(doc: Doc, records: list[dict[str, Any]], devices: list[str]) -> None:
    doc.h(2, "How this was measured")
    doc.bullets([
        _how_runs_ran(records, devices),
        "GPU ms are timestamp queries around each pass (wgpu timestamp queries; "
        "`vkCmdWriteTimestamp2` on vk); CPU record ms is the host time of the pass's "
        "`record()`; wall ms per frame is a run's wall time over its timed frames (record, "
        "submit, the waits for frame-in-flight slots, the last frame's wait for the rest) / "
        "frames.",
        "Statistics: GPU and CPU ms: median, p5 and p95 over single frames; wall ms: each "
        "run's total wall time / frames, median over runs. " + CI_METHOD,
        "Results: `results.jsonl` (one line per run, every frame's numbers); re-run the report "
        "with `rfw bench report DIR`, compare two result sets with "
        "`rfw bench compare OLD NEW`.",
        "Timings are never asserted by the tests; on lavapipe the 'GPU' is the CPU.",
    ])


def _how_runs_ran(records: list[dict[str, Any]], devices: list[str]) -> str:
    """The first bullet of "How this was measured": one process after another here, or Ray
    tasks running concurrently (``--executor ray``); ``devices``: those the rfw runs that
    worked measured (the "Per device" section exists for two or more)."""
    worker = ("load the config, build the scene, render warm-up frames, then the timed "
              "frames; nothing is shared between runs but the shader cache on disk")
    rays = [r for r in records if r.get("executor") == "ray"]
    if not rays:
        return ("Every run is its own process (`python -m rfw.bench.worker`), one after "
                f"another on this machine: {worker}.")
    cluster = next((r["ray_cluster"] for r in rays if r.get("ray_cluster")), {})
    gpus, cpus = cluster.get("gpus") or 0, cluster.get("cpus") or 0
    submitted = cluster.get("submitted") or len(rays)
    per_task = "one GPU" if gpus else "one CPU (the cluster has no GPU)"
    slots = int(gpus or cpus) or submitted
    hosts = len({(r.get("ray") or {}).get("host") for r in rays})
    return (f"Runs went through Ray (`--executor ray`), concurrently: all {submitted} runs "
            f"were submitted at once as Ray tasks asking for {per_task} each, so up to "
            f"{min(submitted, slots)} ran at the same time (cluster resources: "
            f"{gpus:g} GPU, {cpus:g} CPU; {hosts} host(s)). Each task ran its run in its own "
            f"process (`python -m rfw.bench.worker`): {worker}. Runs sharing a machine "
            f"could slow each other down{_devices_pointer(devices)}.")


def _devices_pointer(devices: list[str]) -> str:
    """Where a Ray report sends the reader to compare devices: the "Per device" section,
    which exists only when the runs measured two devices or more."""
    if len(devices) > 1:
        return (f": compare the {len(devices)} devices in the per-device table "
                "(\"Per device\")")
    if devices:
        return (f"; all runs measured one device ({devices[0]}), so there is no per-device "
                "table")
    return ""


def main_report(out_dir: str, reference: str | None = None, diff_scale: str = "own") -> int:
    md, page = write_report(Path(out_dir), reference=reference, diff_scale=diff_scale)
    print(f"wrote {md}, {page}")
    return 0
