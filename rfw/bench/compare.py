"""``rfw bench compare OLD NEW``: per-pass changes beyond the noise.

A change is flagged when the 95% CIs of the two medians do not overlap *and* the relative
change of the median exceeds the threshold; slower is a regression, faster an improvement."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .runner import load_results
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

    def verdict(self, threshold: float) -> str:
        if self.overlap or abs(self.relative) <= threshold:
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
    or measured on different devices."""
    olds = {v.label: v for v in summarize_results(old) if v.ok}
    news = {v.label: v for v in summarize_results(new) if v.ok}
    notes = []
    out = []
    for label in olds.keys() | news.keys():
        if label not in olds or label not in news:
            notes.append(f"{label}: only in {'OLD' if label in olds else 'NEW'}")
    for label in [k for k in olds if k in news]:
        a, b = olds[label], news[label]
        if (a.get("device"), a.get("driver")) != (b.get("device"), b.get("driver")):
            notes.append(f"{label}: devices differ ({a.get('device')} / {a.get('driver')} vs "
                         f"{b.get('device')} / {b.get('driver')})")
        ma, mb = _metrics(a), _metrics(b)
        for key in [k for k in ma if k in mb]:
            out.append(Change(label, key[0], key[1], ma[key], mb[key]))
    return out, notes


def compare(old: Path, new: Path, *, threshold: float = 0.05, fail_on_regression: bool = False,
            show_all: bool = False) -> int:
    """Print the flagged changes; returns the exit code (1 on a regression when asked)."""
    found, notes = changes(load_results(old), load_results(new))
    flagged = [(c, c.verdict(threshold)) for c in found]
    rows = [(c, v) for c, v in flagged if show_all or v != "same"]
    print(f"rfw bench compare: {old} -> {new} (threshold {threshold:.0%}, CIs must not "
          f"overlap)")
    for n in notes:
        print(f"  note: {n}")
    if rows:
        w = max(len(f"{c.variant} {c.what}.{c.metric}") for c, _ in rows)
        print(f"  {'variant pass.metric':<{w}} {'old ms':>10} {'new ms':>10} {'change':>8}  "
              f"verdict")
        for c, v in rows:
            name = f"{c.variant} {c.what}.{c.metric}"
            print(f"  {name:<{w}} {c.old['median']:>10.3f} {c.new['median']:>10.3f} "
                  f"{c.relative:>+8.1%}  {v}  [old {c.old['ci_lo']:.3f}-{c.old['ci_hi']:.3f},"
                  f" new {c.new['ci_lo']:.3f}-{c.new['ci_hi']:.3f}]")
    regressions = sum(1 for _, v in flagged if v == "regression")
    improvements = sum(1 for _, v in flagged if v == "improvement")
    print(f"{regressions} regression(s), {improvements} improvement(s), "
          f"{len(flagged) - regressions - improvements} unchanged of {len(flagged)} compared")
    return 1 if fail_on_regression and regressions else 0
