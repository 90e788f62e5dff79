"""``rfw bench compare OLD NEW [--out DIR]``: per-pass changes beyond the noise.

A change is flagged when it is significant (:func:`rfw.bench.stats.significant`: the 95% CI
of the ratio of the run medians excludes 1) *and* the relative change of the median exceeds
the threshold; slower is a regression, faster an improvement.
With too few samples or runs on either side (:func:`rfw.bench.stats.no_mark`) nothing is
flagged: the verdict says why. OLD and NEW measured differently (size, frames, warm-up,
scene, settings, executor, device) are refused unless ``--allow-mismatch``.
With ``--out`` it also writes ``compare.md`` and a self-contained ``compare.html`` there: every
change with its significance, and each variant's NEW image against its OLD one (PSNR, FLIP,
difference image with its legend), and each variant's frame GPU ms change split into its
passes' parts (:mod:`rfw.bench.attribution`), also as ``attribution.csv``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import RfwError, check_number, naming
from ..fileio import inside
from .attribution import Attribution, attribute, summary_line, write_csv
from .inputs import input_changes
from .report import device_of
from .runner import load_results
from .stats import MIN_RUNS, MIN_SAMPLES, no_mark, significant
from .summary import VariantSummary, summarize_results

METRICS = ("gpu_ms", "cpu_ms")  # per pass; frames add wall_ms


@dataclass
class Change:
    variant: str
    what: str  # "frame" or a pass name
    metric: str
    old: dict[str, Any]
    new: dict[str, Any]

    @property
    def relative(self) -> float:
        return (self.new["median"] - self.old["median"]) / self.old["median"] \
            if self.old["median"] else 0.0

    @property
    def overlap(self) -> bool:
        return self.new["ci_lo"] <= self.old["ci_hi"] and self.old["ci_lo"] <= self.new["ci_hi"]

    @property
    def too_few(self) -> str | None:
        """Why this change cannot be judged (``n=3<6``, ``1 run``), or None."""
        return no_mark(self.old, self.new)

    def verdict(self, threshold: float) -> str:
        if self.too_few:
            return f"too few samples ({self.too_few})"
        if not significant(self.old, self.new) or abs(self.relative) <= threshold:
            return "same"
        return "regression" if self.relative > 0 else "improvement"


def _metrics(v: VariantSummary) -> dict[tuple[str, str], dict[str, Any]]:
    out = {}
    for key, s in v.frame.items():
        if isinstance(s, dict):
            out[("frame", key)] = s
    for p in v.passes:
        for m in METRICS:
            if p.get(m):
                out[(p["name"], m)] = p[m]
    return out


def changes(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> tuple[list[Change],
                                                                            list[str]]:
    """Every (variant, pass, metric) in both result sets, and notes on what is in one only
    or measured with different drivers (other devices are a mismatch: :func:`mismatches`)."""
    return _changes(summarize_results(old), summarize_results(new))


def _changes(old: list[VariantSummary], new: list[VariantSummary]) -> tuple[list[Change],
                                                                          list[str]]:
    """:func:`changes` of two sets already summarized."""
    olds = {v.label: v for v in old if v.ok}
    news = {v.label: v for v in new if v.ok}
    everywhere = {v.label for v in old} & {v.label for v in new}
    notes = []
    out = []
    for label in [*olds, *(k for k in news if k not in olds)]:
        if (label not in olds or label not in news) and label not in everywhere:
            notes.append(f"{label}: only in {'OLD' if label in olds else 'NEW'}")
    notes += _failed_sides(old, new)
    for label in [k for k in olds if k in news]:
        a, b = olds[label], news[label]
        if a.get("driver") != b.get("driver"):
            notes.append(f"{label}: drivers differ ({a.get('driver')} vs {b.get('driver')})")
        ma, mb = _metrics(a), _metrics(b)
        for key in [k for k in ma if k in mb]:
            out.append(Change(label, key[0], key[1], ma[key], mb[key]))
    return out, notes


@dataclass
class OneSided:
    """A pass (or variant, or metric) measured on one side only: an added or removed
    technique, listed with its cost instead of being left out."""

    variant: str
    what: str  # "frame" or a pass name
    metric: str
    side: str  # "OLD" or "NEW": where it was measured
    stats: dict[str, Any]
    verdict: str  # "added", "removed", "not measured in OLD", ...
    main: bool  # its cost (a pass's GPU ms, a variant's frame GPU ms): listed without --all

    @property
    def old(self) -> dict[str, Any] | None:
        return self.stats if self.side == "OLD" else None

    @property
    def new(self) -> dict[str, Any] | None:
        return self.stats if self.side == "NEW" else None


def _cost(keys: list[tuple[str, str]], what: str) -> tuple[str, str] | None:
    """The metric that says what ``what`` costs: GPU ms, else CPU ms (a bridge), else any."""
    mine = [k for k in keys if k[0] == what]
    for metric in ("gpu_ms", "frame_ms", "cpu_ms", "wall_ms"):
        if (what, metric) in mine:
            return what, metric
    return mine[0] if mine else None


def one_sided(old: list[VariantSummary], new: list[VariantSummary]) -> list[OneSided]:
    """Every (variant, pass, metric) measured in OLD or NEW only: passes added or removed
    in a variant both measured, every pass of a variant only one side measured, and metrics
    one side has no samples of (GPU times without timestamps)."""
    olds = {v.label: v for v in old if v.ok}
    news = {v.label: v for v in new if v.ok}
    out: list[OneSided] = []
    for label in [*olds, *(k for k in news if k not in olds)]:
        a, b = olds.get(label), news.get(label)
        ma, mb = _metrics(a) if a else {}, _metrics(b) if b else {}
        names_a = {"frame", *(p["name"] for p in a.passes)} if a else set()
        names_b = {"frame", *(p["name"] for p in b.passes)} if b else set()
        for side, mine, theirs, names in (("OLD", ma, mb, names_b), ("NEW", mb, ma, names_a)):
            keys = [k for k in mine if k not in theirs]
            for what in dict.fromkeys(k[0] for k in keys):
                cost = _cost(list(mine), what)
                for key in (k for k in keys if k[0] == what):
                    gone = what not in names
                    verdict = ("removed" if side == "OLD" else "added") if gone else \
                        f"not measured in {'NEW' if side == 'OLD' else 'OLD'}"
                    out.append(OneSided(label, what, key[1], side, mine[key], verdict,
                                        key == cost))
    return out


def _failed_sides(old: list[VariantSummary], new: list[VariantSummary]) -> list[str]:
    """A note per variant whose runs all failed on one side while the other has results."""
    out = []
    for side, mine, theirs in (("OLD", old, new), ("NEW", new, old)):
        ok = {v.label for v in theirs if v.ok}
        for v in mine:
            if not v.ok and v.label in ok:
                why = " ".join(str(v.errors[0]).split())[:120] if v.errors else "?"
                out.append(f"{v.label}: every run failed in {side} ({len(v.errors)} "
                           f"run(s); first: {why}): not compared")
    return out


# what a run's record says about how it was measured: two runs differing here measured
# different work, or on another device, or side by side with other runs (Ray runs tasks
# concurrently), so their time differences are not changes of the code
PLAN_FIELDS = ("size", "frames", "warmup", "scene", "settings", "executor", "device")


def _plan_of(record: dict[str, Any]) -> dict[str, Any]:
    out = {k: record.get(k) for k in PLAN_FIELDS}
    if isinstance(out["settings"], list):
        out["settings"] = sorted(map(str, out["settings"]))
    out["executor"] = record.get("executor") or "local"
    out["device"] = device_of(record)  # the adapter, and where a Ray task ran it
    return out


def _plans(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Each variant's plan; its devices are every device its runs measured."""
    out: dict[str, dict[str, Any]] = {}
    for r in records:
        if r.get("error"):
            continue
        plan = _plan_of(r)
        first = out.setdefault(r.get("variant"), {**plan, "device": []})
        if plan["device"] not in first["device"]:
            first["device"].append(plan["device"])
    for plan in out.values():
        plan["device"] = sorted(plan["device"])
        if len(plan["device"]) == 1:
            plan["device"] = plan["device"][0]
    return out


def _show(value: Any) -> str:
    if isinstance(value, list) and len(value) == 2 and all(isinstance(x, int) for x in value):
        return f"{value[0]}x{value[1]}"
    if isinstance(value, list):
        return "[" + ", ".join(map(str, value)) + "]"
    return str(value)


def mismatches(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[str]:
    """One line per variant in both sets whose plan (size, frames, warm-up, scene, settings,
    executor, device) differs between OLD and NEW, naming what differs."""
    first_old, first_new = _plans(old), _plans(new)
    out = []
    for label in [k for k in first_old if k in first_new]:
        a, b = first_old[label], first_new[label]
        diff = [f"{k} {_show(a[k])} vs {_show(b[k])}" for k in PLAN_FIELDS
                if a[k] != b[k]]
        if diff:
            out.append(f"{label}: measured differently: {'; '.join(diff)}")
    return out


def _load(path: Path, side: str) -> list[dict[str, Any]]:
    """The records of one side; none at all is an error: there is nothing to judge."""
    with naming(side):
        records = load_results(path)
    if not records:
        where = path / "results.jsonl" if path.is_dir() else path
        raise RfwError("no run records (the file is empty): nothing to compare",
                       file=str(where), element=side)
    return records


def compare(old: Path, new: Path, *, threshold: float = 0.05, fail_on_regression: bool = False,
            show_all: bool = False, out: Path | None = None,
            allow_mismatch: bool = False, diff_scale: str = "own") -> int:
    """Print the flagged changes, the passes measured on one side only and the inputs that
    changed (and write ``compare.md``/``.html`` into ``out``); returns the exit code (1 on a
    regression when asked). OLD and NEW measured differently (size, frames, warm-up, scene,
    settings, executor or device) are refused unless ``allow_mismatch``; then every report
    says so at its top. ``fail_on_regression`` with nothing measured on both sides is an
    RfwError: a gate that compared nothing must not pass."""
    threshold = check_number(threshold, "--threshold", lo=0.0, element="--threshold")
    old_records, new_records = _load(Path(old), "OLD"), _load(Path(new), "NEW")
    differ = mismatches(old_records, new_records)
    if differ and not allow_mismatch:
        more = f" (and {len(differ) - 1} more variant(s))" if len(differ) > 1 else ""
        raise RfwError(f"{differ[0]}{more}: their times are not comparable; pass "
                       "--allow-mismatch to compare anyway", element="bench compare")
    old_summaries, new_summaries = summarize_results(old_records), summarize_results(new_records)
    found, notes = _changes(old_summaries, new_summaries)
    single = one_sided(old_summaries, new_summaries)
    inputs = input_changes(old_records, new_records)
    costs = attributions(old_summaries, new_summaries)
    for line in differ:
        print(f"MISMATCH: {line}")
    if out is not None:
        md, page = write_compare(old, new, old_summaries, new_summaries, out, found=found,
                                 notes=notes, differ=differ, threshold=threshold,
                                 diff_scale=diff_scale, single=single, inputs=inputs,
                                 costs=costs)
        write_csv(out / "attribution.csv", costs)
        print(f"wrote {md}, {page}")
    flagged = [(c, c.verdict(threshold)) for c in found]
    rows = [(c, v) for c, v in flagged if show_all or v in ("regression", "improvement")]
    shown = [o for o in single if show_all or o.main]
    print(f"rfw bench compare: {old} -> {new} (threshold {threshold:.0%}, CIs must not "
          f"overlap)")
    for n in notes:
        print(f"  note: {n}")
    for line in inputs or (["unchanged (config, graph, scene, shaders)"] if found else []):
        print(f"  input: {line}")
    if rows or shown:
        w = max(len(f"{c.variant} {c.what}.{c.metric}") for c in [*(c for c, _ in rows),
                                                                  *shown])
        print(f"  {'variant pass.metric':<{w}} {'old ms':>10} {'new ms':>10} {'change':>8}  "
              f"verdict")
        for c, v in rows:
            name = f"{c.variant} {c.what}.{c.metric}"
            print(f"  {name:<{w}} {c.old['median']:>10.3f} {c.new['median']:>10.3f} "
                  f"{c.relative:>+8.1%}  {v}  [old {c.old['ci_lo']:.3f}-{c.old['ci_hi']:.3f},"
                  f" new {c.new['ci_lo']:.3f}-{c.new['ci_hi']:.3f}]")
        for o in shown:
            name = f"{o.variant} {o.what}.{o.metric}"
            cells = [f"{s['median']:>10.3f}" if s else f"{'-':>10}" for s in (o.old, o.new)]
            print(f"  {name:<{w}} {cells[0]} {cells[1]} {'-':>8}  {o.verdict}  "
                  f"[{o.side.lower()} {o.stats['ci_lo']:.3f}-{o.stats['ci_hi']:.3f}]")
    if costs:
        print("  frame GPU ms NEW - OLD, pass by pass (means, 95% CI; see compare.md):")
    for at in costs:
        print(f"    {summary_line(at)}")
    regressions = sum(1 for _, v in flagged if v == "regression")
    improvements = sum(1 for _, v in flagged if v == "improvement")
    few = sum(1 for c, _ in flagged if c.too_few)
    one = _one_sided_count(single)
    print(f"{regressions} regression(s), {improvements} improvement(s), "
          f"{len(flagged) - regressions - improvements - few} unchanged of {len(flagged)} "
          "compared" + (f"; {few} not judged: too few samples (under {MIN_SAMPLES} samples "
                        f"or {MIN_RUNS} runs a side; wall ms has one sample per run"
                        f"{'' if show_all else '; listed with --all'})" if few else "")
          + (f"; {one}" if one else ""))
    if fail_on_regression and not found:
        raise RfwError("nothing to compare: no pass or frame time was measured on both OLD "
                       "and NEW (a regression cannot be ruled out)",
                       element="--fail-on-regression")
    return 1 if fail_on_regression and regressions else 0


def _one_sided_count(single: list[OneSided]) -> str:
    """``2 measured in NEW only, 1 in OLD only`` (passes and variants, by their cost)."""
    cost = [o for o in single if o.main]
    n_new, n_old = (sum(1 for o in cost if o.side == side) for side in ("NEW", "OLD"))
    parts = [f"{n_new} measured in NEW only"] if n_new else []
    if n_old:
        parts.append(f"{n_old} {'in' if n_new else 'measured in'} OLD only")
    return ", ".join(parts)


def attributions(old: list[VariantSummary], new: list[VariantSummary]) -> list[Attribution]:
    """Each variant measured on both sides: its frame GPU ms change NEW - OLD, pass by pass."""
    olds = {v.label: v for v in old if v.ok}
    out = []
    for v in new:
        if v.ok and v.kind == "rfw" and v.label in olds:
            at = attribute(olds[v.label].records, v.records, variant=v.label, baseline="OLD",
                           device=", ".join(dict.fromkeys(device_of(r) for r in v.records)))
            if at is not None:
                out.append(at)
    return out


def _run_folder(path: Path) -> Path:
    return path if path.is_dir() else path.parent


def write_compare(old: Path, new: Path, old_summaries: list[VariantSummary],
                  new_summaries: list[VariantSummary], out: Path, *, found: list[Change],
                  notes: list[str], differ: list[str], threshold: float = 0.05,
                  diff_scale: str = "own", single: list[OneSided] | None = None,
                  inputs: list[str] | None = None,
                  costs: list[Attribution] | None = None) -> tuple[Path, Path]:
    """``out/compare.md`` and ``out/compare.html``: per-pass changes with significance and
    the image differences between the two runs (images copied into ``out/images``); an image
    rendered from another camera than its OLD one is not compared. ``found`` and ``notes``:
    :func:`changes` of the two summaries, ``differ``: their :func:`mismatches`, as
    :func:`compare` computed them; ``single``: their :func:`one_sided` entries (every
    metric is listed), ``inputs``: :func:`rfw.bench.inputs.input_changes`, ``costs``: their
    :func:`attributions`. ``diff_scale``: as in :func:`rfw.bench.report.write_report`."""
    from .images import compare as compare_images
    from .images import load_png, save_png
    from .report import Doc, Img, change_text, ci, db, diff_cell, image_camera, ms, write_diffs

    out.mkdir(parents=True, exist_ok=True)
    doc = Doc()
    doc.h(1, "rfw bench compare")
    if differ:
        doc.p("**Mismatch: OLD and NEW were not measured the same way** (compared with "
              "`--allow-mismatch`); the time differences below mix that with any change of "
              "the code.")
        doc.bullets(differ)
    doc.table(["what", "value"], [["OLD", f"`{old}`"], ["NEW", f"`{new}`"],
                                  ["threshold", f"{threshold:.0%}"]])
    doc.bullets(notes)
    doc.h(2, "Inputs")
    doc.p("What each run measured, hashed into its record: the config file, the graph it "
          "built, the scene and every shader source (with its includes). "
          + ("Between OLD and NEW:" if inputs else
             "The same on both sides." if found else "Nothing measured on both sides."))
    doc.bullets(list(inputs or []))
    doc.h(2, "Per pass")
    doc.p("Medians and 95% CIs of OLD and NEW (GPU and CPU ms over frames, wall ms per frame "
          "one number per run). `change`: `*` where the 95% CI of the ratio of the run "
          "medians excludes 1 (Welch's t-test), `(n.s.)` where not (within the noise), no mark below {MIN_SAMPLES} samples or {MIN_RUNS} "
          "runs on either side (`(n=3<6: no mark)`: too few to say); `verdict`: a significant "
          "change larger than the threshold; `added`/`removed`: a pass (or variant) "
          "measured in NEW or OLD only, with its cost on that side.")
    rows = [[c.variant, c.what, c.metric, ms(c.old), ci(c.old), ms(c.new), ci(c.new),
             change_text(c.old, c.new), c.verdict(threshold)] for c in found]
    # measured on one side only: an added or removed pass, listed with its cost
    rows += [[o.variant, o.what, o.metric, ms(o.old), ci(o.old), ms(o.new), ci(o.new), "-",
              o.verdict] for o in single or []]
    doc.table(["variant", "pass", "metric", "OLD ms", "OLD 95% CI", "NEW ms", "NEW 95% CI",
               "change", "verdict"], rows)
    if costs:
        from .report.attribution import INTRO, attribution_tables

        doc.h(2, "Frame change, pass by pass")
        doc.p("Each variant's NEW against its OLD. " + INTRO)
        for at in costs:
            doc.h(3, at.variant)
            attribution_tables(doc, [at], base="OLD", own="NEW", titles=False)
    olds = {v.label: v for v in old_summaries if v.ok and v.image}
    news = {v.label: v for v in new_summaries if v.ok and v.image}
    both = [k for k in olds if k in news]
    if both:
        doc.h(2, "Images")
        doc.p("Each variant's NEW image against its OLD one: |OLD - NEW|, max over RGB, "
              + ("colour-mapped from black (0) to the largest difference of all the images "
                 "(`--diff-scale shared`; each legend states the scale and the image's own "
                 "largest difference)." if diff_scale == "shared" else
                 "colour-mapped from black (0) to the largest difference of that image: each "
                 "image has its own scale, stated below it (`scale 0-4/255`); "
                 "`--diff-scale shared` draws them all on one."))
        table, rows = [], []
        for n, label in enumerate(both):
            a = load_png(inside(_run_folder(old), olds[label].image))
            b = load_png(inside(_run_folder(new), news[label].image))
            files = {k: Path("images") / f"{n}_{k}.png" for k in ("old", "new")}
            save_png(inside(out, files["old"]), a)
            save_png(inside(out, files["new"]), b)
            cells: list[Any] = [label, Img(str(files["old"]), "old"),
                                Img(str(files["new"]), "new")]
            (cam_a, text_a), (cam_b, text_b) = image_camera(olds[label]), image_camera(news[label])
            row: dict[str, Any] = {"cells": cells}
            if cam_a != cam_b:  # another view: a PSNR would measure the views, not the code
                what = "scenes" if cam_a[1] != cam_b[1] else "cameras"
                row["camera"] = (f"different {what}: not compared (OLD: {text_a}; "
                                 f"NEW: {text_b})")
            elif a.shape == b.shape:
                c = compare_images(a, b)
                row.update(psnr=c["psnr"], diff_max=c["diff_max"], abs_diff=c["abs_diff"],
                           files=(Path("images") / f"{n}_diff.png",
                                  Path("images") / f"{n}_legend.png"))
            rows.append(row)
        write_diffs(out, rows, diff_scale)  # images/<n>_diff.png, <n>_legend.png
        for row in rows:
            if row.get("camera"):
                table.append([*row["cells"], row["camera"], "not compared"])
            elif row.get("diff"):
                table.append([*row["cells"], diff_cell(row), db(row["psnr"])])
            else:
                table.append([*row["cells"], "other size", "-"])
        if any(row.get("camera") for row in rows):
            doc.p("**Different cameras:** a NEW image rendered from another camera than its "
                  "OLD one (a camera path's last frame, another static camera or another "
                  "scene) is not compared: a PSNR between two views measures the views, not "
                  "the code.")
        doc.table(["variant", "OLD", "NEW", "difference", "PSNR"], table)
    md, page = out / "compare.md", out / "compare.html"
    md.write_text(doc.markdown(), encoding="utf-8")
    page.write_text(doc.html("rfw bench compare", out), encoding="utf-8")
    return md, page
