"""The report written: its sections in order into ``report.md`` and ``report.html``, and the
summary numbers into ``results.csv``."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from ...fileio import atomic_write
from ..path_chart import path_charts
from ..runner import load_results
from ..summary import VariantSummary, summarize_results
from .attribution import _attribution
from .charts import _charts
from .devices import _by_device, _devices, _report_devices, split_devices
from .document import Doc, Img
from .images import _images
from .method import _method
from .peers import _peers
from .power import _power
from .tables import (
    _counters,
    _environment,
    _failures,
    _frame_table,
    _pass_tables,
    _temporal,
)
from .truth import _truth, csv_rows, write_truth_csv


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
    from ..truth import parse as parse_truth

    # --reference pathtrace[:SPP]: the images are compared with the first variant, as without
    # one, and against the truth in a section of their own
    truth_given = parse_truth(reference) is not None
    if truth_given and not (out_dir / "truth.json").is_file():
        raise ValueError(f"--reference {reference}: this bench has no references (it ran "
                         "without --reference pathtrace; run it again with it)")
    _attribution(doc, out_dir, rfw, pooled, None if truth_given else reference)
    _images(doc, out_dir, rfw, None if truth_given else reference, pooled,
            diff_scale=diff_scale, parts=parts)
    truth_rows = _truth(doc, out_dir, pooled)
    _counters(doc, rfw)
    _temporal(doc, rfw)
    _peers(doc, out_dir, rfw, peers)
    _devices(doc, pooled, parts=parts)
    _failures(doc, variants)
    _power(doc, rfw)  # late: its rows repeat the variants' labels
    _method(doc, records, _report_devices(pooled))
    md, page = out_dir / "report.md", out_dir / "report.html"
    # whole or not at all: 'rfw bench report' rewrites them in place
    atomic_write(md, lambda f: f.write(doc.markdown().encode("utf-8")))
    atomic_write(page, lambda f: f.write(doc.html("rfw benchmark", out_dir).encode("utf-8")))
    write_csv(out_dir / "results.csv", [*rfw, *peers], extra=csv_rows(truth_rows))
    if truth_rows:
        write_truth_csv(out_dir / "truth.csv", truth_rows)
    return md, page


CSV_FIELDS = ("variant", "kind", "device", "backend", "pass", "metric", "n", "runs", "median",
              "ci_lo", "ci_hi", "p5", "p95", "mean")


def write_csv(path: Path, variants: list[VariantSummary],
              extra: list[list[Any]] | None = None) -> Path:
    """One row per variant, device, pass (``frame`` for whole frames) and metric: the
    summary numbers of the report (ms), for plotting elsewhere; then ``extra`` rows (the
    errors against the truth: pass ``truth``)."""
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
        w.writerows(extra or [])
    return path


def _csv_row(v: VariantSummary, device: str, name: str, metric: str,
             s: dict[str, Any]) -> list[Any]:
    return [v.label, v.kind, device, v.get("backend", ""), name, metric, s["n"], s["runs"],
            *(round(s[k], 6) for k in ("median", "ci_lo", "ci_hi", "p5", "p95", "mean"))]


def main_report(out_dir: str, reference: str | None = None, diff_scale: str = "own") -> int:
    md, page = write_report(Path(out_dir), reference=reference, diff_scale=diff_scale)
    print(f"wrote {md}, {page}")
    return 0
