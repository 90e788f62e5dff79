"""Robust summaries of timing samples: median, p5-p95 spread and a bootstrap CI of the median,
and the rule that decides whether two of them differ beyond the noise.

Everything is seeded, so one set of samples always gives the same numbers.

Significance: two medians differ when their 95% CIs do not overlap, and only when each CI
rests on at least :data:`MIN_SAMPLES` samples from at least :data:`MIN_RUNS` runs. Below
:data:`MIN_SAMPLES` no 95% interval of a median exists without assuming a distribution (even
the samples' whole range covers the median with probability ``1 - 2 * 0.5**n``: 94% at n=5,
97% at n=6), and the percentile bootstrap then returns about that range; from one run alone
the run-to-run noise (another process, another memory layout) is not measured."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

RESAMPLES = 2000
SEED = 20240607
MIN_SAMPLES = 6  # the smallest n with a distribution-free 95% interval of the median
MIN_RUNS = 2  # one run says nothing of the noise between runs


def bootstrap_ci(samples: Sequence[float], *, level: float = 0.95, resamples: int = RESAMPLES,
                 seed: int = SEED) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the median of ``samples``.

    One sample gives a zero-width interval at that value; none raises ``ValueError``. Below
    :data:`MIN_SAMPLES` samples the interval is about the samples' range (n=2: min-max),
    not a 95% interval: :func:`no_mark` says so."""
    x = np.asarray(samples, np.float64)
    if x.size == 0:
        raise ValueError("bootstrap_ci needs at least one sample")
    if x.size == 1:
        return float(x[0]), float(x[0])
    rng = np.random.default_rng(seed)
    # resample indices in one block: (resamples, n) is small for benchmark sample counts
    picks = x[rng.integers(0, x.size, size=(resamples, x.size))]
    medians = np.median(picks, axis=1)
    alpha = (1.0 - level) / 2
    lo, hi = np.quantile(medians, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def bootstrap_ci_runs(runs: Sequence[Sequence[float]], *, level: float = 0.95,
                      resamples: int = RESAMPLES, seed: int = SEED) -> tuple[float, float]:
    """Two-level bootstrap CI of the median over frames grouped by run (process): resample
    the runs, then the frames inside each picked run. A run-to-run shift (another process,
    another memory layout, machine drift) then widens the interval, as it should; frames of
    one process alone would understate it. Runs of unequal length fall back to frames."""
    runs = [np.asarray(r, np.float64) for r in runs if len(r)]
    if not runs:
        raise ValueError("bootstrap_ci_runs needs at least one sample")
    if len(runs) == 1 or len({r.size for r in runs}) != 1:
        return bootstrap_ci(np.concatenate(runs), level=level, resamples=resamples, seed=seed)
    m = np.stack(runs)  # (R, F)
    r, f = m.shape
    rng = np.random.default_rng(seed)
    pick_run = rng.integers(0, r, size=(resamples, r, 1))
    pick_frame = rng.integers(0, f, size=(resamples, r, f))
    medians = np.median(m[pick_run, pick_frame].reshape(resamples, r * f), axis=1)
    alpha = (1.0 - level) / 2
    lo, hi = np.quantile(medians, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def summarize(samples: Sequence[float] | Sequence[Sequence[float]] | None, *,
              seed: int = SEED) -> dict[str, Any] | None:
    """``{n, runs, median, mean, p5, p95, ci_lo, ci_hi}``; None for no samples.

    ``samples`` is one flat list, or one list per run (the CI then resamples runs too, see
    :func:`bootstrap_ci_runs`); median and percentiles are over all samples."""
    if samples is None:
        return None
    groups = [list(g) for g in samples] if samples and isinstance(
        samples[0], list | tuple | np.ndarray) else [list(samples)]
    groups = [[v for v in g if v is not None] for g in groups]
    groups = [g for g in groups if g]
    if not groups:
        return None
    x = np.concatenate([np.asarray(g, np.float64) for g in groups])
    p5, med, p95 = np.percentile(x, [5, 50, 95])
    lo, hi = bootstrap_ci_runs(groups, seed=seed)
    return {"n": int(x.size), "runs": len(groups), "median": float(med),
            "mean": float(x.mean()), "p5": float(p5), "p95": float(p95), "ci_lo": lo,
            "ci_hi": hi}


def summarize_runs(values: Sequence[float | None]) -> dict[str, Any] | None:
    """:func:`summarize` of one number per run (a run's median, or its wall time / frames):
    the median and CI across runs, ``n`` = ``runs`` = the number of runs."""
    return summarize([[v] for v in values if v is not None])


def summarize_passes(renders: Sequence[Mapping[str, float | None]]
                     ) -> dict[str, dict[str, Any] | None]:
    """Per pass, :func:`summarize_runs` over renders: ``renders`` holds one ``{pass: ms}``
    per render (e.g. each render's ``Result.gpu_ms``, itself a median over its frames), so
    the median and CI are across renders; None for a pass without times."""
    names = list(dict.fromkeys(k for r in renders for k in r))
    return {k: summarize_runs([r.get(k) for r in renders]) for k in names}


def no_mark(*summaries: dict[str, Any] | None) -> str | None:
    """Why a difference between these summaries gets no significance mark (``"n=3<6"``,
    ``"1 run"``), or None when each has enough samples and runs for one."""
    for s in summaries:
        if not s:
            continue
        if s["n"] < MIN_SAMPLES:
            return f"n={s['n']}<{MIN_SAMPLES}"
        if s["runs"] < MIN_RUNS:
            return f"{s['runs']} run"
    return None


def significant(a: dict[str, Any] | None, b: dict[str, Any] | None) -> bool:
    """Whether two medians differ beyond the noise: their 95% CIs do not overlap and both
    rest on enough samples (:func:`no_mark`)."""
    if not a or not b or no_mark(a, b):
        return False
    return a["ci_hi"] < b["ci_lo"] or b["ci_hi"] < a["ci_lo"]


def mark(a: dict[str, Any] | None, b: dict[str, Any] | None) -> str:
    """The significance mark of the difference between ``a`` and ``b``: ``*`` (the CIs do
    not overlap), ``(n.s.)`` (they do: within the noise) or ``(n=3<6: no mark)`` (too few
    samples or runs to say)."""
    why = no_mark(a, b)
    if why:
        return f"({why}: no mark)"
    return "*" if significant(a, b) else "(n.s.)"


def change_text(ref: dict[str, Any] | None, own: dict[str, Any] | None) -> str:
    """``own`` against ``ref``: ``+15.0% *``, ``+15.0% (n.s.)`` or ``+15.0% (n=3<6: no
    mark)`` (see :func:`mark`); ``-`` when either is missing."""
    if not ref or not own or not ref["median"]:
        return "-"
    return f"{own['median'] / ref['median'] - 1:+.1%} {mark(ref, own)}"
