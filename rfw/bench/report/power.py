"""The report's "Power" section: per variant and pass, the chance that the significance rule
marks a 2% change of the GPU ms at this bench's shape, and the runs or frames per run that
would detect it at 80% power, from the measured noise (:func:`rfw.bench.stats.needed`)."""

from __future__ import annotations

from typing import Any

from ..stats import MAX_RUNS, needed, noise
from ..summary import VariantSummary
from .document import Doc

CHANGE = 0.02
TARGET = 0.8


def power_rows(v: VariantSummary, change: float = CHANGE, target: float = TARGET
               ) -> list[dict[str, Any]]:
    """One row per metric of ``v``'s GPU ms (the frame total, then each pass) with enough
    runs: ``{what, runs, frames, between, within, power, runs_needed, frames_needed}``
    (relative SDs on the log scale; :func:`rfw.bench.stats.noise`)."""
    rows = []
    for what, s in [("frame", v.frame.get("gpu_ms")),
                    *((p["name"], p.get("gpu_ms")) for p in v.passes)]:
        n = noise(s)
        if n is None:
            continue
        need = needed(s, change, target=target)
        rows.append({"what": what, "runs": n["runs"], "frames": n["frames"],
                     "between": n["between"], "within": n["within"], "power": need["power"],
                     "runs_needed": need["runs"], "frames_needed": need["frames"]})
    return rows


def _power(doc: Doc, rfw: list[VariantSummary]) -> None:
    tables = [(v, power_rows(v)) for v in rfw if v.ok]
    if not any(rows for _, rows in tables):
        return
    doc.h(2, "Power: what a 2% change takes")
    doc.p(f"The chance that a {CHANGE:.0%} change of the GPU ms median gets the `*` mark "
          f"between two benches shaped like this one (power), and what would detect it with "
          f"{TARGET:.0%} power: the runs at these frames per run, or the frames per run at "
          "these runs. From the measured noise of the log times: between runs (the run "
          "medians' spread that the frames do not explain) and within a run (one frame's "
          "robust SD); more frames shrink only the second, more runs both. `none`: the "
          "noise between runs alone keeps the power under target however many frames. "
          "Estimates from few runs are rough (median-unbiased: as often too low as too "
          "high); how the power is computed: `rfw.bench.stats`.")
    rows = []
    for v, found in tables:
        for r in found:
            rows.append([v.label, r["what"], f"{r['runs']} x {r['frames']}",
                         f"{r['between']:.2%}", "-" if r["within"] is None else f"{r['within']:.2%}",
                         f"{r['power']:.0%}",
                         f"{r['runs_needed']}" if r["runs_needed"] else f"> {MAX_RUNS}",
                         "-" if r["within"] is None else (
                             f"{r['frames_needed']}" if r["frames_needed"] else "none")])
    doc.table(["variant", "pass", "runs x frames", "between runs", "within a run",
               f"power at {CHANGE:.0%}", "runs needed", "frames needed"], rows)
