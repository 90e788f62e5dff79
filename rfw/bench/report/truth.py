"""The report's "Error against the truth" section (``--reference pathtrace[:SPP]``): each
variant's error against the path tracer's reference of its view beside its GPU ms, the
error-versus-cost fronts per technique family as charts, the dominated configurations
named, the references with their cost and noise floor; and the numbers as ``truth.csv``
and as rows of ``results.csv``. The measures are :mod:`rfw.bench.truth`'s."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from ...fileio import inside, read_exr
from ..images import PNG_METADATA, load_png
from ..stats import no_mark
from ..summary import VariantSummary
from ..truth import META_FILE, Point, dominance, errors, family_of, front, front_metric
from .document import Doc, Img, ci, ms

TRUTH_JSON = "truth.json"
METRICS = (("hdr_flip", "HDR-FLIP"), ("hdr_flip_p99", "HDR-FLIP p99"),
           ("rel_mse", "relMSE"), ("rmse", "RMSE"), ("flip", "FLIP (display)"))
WORDS = {"hdr_flip": "HDR-FLIP (mean)", "hdr_flip_p99": "HDR-FLIP (99th percentile)",
         "rel_mse": "relative MSE", "rmse": "RMSE", "flip": "FLIP (mean, displayed image)"}


COMPONENT_WORDS = {
    "full": "Every variant's linear image before tone mapping against the path-traced "
            "radiance, global illumination included: what no raster pass computes counts "
            "against it.",
    "ao": "The ambient occlusion the lighting pass reads (ones without an AO pass) against "
          "the path tracer's AO of the same radius, on pixels wholly on the scene.",
    "direct": "The punctual lights' direct light alone (the lighting pass's ambient term "
              "off; the path tracer without sky and bounces) over each pixel's footprint, "
              "on pixels the scene covers.",
    "direct_centre": "The punctual lights' direct light alone through pixel centres (the "
                     "path tracer without sky, bounces or jitter), on pixels wholly on the "
                     "scene: shadows apart from anti-aliasing.",
}


def truth_rows(out_dir: Path, pooled: list[VariantSummary]) -> tuple[dict, list[dict]] | None:
    """``(truth.json, one row per variant)``: the variant, its family, its GPU ms summary and
    :func:`rfw.bench.truth.errors` against its view's reference; None without a truth."""
    path = out_dir / TRUTH_JSON
    if not path.is_file():
        return None
    truth = json.loads(path.read_text(encoding="utf-8"))
    refs = truth.get("references") or {}
    loaded: dict[str, tuple[Any, Any] | None] = {}
    rows = []
    for v in pooled:
        if not v.ok:
            continue
        key = (truth.get("variants") or {}).get(v.label)
        ref = refs.get(key) if key else None
        row: dict[str, Any] = {"variant": v, "family": family_of(v.first), "key": key,
                               "gpu": v.frame.get("gpu_ms"), "errors": {}}
        if ref is None or ref.get("error"):
            row["why"] = "no reference" if ref is None else f"reference failed: {ref['error']}"
            rows.append(row)
            continue
        if key not in loaded:
            folder = inside(out_dir, ref["folder"])
            loaded[key] = (read_exr(folder / "hdr.exr"), load_png(folder / "ldr.png")) \
                if (folder / META_FILE).is_file() else None
        if loaded[key] is None:
            row["why"] = "reference missing"
            rows.append(row)
            continue
        ref_hdr, ref_ldr = loaded[key]
        own = next((r["hdr"] for r in v.records if isinstance(r.get("hdr"), dict)), {})
        linear = own.get("file")
        test_hdr = read_exr(inside(out_dir, linear)) if linear else None
        shown = own.get("display") or v.image  # direct*: the replay's, with ambient off
        test_ldr = load_png(inside(out_dir, shown)) if shown else None
        row["errors"] = errors(ref_hdr, test_hdr, ref_ldr, test_ldr,
                               component=truth.get("component", "full"))
        if test_hdr is None:
            row["why"] = f"no image to judge: {own.get('missing', 'not written')}"
        rows.append(row)
    return truth, rows


def points(rows: list[dict], metric: str) -> list[Point]:
    out = []
    for r in rows:
        e, g = r["errors"].get(metric), r["gpu"]
        if e is None or not g:
            continue
        out.append(Point(r["variant"].label, r["family"], g["median"], g["ci_lo"], g["ci_hi"],
                         e["value"], e["ci_lo"], e["ci_hi"], ms_ci=not no_mark(g)))
    return out


def chosen_metric(rows: list[dict], component: str) -> tuple[str, str] | None:
    """The error the fronts are drawn against (:func:`rfw.bench.truth.front_metric`), or
    the displayed image's FLIP where no variant has that one."""
    have = [r for r in rows if r["gpu"] and r["errors"]]
    for metric in (front_metric(component), "flip"):
        if have and any(metric in r["errors"] for r in have):
            return metric, WORDS[metric]
    return None


def _value(e: dict[str, float] | None, digits: int = 4) -> str:
    if not e:
        return "-"
    return f"{e['value']:.{digits}f} [{e['ci_lo']:.{digits}f}-{e['ci_hi']:.{digits}f}]"


def _truth(doc: Doc, out_dir: Path, pooled: list[VariantSummary]) -> list[dict]:
    """Write the section; returns its rows (for the CSV files)."""
    got = truth_rows(out_dir, pooled)
    if got is None:
        return []
    truth, rows = got
    doc.h(2, "Error against the truth")
    refs = truth.get("references") or {}
    sets = truth.get("reference_sets") or []
    component = truth.get("component", "full")
    doc.p(f"Component: **{component}** " + (f"(the path tracer with {', '.join(sets)}). "
                                            if sets else "(the whole image). ")
          + COMPONENT_WORDS.get(component.partition("=")[0], ""))
    doc.p(f"Reference: the path tracer (`--reference {truth.get('reference')}`, "
          "`configs/pathtrace.toml`: next-event estimation with MIS, Russian roulette, "
          "Owen-scrambled Sobol samples, pixel-footprint jitter) rendered at each variant's "
          "view (scene, camera, size; a camera path's last frame). Errors are of each "
          "variant's first run: HDR-FLIP (mean and 99th percentile) and relative MSE "
          "(`(x - y)² / (y² + 0.01)`, mean over pixels and channels) on the linear image "
          "the tonemap pass reads, FLIP on the displayed 8-bit image; in brackets the 95% "
          "CI of a bootstrap over 16x16-pixel tiles (how much the number depends on which "
          "parts of the image there are). `noise floor`: the relative MSE a perfect "
          "technique would score against the reference, from its convergence estimate.")
    table = []
    for key, ref in refs.items():
        view = ref.get("view") or {}
        where = ", ".join(view.get("camera") or []) or "the scene's camera"
        if ref.get("error"):
            table.append([key, where, "-", "-", "-", "-", f"failed: {ref['error']}", "-"])
            continue
        noise = ref.get("noise") or {}
        shown = f"{ref['folder']}/ldr.png"
        table.append([
            Img(shown, "reference", 200) if (out_dir / shown).is_file() else "image missing",
            where,
            f"{ref['size'][0]}x{ref['size'][1]}, {ref['spp']} spp",
            f"{ref['render_s']:.1f} s", f"{ref['samples_per_s'] / 1e6:.3f} M",
            f"{noise.get('rel_mse', float('nan')):.2e}",
            f"{ref.get('device')} ({ref.get('method')}); {ref.get('source')}",
            f"{ref.get('driver')}"])
    doc.table(["reference", "camera", "size, samples", "render", "samples/s",
               "noise floor (relMSE)", "device; source", "driver"], table)
    chosen = chosen_metric(rows, component)
    dominated: dict[str, list[tuple[str, bool]]] = {}
    on_front: set[str] = set()
    if chosen:
        pts = points(rows, chosen[0])
        dominated = dominance(pts)
        on_front = {p.label for p in front(pts)}
        fronts = _front_chart(out_dir, rows, pts, chosen)
        if fronts:
            doc.image(fronts)
    for r in rows:
        r["dominated_by"] = dominated.get(r["variant"].label, [])
        r["on_front"] = r["variant"].label in on_front
    headers = ["variant", "family", "GPU ms [95% CI]", *(w for _, w in METRICS), "front",
               "dominated by"]
    body = []
    for r in rows:
        g = r["gpu"]
        cells = [r["variant"].label, r["family"],
                 f"{ms(g)} [{ci(g)}]" if g else "-",
                 *(_value(r["errors"].get(m), 5 if m == "rel_mse" else 4) for m, _ in METRICS)]
        cells.append("yes" if r["on_front"] else "-" if not r["dominated_by"] else "no")
        cells.append(_dominated_text(r) if r["dominated_by"] else r.get("why", "-"))
        body.append(cells)
    doc.table(headers, body)
    named = [r for r in rows if r["dominated_by"]]
    if chosen:
        doc.p(f"Fronts against {chosen[1]}. A variant is dominated when another is no slower "
              "and no worse (medians) and better in one; `*`: beyond the CIs (better on one "
              "axis with the two 95% CIs apart; GPU ms only where both have enough samples "
              "and runs for a CI), `(n.s.)`: by the medians only."
              + (" Dominated: " + "; ".join(f"**{r['variant'].label}** by "
                                            f"{_dominated_text(r)}" for r in named) + "."
                 if named else " No variant is dominated."))
    return rows


def _dominated_text(r: dict) -> str:
    by = sorted(r["dominated_by"], key=lambda x: not x[1])
    return ", ".join(f"{label} {'*' if sure else '(n.s.)'}" for label, sure in by)


def _front_chart(out_dir: Path, rows: list[dict], pts: list[Point],
                 chosen: tuple[str, str]) -> Img | None:
    if not pts:
        return None
    path = out_dir / "charts" / f"front_{chosen[0]}.png"
    draw_front(path, pts, chosen[1])
    return Img(str(path.relative_to(out_dir)), "error-versus-cost fronts", 720)


def draw_front(path: Path, pts: list[Point], words: str, *, title: str | None = None) -> Path:
    """GPU ms (median, 95% CI) against the error (95% CI), one colour per family with its
    own front as a step line, the front of all variants dashed; written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = list(dict.fromkeys(p.family for p in pts))
    cmap = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for i, fam in enumerate(families):
        mine = [p for p in pts if p.family == fam]
        color = cmap(i % 10)
        ax.errorbar([p.ms for p in mine], [p.err for p in mine],
                    xerr=[[p.ms - p.ms_lo for p in mine], [p.ms_hi - p.ms for p in mine]],
                    yerr=[[p.err - p.err_lo for p in mine], [p.err_hi - p.err for p in mine]],
                    fmt="o", color=color, ecolor=color, elinewidth=0.8, capsize=2,
                    markersize=5, label=fam)
        line = front(mine)
        if len(line) > 1:
            ax.step([p.ms for p in line], [p.err for p in line], where="post", color=color,
                    linewidth=1.0, alpha=0.8)
        for p in mine:
            ax.annotate(_short_label(p.label), (p.ms, p.err), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")
    best = front(pts)
    ax.step([p.ms for p in best], [p.err for p in best], where="post", color="black",
            linestyle="--", linewidth=1.0, label="front of all")
    ax.set_xlabel("frame GPU ms (median, 95% CI)")
    ax.set_ylabel(words + " vs path-traced reference (95% CI)")
    ax.set_title(title or "error against the truth vs cost: lower left is better")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small", loc="best")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, metadata=PNG_METADATA)
    plt.close(fig)
    return path


def points_from_csv(path: Path, metric: str) -> list[Point]:
    """The points of a ``truth.csv`` against ``metric`` (a fronts' redrawing without the
    images: every number it needs is in the file)."""
    out = []
    with open(path, encoding="utf-8", newline="") as f:
        for r in csv.DictReader(f):
            if not r.get(metric) or not r.get("gpu_ms"):
                continue
            out.append(Point(r["variant"], r["family"], float(r["gpu_ms"]),
                             float(r["gpu_ms_ci_lo"]), float(r["gpu_ms_ci_hi"]),
                             float(r[metric]), float(r[f"{metric}_ci_lo"]),
                             float(r[f"{metric}_ci_hi"])))
    return out


def _short_label(label: str) -> str:
    """The swept settings of a label (``ssao.samples=8``), or the label."""
    inside_ = label.partition("[")[2].partition("]")[0]
    keep = [c for c in inside_.split(",") if "." in c.partition("=")[0]]
    return ",".join(keep) or label


TRUTH_CSV_FIELDS = ("variant", "family", "gpu_ms", "gpu_ms_ci_lo", "gpu_ms_ci_hi",
                    *(f"{m}{s}" for m, _ in METRICS for s in ("", "_ci_lo", "_ci_hi")),
                    "on_front", "dominated_by")


def write_truth_csv(path: Path, rows: list[dict]) -> Path:
    """One row per variant: GPU ms and every error with its CI, whether it is on the front
    and what dominates it (``*`` beyond the CIs)."""
    with path.open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRUTH_CSV_FIELDS)
        for r in rows:
            g = r["gpu"] or {}
            cells: list[Any] = [r["variant"].label, r["family"],
                                *(_round(g.get(k)) for k in ("median", "ci_lo", "ci_hi"))]
            for m, _ in METRICS:
                e = r["errors"].get(m) or {}
                cells += [_round(e.get(k)) for k in ("value", "ci_lo", "ci_hi")]
            cells.append(int(bool(r.get("on_front"))))
            cells.append("; ".join(f"{lab}{' *' if sure else ''}"
                                   for lab, sure in r.get("dominated_by") or []))
            w.writerow(cells)
    return path


def _round(x: Any) -> Any:
    return "" if x is None else round(float(x), 8)


def csv_rows(rows: list[dict]) -> list[list[Any]]:
    """The errors as rows of ``results.csv`` (pass ``truth``; ``median`` holds the value)."""
    out = []
    for r in rows:
        v = r["variant"]
        for m, _ in METRICS:
            e = r["errors"].get(m)
            if e:
                out.append([v.label, v.kind, "", v.get("backend", ""), "truth", m, "", 1,
                            round(e["value"], 8), round(e["ci_lo"], 8), round(e["ci_hi"], 8),
                            "", "", round(e["value"], 8)])
    return out
