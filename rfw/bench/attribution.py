"""What a change costs, pass by pass: the frame total's GPU ms change between two sets of runs
(a variant against a baseline, NEW against OLD) split into what each pass contributes.

Passes are matched by name. A pass timed on both sides contributes its difference
(``changed``), one timed in the variant only its whole time (``added``), one timed in the
baseline only minus its time (``removed``); a renamed pass therefore shows as one removed and
one added. The ``residual`` is the frame total's change less the passes' changes: work no pass
timer saw (passes overlapping or running async, passes without timers, a frame timer's own
overhead). The parts add up to the frame total's change exactly.

Means per frame, not medians: only means add up (the median of a frame total is not the sum
of its passes' medians), so the frame change here can differ from the medians' change of the
frame table. Each part's 95% CI is a percentile bootstrap of the difference: each side
resamples its runs, then frames inside each picked run (as :mod:`rfw.bench.stats` does for a
median), and the frame total and every pass are read from the *same* picked frames, so in each
resample the parts add up to the total too. Few runs make that interval too narrow (resampling
R runs understates their spread by (R - 1) / R, and the spread itself is uncertain): each
side's resampled means are spread by sqrt(R / (R - 1)) and the interval is stretched by
Student's t over the normal 97.5% point, with (runs - 2) degrees of freedom. On synthetic A/A
pairs of 3 runs a side whose runs shift by 1-2% the bare percentile bootstrap marked 15-20%,
this 1-7% (``tests/bench/test_attribution.py``). A part is marked ``*`` when its CI excludes 0,
``(n.s.)`` when it holds 0, and gets no mark where either side rests on too few frames or runs
(:func:`rfw.bench.stats.no_mark`: ``(n=3<6: no mark)``, ``(1 run: no mark)``)."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .stats import RESAMPLES, SEED, no_mark

TOTAL, RESIDUAL = "frame total", "residual"
KINDS = ("changed", "added", "removed", RESIDUAL, "total")
# a residual this small is rounding of the passes' sum (timestamps resolve ns, 1e-6 ms)
SNAP = 1e-9
BLOCK = 250  # resamples per block: bounds the (resamples x frames) count matrix


@dataclass
class Part:
    """One line of an attribution: a pass (or the residual, or the frame total), its mean ms
    per frame on each side, the change and its 95% CI."""

    name: str  # a pass name, RESIDUAL or TOTAL
    kind: str  # one of KINDS
    base: float  # mean ms per frame in the baseline (0 where the pass was added)
    own: float  # mean ms per frame in the variant (0 where the pass was removed)
    ci_lo: float
    ci_hi: float
    mark: str

    @property
    def change(self) -> float:
        return self.own - self.base


@dataclass
class Attribution:
    """The frame total's change of ``variant`` against ``baseline`` and its parts."""

    variant: str
    baseline: str
    device: str
    parts: list[Part]  # passes in frame order, then the residual
    total: Part
    frames: tuple[int, int]  # frames (baseline, variant) the means rest on
    runs: tuple[int, int]
    notes: list[str] = field(default_factory=list)


@dataclass
class _Side:
    runs: list[np.ndarray]  # per run (frames, 1 + passes): frame total, then each pass
    timed: set[str]  # the passes with a GPU time in some frame
    summary: dict[str, Any] | None  # {n, runs} of the frame totals (stats.no_mark reads them)
    untimed: int  # pass values missing in frames that have a frame total


def _gpu(values: Any, i: int) -> float | None:
    return values[i] if isinstance(values, list) and i < len(values) else None


def _side(records: list[dict[str, Any]], names: list[str]) -> _Side:
    """The frames of ``records`` as matrices; a pass without a time in a frame counts 0 there
    (its time, if any, is then in that frame's residual)."""
    runs, timed, untimed = [], set(), 0
    for r in records:
        total = [x for x in ((r.get("frame") or {}).get("gpu_ms") or [])]
        by_name = {p["name"]: p.get("gpu_ms") or [] for p in r.get("passes") or []}
        rows = []
        for i, t in enumerate(total):
            if t is None:
                continue  # no frame total: nothing to split
            row = [float(t)]
            for n in names:
                v = _gpu(by_name.get(n), i)
                untimed += v is None and n in by_name and bool(by_name[n])
                row.append(0.0 if v is None else float(v))
            rows.append(row)
        timed.update(n for n, v in by_name.items() if any(x is not None for x in v))
        if rows:
            runs.append(np.asarray(rows, np.float64))
    summary = {"n": sum(m.shape[0] for m in runs), "runs": len(runs)} if runs else None
    return _Side(runs, timed, summary, untimed)


def _with_residual(m: np.ndarray) -> np.ndarray:
    """Columns: each pass, then the residual (total - passes), then the frame total."""
    resid = m[:, 0] - m[:, 1:].sum(axis=1)
    resid[np.abs(resid) <= SNAP * np.maximum(1.0, np.abs(m[:, 0]))] = 0.0
    return np.column_stack([m[:, 1:], resid, m[:, 0]])


def _resampled_means(runs: list[np.ndarray], rng: np.random.Generator,
                     resamples: int) -> np.ndarray:
    """(resamples, columns): the mean of every column over the frames of one two-level
    resample (runs with replacement, then as many frames as the run has, with replacement,
    inside each picked run); every column is read from the same picked frames."""
    data = np.concatenate(runs)
    lengths = np.array([m.shape[0] for m in runs])
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    n_runs, longest = len(runs), int(lengths.max())
    out = []
    for b0 in range(0, resamples, BLOCK):
        b = min(BLOCK, resamples - b0)
        pick = rng.integers(0, n_runs, size=(b, n_runs))
        lens = lengths[pick][..., None]  # (b, runs, 1)
        frame = np.minimum((rng.random((b, n_runs, longest)) * lens).astype(np.int64), lens - 1)
        keep = np.arange(longest)[None, None, :] < lens  # a short run picks fewer frames
        rows = (starts[pick][..., None] + frame)[keep]
        which = np.broadcast_to(np.arange(b)[:, None, None], keep.shape)[keep]
        counts = np.zeros((b, data.shape[0]))
        np.add.at(counts, (which, rows), 1.0)
        out.append(counts @ data / counts.sum(axis=1, keepdims=True))
    return np.concatenate(out)


Z975 = 1.959964  # the normal distribution's 97.5% point


def _widened(means: np.ndarray, center: np.ndarray, runs: int) -> np.ndarray:
    """Resampled means spread by sqrt(R / (R - 1)) about ``center``: resampling R runs with
    replacement understates the variance between them by (R - 1) / R (a third at 3 runs)."""
    return means if runs < 2 else center + (means - center) * np.sqrt(runs / (runs - 1))


def _t975(df: int) -> float:
    """Student's t 97.5% point for ``df`` degrees of freedom (Cornish-Fisher expansion; within
    0.13 of the table at df=2, 0.01 from df=4): with few runs the spread between them is itself
    uncertain, so the interval of their mean is wider than the normal one."""
    if df < 1:
        return Z975
    z, n = Z975, float(df)
    return (z + (z**3 + z) / (4 * n) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * n**2)
            + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * n**3))


def _mark(lo: float, hi: float, why: str | None) -> str:
    if why:
        return f"({why}: no mark)"
    return "*" if lo > 0 or hi < 0 else "(n.s.)"


def attribute(base: list[dict[str, Any]], own: list[dict[str, Any]], *, variant: str,
              baseline: str, device: str = "", resamples: int = RESAMPLES,
              seed: int = SEED) -> Attribution | None:
    """The frame total's GPU ms change from the runs ``base`` to the runs ``own`` (run
    records as in ``results.jsonl``), pass by pass; None where either side has no frame with
    a GPU frame total (no timestamps)."""
    names: list[str] = []
    for r in [*base, *own]:  # frame order: a pass the baseline lacks after its predecessor
        before = -1
        for p in r.get("passes") or []:
            if p["name"] in names:
                before = names.index(p["name"])
            elif any(x is not None for x in p.get("gpu_ms") or []):
                before += 1
                names.insert(before, p["name"])
    a, b = _side(base, names), _side(own, names)
    if not a.runs or not b.runs:
        return None
    ma = [_with_residual(m) for m in a.runs]
    mb = [_with_residual(m) for m in b.runs]
    rng = np.random.default_rng(seed)
    mean_a, mean_b = np.concatenate(ma).mean(axis=0), np.concatenate(mb).mean(axis=0)
    diffs = (_widened(_resampled_means(mb, rng, resamples), mean_b, len(mb))
             - _widened(_resampled_means(ma, rng, resamples), mean_a, len(ma)))
    lo, hi = np.quantile(diffs, [0.025, 0.975], axis=0)
    est, stretch = mean_b - mean_a, _t975(len(ma) + len(mb) - 2) / Z975
    lo, hi = est - stretch * (est - lo), est + stretch * (hi - est)
    why = no_mark(a.summary, b.summary)
    parts = []
    for j, n in enumerate([*names, RESIDUAL, TOTAL]):
        if n == TOTAL:
            kind = "total"
        elif n == RESIDUAL:
            kind = RESIDUAL
        else:
            kind = ("changed" if n in b.timed else "removed") if n in a.timed else "added"
        parts.append(Part(n, kind, float(mean_a[j]), float(mean_b[j]), float(lo[j]),
                          float(hi[j]), _mark(float(lo[j]), float(hi[j]), why)))
    notes = [f"{side}: {k} pass time(s) missing in frames with a frame total: counted in "
             "the residual" for side, k in (("baseline", a.untimed), ("variant", b.untimed))
             if k]
    return Attribution(variant, baseline, device, parts[:-1], parts[-1],
                       (a.summary["n"], b.summary["n"]), (a.summary["runs"],
                                                          b.summary["runs"]), notes)


CSV_FIELDS = ("variant", "baseline", "device", "part", "kind", "baseline_ms", "variant_ms",
              "change_ms", "ci_lo", "ci_hi", "mark", "baseline_frames", "baseline_runs",
              "variant_frames", "variant_runs")


def write_csv(path: Path, attributions: list[Attribution]) -> Path:
    """``attribution.csv``: one row per (pair, part), the frame total last of each pair; the
    ``change_ms`` of a pair's other rows add up to its frame total's."""
    with Path(path).open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_FIELDS)
        for at in attributions:
            for p in [*at.parts, at.total]:
                w.writerow([at.variant, at.baseline, at.device, p.name, p.kind,
                            *(round(x, 6) for x in (p.base, p.own, p.change, p.ci_lo,
                                                    p.ci_hi)),
                            p.mark, at.frames[0], at.runs[0], at.frames[1], at.runs[1]])
    return Path(path)


def summary_line(at: Attribution) -> str:
    """One line for a terminal: the frame change and the parts beyond the noise."""
    t = at.total
    head = f"{at.variant}: frame {t.change:+.3f} ms [{t.ci_lo:+.3f}, {t.ci_hi:+.3f}] {t.mark}"
    if t.mark not in ("*", "(n.s.)"):
        return head  # too few frames or runs: no part is marked either
    sure = [f"{p.name} {p.change:+.3f} ({p.kind})" for p in at.parts if p.mark == "*"]
    rest = len(at.parts) - len(sure)
    return (head + (" = " + ", ".join(sure) if sure else "")
            + (f"; {rest} part(s) within the noise" if rest else ""))
