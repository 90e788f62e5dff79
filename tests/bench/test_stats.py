"""Statistics of the harness: the bootstrap CI covers, is seeded, widens with run shifts."""

from __future__ import annotations

import numpy as np
import pytest

from rfw.bench.stats import bootstrap_ci, bootstrap_ci_runs, summarize


def test_bootstrap_ci_covers_the_true_median():
    rng = np.random.default_rng(1)
    covered = 0
    trials = 100
    for _ in range(trials):
        x = rng.normal(10.0, 1.0, size=60)  # true median 10
        lo, hi = bootstrap_ci(x, resamples=500, seed=int(rng.integers(1 << 30)))
        covered += lo <= 10.0 <= hi
    assert covered >= 85  # nominal 95%; the percentile bootstrap of a median runs a bit low


def test_bootstrap_is_seeded_and_deterministic():
    x = np.random.default_rng(2).exponential(size=40)
    assert bootstrap_ci(x) == bootstrap_ci(x)
    assert bootstrap_ci(x, seed=1) != bootstrap_ci(x, seed=2)
    assert summarize(list(x)) == summarize(list(x))


def test_summary_fields():
    s = summarize([1.0, 2.0, 3.0, 4.0, 100.0])
    assert s["median"] == 3.0 and s["n"] == 5 and s["runs"] == 1
    assert s["p5"] < s["median"] < s["p95"]
    assert s["ci_lo"] <= s["median"] <= s["ci_hi"]
    assert summarize([]) is None and summarize(None) is None
    one = summarize([2.5])
    assert one["ci_lo"] == one["ci_hi"] == 2.5
    with pytest.raises(ValueError):
        bootstrap_ci([])


def test_run_level_bootstrap_widens_for_shifted_runs():
    rng = np.random.default_rng(3)
    runs = [list(rng.normal(10.0 + shift, 0.05, size=30)) for shift in (0.0, 0.5, 1.0)]
    flat_lo, flat_hi = bootstrap_ci(np.concatenate(runs))
    lo, hi = bootstrap_ci_runs(runs)
    assert hi - lo > flat_hi - flat_lo  # the process-to-process shift is part of the noise
    s = summarize(runs)
    assert s["runs"] == 3 and s["n"] == 90 and (s["ci_lo"], s["ci_hi"]) == (lo, hi)
