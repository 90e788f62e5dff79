"""Robust summaries of timing samples: median, p5-p95 spread and a bootstrap CI of the median;
the rule that decides whether two of them differ beyond the noise; and the power of that rule.

Everything is seeded, so one set of samples always gives the same numbers.

Significance (:func:`significant`, :func:`mark`): the run (one process) is the unit of
replication. Each run is reduced to its median frame, and the two sides' log run medians are
compared by Welch's t-test; the difference is marked when the 95% CI of the ratio of the sides'
geometric mean run medians (:func:`difference`) excludes 1. Frames of one process are not
independent samples of the bench: a run-to-run shift (another process, another memory layout,
clocks) moves all of them together, and consecutive frames are correlated, so a test that
counts frames, or the overlap of per-side CIs resampled from two or three runs, marks A/A
pairs far more often than 5% (with 3% run offsets and 3% frame noise, the old rule, "the two
run-level bootstrap CIs do not overlap", marked 13% of A/A pairs at 2 runs x 10 frames a side,
and a CI of all frames pooled 19% at 3 x 10).
The t-test on run medians is exact for normal run medians whatever happens inside a run
(autocorrelation, spikes: the median absorbs them), and Welch's degrees of freedom keep it at
or under 5% when the sides' noise differs; tests/bench/test_stats_calibration.py checks the
rate on synthetic A/A pairs (4.0% of 200) and benchmarks/aa_pairs.py on real ones. The test
takes runs as independent: interleave the sides (``rfw bench`` rotates the variants in every
repeat), since a machine whose load drifts over several runs makes neighbouring runs alike. A
side whose run medians are all equal takes the variance its frames imply. The price is honest
power: with 2 runs a side the t quantile is 4.3-12.7, so a small change needs more runs, and
:func:`needed` says how many (the report's "Power" section).

A mark needs at least :data:`MIN_SAMPLES` samples from at least :data:`MIN_RUNS` runs a side.
Below :data:`MIN_SAMPLES` no 95% interval of a median exists without assuming a distribution
(even the samples' whole range covers the median with probability ``1 - 2 * 0.5**n``: 94% at
n=5, 97% at n=6), and the percentile bootstrap then returns about that range; from one run
alone the run-to-run noise is not measured. Summaries without run medians (made elsewhere)
fall back to the overlap of their CIs.

Power (:func:`power`, :func:`needed`): the variance of a log run median of F frames is
modelled as ``between**2 + K * within**2 / F`` (:func:`noise`): ``within`` is the robust SD of
the log frame times around their run's median (1.4826 MAD), ``K = pi/2`` the variance of a
median over that of a mean for normal frames, and ``between`` whatever of the run medians'
(median-unbiased) variance the frames do not explain (frame-to-frame correlation lands there
too, so the frames needed are then overstated, never understated). The power of Welch's test
between two sides of that shape, one scaled by ``1 + change``, is a seeded Monte Carlo of the
test; on synthetic benches it matched the detected rate of planted 2% and 5% changes."""

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
            "ci_hi": hi, "run_medians": [float(np.median(g)) for g in groups],
            "frames": int(np.median([len(g) for g in groups])),
            "within_sd": _within_sd(groups)}


def _within_sd(groups: list[list[float]]) -> float | None:
    """Robust SD of the log samples around their run's median (1.4826 x their MAD), pooled
    over runs; None for one sample per run or samples that are not all positive."""
    if max(len(g) for g in groups) < 2:
        return None
    x = [np.asarray(g, np.float64) for g in groups]
    if min(float(g.min()) for g in x) <= 0:
        return None
    dev = np.concatenate([np.log(g) - np.log(np.median(g)) for g in x if g.size > 1])
    return float(1.4826 * np.median(np.abs(dev)))


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
    """Whether two medians differ beyond the noise: the 95% CI of their ratio
    (:func:`difference`, Welch's t-test of the log run medians) excludes 1, and both rest on
    enough samples and runs (:func:`no_mark`). Summaries without run medians: their 95% CIs
    do not overlap."""
    if not a or not b or no_mark(a, b):
        return False
    d = difference(a, b)
    if d is None:
        return a["ci_hi"] < b["ci_lo"] or b["ci_hi"] < a["ci_lo"]
    return d["lo"] > 1.0 or d["hi"] < 1.0


def difference(a: dict[str, Any] | None, b: dict[str, Any] | None, *, level: float = 0.95
               ) -> dict[str, float] | None:
    """``b`` against ``a`` by Welch's t-test of their log run medians: ``{ratio, lo, hi, t,
    df}``, the ratio of the geometric means of the run medians with its CI at ``level``;
    None without run medians, with fewer than 2 runs a side or with a median <= 0. A side
    whose run medians are all equal (identical runs, a coarse timer's ticks) has measured no
    variance between them: it takes the variance its frames imply (:func:`frames_floor`)."""
    if not a or not b or not a.get("run_medians") or not b.get("run_medians"):
        return None
    x, y = np.asarray(a["run_medians"], np.float64), np.asarray(b["run_medians"], np.float64)
    if x.size < 2 or y.size < 2 or min(x.min(), y.min()) <= 0:
        return None
    x, y = np.log(x), np.log(y)
    d = float(y.mean() - x.mean())
    va = (float(x.var(ddof=1)) or frames_floor(a)) / x.size
    vb = (float(y.var(ddof=1)) or frames_floor(b)) / y.size
    se = (va + vb) ** 0.5
    if se == 0:  # no noise at all (one sample per run, all equal): any difference is beyond
        return {"ratio": float(np.exp(d)), "lo": float(np.exp(d)), "hi": float(np.exp(d)),
                "t": float("inf") if d else 0.0, "df": float(x.size + y.size - 2)}
    df = (va + vb) ** 2 / (va**2 / (x.size - 1) + vb**2 / (y.size - 1))
    half = float(t_quantile((1 + level) / 2, df)) * se
    return {"ratio": float(np.exp(d)), "lo": float(np.exp(d - half)),
            "hi": float(np.exp(d + half)), "t": d / se, "df": float(df)}


def frames_floor(s: dict[str, Any], frames: int | None = None) -> float:
    """The variance of a log run median of ``frames`` frames (default: ``s``'s) that
    ``s``'s frames imply if they were independent: ``K * within**2 / frames`` (module docstring); 0 without
    ``within_sd`` (one sample per run)."""
    within = s.get("within_sd")
    return MEDIAN_VARIANCE * within**2 / int(frames or s.get("frames") or 1) if within else 0.0


def t_quantile(p: float, df: float | np.ndarray) -> float | np.ndarray:
    """Student's t quantile at ``p`` (0.5 <= p < 1) for ``df`` >= 1 degrees of freedom (an
    array: each; fractional df allowed), from ``P(|T| <= sqrt(df) tan(u)) =
    int_0^u cos^(df-1) / int_0^(pi/2) cos^(df-1)``, a bounded integrand, integrated on a fine
    grid (relative error under 1e-6)."""
    dfs = np.atleast_1d(np.asarray(df, np.float64))
    out = np.empty_like(dfs)
    for i, v in enumerate(dfs):
        if v < 1:
            raise ValueError(f"t_quantile needs df >= 1, got {v}")
        # cos^(v-1) ~ exp(-(v-1) u^2 / 2): past 12 of its SDs nothing is left to integrate
        u = np.linspace(0.0, min(np.pi / 2, 12 / np.sqrt(max(v - 1, 1e-9))), 4001)
        w = np.cos(u) ** (v - 1)
        c = np.concatenate([[0.0], np.cumsum((w[1:] + w[:-1]) / 2)])
        out[i] = np.sqrt(v) * np.tan(np.interp(2 * p - 1, c / c[-1], u))
    return float(out[0]) if np.ndim(df) == 0 else out


MEDIAN_VARIANCE = np.pi / 2  # var(median) / var(mean) of many normal samples
MAX_RUNS = 100  # :func:`needed` looks no further
MAX_FRAMES = 1_000_000


def noise(s: dict[str, Any] | None) -> dict[str, Any] | None:
    """The noise of one summary on the log scale (a relative SD), split as the power model
    needs it (module docstring): ``{runs, frames, run_sd, within, between, frames_var}``:
    ``run_sd`` the SD of the log run medians; their variance made median-unbiased
    (:func:`_median_unbiased`) is split into ``frames_var``, the part the frames imply
    (:func:`frames_floor`, at most all of it), and ``between**2``, the rest; ``within`` is
    None for one sample per run. None without run medians,
    with fewer than 2 runs, or with a median <= 0."""
    if not s or len(s.get("run_medians") or []) < 2 or min(s["run_medians"]) <= 0:
        return None
    run_sd = float(np.log(np.asarray(s["run_medians"], np.float64)).std(ddof=1))
    runs = len(s["run_medians"])
    total = run_sd**2 * _median_unbiased(runs)
    part = min(frames_floor(s), total)
    return {"runs": runs, "frames": int(s.get("frames") or 1), "run_sd": run_sd,
            "within": s.get("within_sd"), "between": (total - part) ** 0.5,
            "frames_var": part}


def power(s: dict[str, Any] | None, change: float = 0.02, *, runs: int | None = None,
          frames: int | None = None, level: float = 0.95) -> float | None:
    """The chance that :func:`significant` marks a change of the median by ``change`` (0.02:
    2%) between two sides with the noise of ``s`` (:func:`noise`), ``runs`` runs of
    ``frames`` frames each (default: those of ``s``): :func:`welch_power` at the variance
    :func:`run_variance`. None where :func:`noise` is."""
    n = noise(s)
    if n is None:
        return None
    return welch_power(run_variance(n, frames), int(runs or n["runs"]), change, level=level)


def _median_unbiased(runs: int) -> float:
    """The factor that makes a sample variance from ``runs`` runs median-unbiased: ``(runs -
    1) / median(chi2(runs - 1))`` (2.2 at 2 runs, 1.44 at 3, 1.19 at 5). The power falls as
    the variance grows, so the power from the scaled variance is about median-unbiased too:
    a bench states too much power about as often as too little (from the plain variance it
    is too much more often, most at 2-3 runs)."""
    if runs not in _MEDIAN_CHI2:
        draws = np.random.default_rng(SEED).chisquare(runs - 1, 200_000)
        _MEDIAN_CHI2[runs] = (runs - 1) / float(np.median(draws))
    return _MEDIAN_CHI2[runs]


_MEDIAN_CHI2: dict[int, float] = {}


def run_variance(n: dict[str, Any], frames: int | None = None) -> float:
    """The variance of a log run median of ``frames`` frames (default: as measured) under
    the model of :func:`noise`: ``between**2`` plus the frames' part scaled by
    ``measured frames / frames``."""
    return n["between"] ** 2 + n["frames_var"] * n["frames"] / int(frames or n["frames"])


def welch_power(var: float, runs: int, change: float, *, level: float = 0.95) -> float:
    """The chance that :func:`difference`'s test at ``level`` marks the difference between
    two sides of ``runs`` normal log run medians of variance ``var``, one shifted by
    ``log(1 + change)``: a seeded Monte Carlo of Welch's test (sample variances and degrees
    of freedom included) of :data:`DRAWS` draws, made once per ``runs`` in units of the
    noise (the test depends on ``runs`` and ``log(1 + change) / sqrt(2 var / runs)`` alone)."""
    if runs < 2:
        return 0.0
    if var <= 0:
        return 1.0 if change else 0.0
    z, bound = _welch_draws(runs, level)
    return float((np.abs(np.log1p(change) / (2 * var / runs) ** 0.5 + z) > bound).mean())


DRAWS = 4000
_DRAWS: dict[tuple[int, float], tuple[np.ndarray, np.ndarray]] = {}


def _welch_draws(runs: int, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch's test on two sides of ``runs`` standard normal values, in units of the SD of
    the difference of their means: that difference's noise ``z``, and the ``bound`` its
    shifted value must pass (the t quantile of the draw's degrees of freedom x its SE)."""
    key = (runs, level)
    if key not in _DRAWS:
        rng = np.random.default_rng(SEED)
        z = rng.standard_normal(DRAWS)
        va, vb = rng.chisquare(runs - 1, size=(2, DRAWS)) / (runs - 1)
        df = (va + vb) ** 2 / ((va**2 + vb**2) / (runs - 1))
        _DRAWS[key] = z, _t_crit(df, level) * np.sqrt((va + vb) / 2)
    return _DRAWS[key]


def needed(s: dict[str, Any] | None, change: float = 0.02, *, target: float = 0.8,
           level: float = 0.95) -> dict[str, Any] | None:
    """What it takes to detect ``change`` with :func:`power` >= ``target``, from the noise
    of ``s``: ``{power, runs, frames}``: the power now, the runs needed at ``s``'s frames per
    run, and the frames per run needed at ``s``'s runs (None where no number up to
    :data:`MAX_RUNS` / :data:`MAX_FRAMES` reaches it: the noise between runs alone is too
    large, or there is one sample per run). None where :func:`noise` is."""
    n = noise(s)
    if n is None:
        return None

    def enough(**kw: int) -> bool:
        return (power(s, change, level=level, **kw) or 0.0) >= target

    runs = next((r for r in range(2, MAX_RUNS + 1) if enough(runs=r)), None)
    frames = None
    if n["within"] and enough(frames=MAX_FRAMES):
        lo, hi = 1, 2  # power grows with frames: double, then bisect
        while not enough(frames=hi):
            lo, hi = hi, hi * 2
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if enough(frames=mid) else (mid, hi)
        frames = hi
    return {"power": power(s, change, level=level), "runs": runs, "frames": frames}


_CRIT: dict[float, tuple[np.ndarray, np.ndarray]] = {}


def _t_crit(df: np.ndarray, level: float) -> np.ndarray:
    """:func:`t_quantile` of many ``df`` at once, interpolated in log df on a table."""
    if level not in _CRIT:
        grid = np.geomspace(1.0, 1e4, 400)
        _CRIT[level] = np.log(grid), t_quantile((1 + level) / 2, grid)
    x, y = _CRIT[level]
    return np.interp(np.log(np.clip(df, 1.0, 1e4)), x, y)


def mark(a: dict[str, Any] | None, b: dict[str, Any] | None) -> str:
    """The significance mark of the difference between ``a`` and ``b``: ``*``
    (:func:`significant`), ``(n.s.)`` (within the noise) or ``(n=3<6: no mark)`` (too few
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
