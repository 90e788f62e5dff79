"""The report's "Frame change, pass by pass" section: each variant's frame GPU ms change against
the baseline variant split into passes added, removed and changed and a residual, each with
its 95% CI and mark (:mod:`rfw.bench.attribution`); also ``attribution.csv``. ``rfw bench
compare`` draws the same table for NEW against OLD (:func:`attribution_tables`)."""

from __future__ import annotations

from pathlib import Path

from ..attribution import RESIDUAL, Attribution, attribute, write_csv
from ..summary import VariantSummary
from .devices import device_of
from .document import Doc
from .images import _pick_reference

HOW = {"changed": "changed", "added": "added: its whole time",
       "removed": "removed: minus its time"}

INTRO = ("The frame total's GPU ms change split into what each pass contributes, so a "
         "technique's cost and what it saves elsewhere read as one table: a pass timed on both "
         "sides contributes its difference (`changed`), a pass timed on one side only its whole "
         "time (`added`) or minus it (`removed`); passes are matched by name, so a renamed pass "
         "shows as one `removed` and one `added`. The `residual` is the frame total's change "
         "less the passes' changes: work no pass timer saw (overlapping or async passes, passes "
         "without timers); the parts add up to the frame total's change. Means per frame, not "
         "medians (only means add up, so the frame change can differ from the medians' change "
         "above). 95% CI of each difference: a bootstrap that resamples each side's runs, then "
         "frames in each run, reading the frame total and every pass from the same frames, "
         "widened for few runs (by sqrt(R/(R-1)) and Student's t); "
         "`*` where the CI excludes 0, `(n.s.)` where it holds 0 (within the noise), no mark "
         "with too few frames or runs on either side (`(n=3<6: no mark)`). Every number is "
         "also in `attribution.csv`.")


def attribution_tables(doc: Doc, attributions: list[Attribution], *, base: str = "baseline",
                       own: str = "variant", titles: bool = True) -> None:
    """One table per pair: each part's mean ms on both sides (``base`` and ``own`` name the
    columns), the change, its 95% CI and mark; the frame total last."""
    for at in attributions:
        if titles:
            doc.h(3, f"{at.variant} against {at.baseline}")
        rows = []
        for p in [*at.parts, at.total]:
            if p.kind == "total":
                name, how = f"**{p.name}**", "the sum of the above"
            elif p.kind == RESIDUAL:
                name = f"({p.name})"
                how = ("none: the frame total is the passes' sum" if p.base == p.own == 0.0
                       else "frame total - passes: overlap, async, untimed")
            else:
                name, how = p.name, HOW[p.kind]
            rows.append([name, how, "-" if p.kind == "added" else f"{p.base:.3f}",
                         "-" if p.kind == "removed" else f"{p.own:.3f}", f"{p.change:+.3f}",
                         f"{p.ci_lo:+.3f} to {p.ci_hi:+.3f}", p.mark])
        doc.table(["part", "how", f"{base} ms", f"{own} ms", "change ms", "95% CI", "mark"],
                  rows)
        frames = (f"means over {at.frames[0]} frames from {at.runs[0]} run(s) ({base}) and "
                  f"{at.frames[1]} from {at.runs[1]} ({own})")
        doc.bullets([frames + (f"; device {at.device}" if at.device else ""), *at.notes])


def against_baseline(rfw: list[VariantSummary], pooled: list[VariantSummary],
                     reference: str | int | None) -> tuple[VariantSummary | None,
                                                           list[Attribution]]:
    """Each variant row of ``rfw`` (one per device where a variant measured several)
    against the baseline's runs on the same device(s); the baseline is ``reference`` (name or
    index into ``pooled``) or else, as for the images, the first variant with an image."""
    done = [v for v in pooled if v.ok]
    if len(done) < 2:
        return None, []
    # the images' reference by default: the first variant with an image
    first = next((v for v in done if v.image), done[0])
    ref = first if reference is None else _pick_reference(pooled, reference)
    if not ref.ok:
        return ref, []
    out = []
    for v in rfw:
        if not v.ok or (v.base or v.label) == ref.label:
            continue
        devices = list(dict.fromkeys(device_of(r) for r in v.records))
        base = [r for r in ref.records if device_of(r) in devices]
        at = attribute(base, v.records, variant=v.label,
                       baseline=ref.label + (f" [{v.device}]" if v.device else ""),
                       device=", ".join(devices)) if base else None
        if at is not None:
            out.append(at)
    return ref, out


def _attribution(doc: Doc, out_dir: Path, rfw: list[VariantSummary],
                 pooled: list[VariantSummary], reference: str | int | None) -> None:
    """The section and ``out_dir/attribution.csv`` (absent with no pair to attribute)."""
    ref, found = against_baseline(rfw, pooled, reference)
    csv_path = Path(out_dir) / "attribution.csv"
    if not found:
        csv_path.unlink(missing_ok=True)  # a rewritten report keeps no stale table
        return
    doc.h(2, "Frame change, pass by pass")
    doc.p(f"Each variant against **{ref.label}** (the baseline: `--reference` picks "
          "another). " + INTRO)
    attribution_tables(doc, found)
    write_csv(csv_path, found)
