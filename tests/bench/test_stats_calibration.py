"""The significance mark calibrated on synthetic A/A pairs (issue 24, item 2).

Each side is a bench's shape, R runs x F frames: lognormal frames (3% SD), optionally a
random offset per run (another process), AR(1) correlated frames and occasional spikes. Both
sides of an A/A pair come from the same distribution, so every mark is a false positive; a
planted change scales one side. Everything goes through the functions the report and
``rfw bench compare`` use (:func:`summarize`, then :func:`mark` / :func:`significant`), seeded.
The negative controls are rules that must fail here: a frame-level CI that ignores runs, and
the old rule (non-overlap of the run-level bootstrap CIs) with 2 runs a side."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rfw.bench.stats import (
    bootstrap_ci,
    mark,
    needed,
    noise,
    power,
    significant,
    summarize,
    welch_power,
)

FAMILIES = {  # name -> (between-run SD, AR(1) coefficient, spike probability), log scale
    "lognormal": (0.0, 0.0, 0.0),
    "run offset": (0.03, 0.0, 0.0),
    "AR(1)": (0.0, 0.7, 0.0),
    "spikes": (0.0, 0.0, 0.05),
    "all": (0.02, 0.5, 0.03),
}
SHAPES = [(2, 10), (3, 10)]  # runs x frames a side: near the least that gets a mark, and
# the bench's default
WITHIN = 0.03


def side(rng: np.random.Generator, runs: int, frames: int, family: str,
         scale: float = 1.0) -> np.ndarray:
    """``runs`` x ``frames`` frame times (ms) around 10 ms x ``scale``."""
    between, phi, spike = FAMILIES[family]
    z = rng.standard_normal((runs, frames))
    e = np.empty_like(z)
    e[:, 0] = z[:, 0]
    for i in range(1, frames):  # stationary AR(1) with unit variance
        e[:, i] = phi * e[:, i - 1] + math.sqrt(1 - phi**2) * z[:, i]
    x = 10.0 * scale * np.exp(between * rng.standard_normal((runs, 1)) + WITHIN * e)
    hit = rng.random(x.shape) < spike
    return np.where(hit, x * rng.uniform(1.5, 3.0, x.shape), x)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial rate k/n (95% at z=1.96, 99% at 2.576)."""
    p = k / n
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return mid - half, mid + half


def pairs(family: str, runs: int, frames: int, count: int, *, seed: int,
          scale: float = 1.0) -> list[tuple[dict, dict, np.ndarray, np.ndarray]]:
    """``count`` pairs ``(summary A, summary B, frames A, frames B)``; B scaled by ``scale``."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        xa, xb = side(rng, runs, frames, family), side(rng, runs, frames, family, scale)
        out.append((summarize(xa.tolist()), summarize(xb.tolist()), xa, xb))
    return out


def true_run_variance(family: str, frames: int) -> float:
    """The variance of a log run median, from many simulated runs."""
    x = side(np.random.default_rng(99), 20000, frames, family)
    return float(np.log(np.median(x, axis=1)).var())


@pytest.fixture(scope="module")
def aa() -> dict[str, list[tuple[dict, dict, np.ndarray, np.ndarray]]]:
    """40 A/A pairs per family, 20 of each shape: 200 in all."""
    return {f: [p for k, (r, n) in enumerate(SHAPES) for p in pairs(f, r, n, 20, seed=10 * i + k)]
            for i, f in enumerate(FAMILIES)}


def test_aa_false_positive_rate_is_at_most_5_percent(aa):
    rates = {}
    for family, found in aa.items():
        marks = [mark(a, b) for a, b, _, _ in found]
        assert set(marks) <= {"*", "(n.s.)"}  # every pair has enough samples for a mark
        k = marks.count("*")
        rates[family] = (k, len(found))
        lo, _ = wilson(k, len(found))
        assert lo <= 0.05, f"{family}: {k}/{len(found)} A/A pairs marked"  # none shows > 5%
    k, n = sum(k for k, _ in rates.values()), sum(n for _, n in rates.values())
    lo, hi = wilson(k, n)
    print(f"A/A false positives: {k}/{n} = {k / n:.1%} (95% CI {lo:.1%}-{hi:.1%}); "
          + ", ".join(f"{f} {a}/{b}" for f, (a, b) in rates.items()))
    assert n >= 100 and k / n <= 0.05


def test_negative_controls_rules_that_ignore_runs_fail():
    # a frame-level CI (all frames pooled, runs ignored) on run offsets marks far more than 5%
    rng = np.random.default_rng(8)
    naive, count = 0, 100
    for _ in range(count):
        xa, xb = side(rng, 3, 10, "run offset"), side(rng, 3, 10, "run offset")
        (alo, ahi), (blo, bhi) = bootstrap_ci(xa.ravel()), bootstrap_ci(xb.ravel())
        naive += ahi < blo or bhi < alo
    lo, _ = wilson(naive, count)
    assert lo > 0.05, f"frame-level CI: {naive}/{count}"
    # the old rule (the run-level bootstrap CIs do not overlap) with 2 runs a side
    two = pairs("run offset", 2, 10, 100, seed=7)
    old = sum(a["ci_hi"] < b["ci_lo"] or b["ci_hi"] < a["ci_lo"] for a, b, _, _ in two)
    new = sum(significant(a, b) for a, b, _, _ in two)
    lo, _ = wilson(old, len(two))
    print(f"negative controls: frame-level CI {naive}/{count}, old rule at 2 runs "
          f"{old}/{len(two)} (this rule {new}/{len(two)})")
    assert lo > 0.05 and new / len(two) <= 0.05


@pytest.mark.parametrize("family, runs, frames", [("lognormal", 3, 10), ("run offset", 3, 10)])
def test_planted_change_detected_at_the_stated_power(family, runs, frames):
    var = true_run_variance(family, frames)
    for change in (0.02, 0.05):
        found = pairs(family, runs, frames, 100, seed=int(change * 1000) + runs,
                      scale=1 + change)
        hits = sum(significant(a, b) for a, b, _, _ in found)
        lo, hi = wilson(hits, len(found), z=2.576)  # 99%
        stated = float(np.median([power(a, change) for a, _, _, _ in found]))
        exact = welch_power(var, runs, change)  # the model at the true noise
        print(f"{family} {runs}x{frames} +{change:.0%}: detected {hits}/{len(found)} "
              f"(99% CI {lo:.2f}-{hi:.2f}), stated power {stated:.2f} (median over "
              f"benches), {exact:.2f} at the true noise")
        assert lo <= stated <= hi and lo <= exact <= hi
        if FAMILIES[family][0]:  # negative control: a power that ignores run offsets
            frames_only = float(np.median([welch_power(noise(a)["frames_var"], runs, change)
                                           for a, _, _, _ in found]))
            assert not lo <= frames_only <= hi, frames_only


def test_runs_needed_give_the_power():
    # from a long bench's noise (20 runs x 10 frames: the estimate is close to the truth), the
    # runs for 80% power at 2%: benches of that shape detect a 2% change about 80% of the time
    a, _, _, _ = pairs("lognormal", 20, 10, 1, seed=3)[0]
    need = needed(a, 0.02)
    runs = need["runs"]
    assert runs and power(a, 0.02, runs=runs) >= 0.8 > power(a, 0.02, runs=runs - 1)
    frames = need["frames"]  # at 20 runs: fewer frames than 10 do
    assert frames and frames < 10 and power(a, 0.02, frames=frames) >= 0.8
    assert power(a, 0.02, frames=frames - 1) < 0.8
    found = pairs("lognormal", runs, 10, 100, seed=5, scale=1.02)
    hits = sum(significant(a, b) for a, b, _, _ in found)
    lo, hi = wilson(hits, len(found), z=2.576)
    exact = welch_power(true_run_variance("lognormal", 10), runs, 0.02)
    print(f"runs needed at 10 frames: {runs}; detected {hits}/100 (99% CI {lo:.2f}-{hi:.2f})"
          f", the model at the true noise {exact:.2f}")
    assert lo <= 0.8 <= hi


def test_report_prints_the_power_table(tmp_path):
    from rfw.bench.report import write_report
    from rfw.bench.report.power import power_rows
    from rfw.bench.runner import load_results
    from rfw.bench.summary import summarize_results

    from .synthetic import results

    out = results(tmp_path / "b", {"d@wgpu": {"gbuffer": 10.0, "lighting": 2.0}}, noise=0.03)
    md = write_report(out)[0].read_text()
    section = md.split("## Power: what a 2% change takes")[1].split("\n## ")[0]
    v = summarize_results(load_results(out))[0]
    rows = power_rows(v)
    assert [r["what"] for r in rows] == ["frame", "gbuffer", "lighting"]
    for r in rows:  # the table says what needed() says of each pass's GPU ms
        s = v.frame["gpu_ms"] if r["what"] == "frame" else next(
            p["gpu_ms"] for p in v.passes if p["name"] == r["what"])
        assert needed(s, 0.02)["power"] == r["power"]
        line = next(x for x in section.splitlines() if x.startswith(f"| d@wgpu | {r['what']} |"))
        assert f"| 3 x 20 | {r['between']:.2%} | {r['within']:.2%} | {r['power']:.0%} |" in line
    # negative control: one run measures no noise between runs, so there is no table
    one = results(tmp_path / "one", {"d@wgpu": {"gbuffer": 10.0}}, repeats=1, noise=0.03)
    assert "## Power" not in write_report(one)[0].read_text()


def test_t_quantiles_and_the_ratio_ci():
    from rfw.bench.stats import difference, t_quantile

    # Student's t 97.5% points (tables): 1, 2, 4, 30 degrees of freedom; many: the normal
    for df, q in [(1, 12.7062), (2, 4.3027), (4, 2.7764), (30, 2.0423), (1e5, 1.9600)]:
        assert t_quantile(0.975, df) == pytest.approx(q, abs=2e-4)
    a = summarize([[10.0, 10.1], [10.2, 10.3], [9.9, 10.0]])
    b = summarize([[11.0, 11.1], [11.2, 11.3], [10.9, 11.0]])
    d = difference(a, b)
    ra = np.log([10.05, 10.25, 9.95])
    rb = np.log([11.05, 11.25, 10.95])
    assert d["ratio"] == pytest.approx(np.exp(rb.mean() - ra.mean()))
    va, vb = ra.var(ddof=1) / 3, rb.var(ddof=1) / 3
    df = (va + vb) ** 2 / ((va**2 + vb**2) / 2)  # Welch-Satterthwaite: near 4, equal noise
    assert d["lo"] < d["ratio"] < d["hi"] and d["df"] == pytest.approx(df) and 3.9 < df <= 4
    half = t_quantile(0.975, df) * np.sqrt(va + vb)
    assert np.log(d["hi"] / d["ratio"]) == pytest.approx(half)
    assert significant(a, b) and not significant(a, a)
    # identical runs measure no variance between them: the frames' spread stands in for it
    same = [[9.0, 10.0, 11.0]] * 3
    assert not significant(summarize(same), summarize([[9.1, 10.1, 11.1]] * 3))
    assert significant(summarize(same), summarize([[13.0, 14.0, 15.0]] * 3))  # +40%
