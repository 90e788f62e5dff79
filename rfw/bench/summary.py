"""Results of many runs folded per variant: statistics over all frames of all repeats.

GPU and CPU ms are per frame (every frame of every run, the CI resampling runs, then frames).
Wall ms is per run: the run's total wall time of its timed frames / frames, one number per
run, with median and CI across runs. Single frames' wall times are not comparable samples:
with frames in flight a frame's wall clock may absorb the wait for an earlier frame (on
lavapipe e.g. wall [0.9, 22.2, 46.5] ms against GPU [21.3, 23.3, 20.7])."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..units import MiB
from .stats import summarize, summarize_runs

RAYCAST_PEERS = ("open3d", "mitsuba", "embree", "rfw_raycast")  # benchmarks/peers


@dataclass
class VariantSummary:
    label: str
    kind: str  # "rfw" | "peer"
    records: list[dict[str, Any]] = field(default_factory=list)  # runs that worked
    errors: list[str] = field(default_factory=list)  # why the others did not
    failed: list[dict[str, Any]] = field(default_factory=list)  # their records
    frame: dict[str, Any] = field(default_factory=dict)  # metric -> summary
    passes: list[dict[str, Any]] = field(default_factory=list)  # {name, gpu_ms, cpu_ms}
    samples: dict[str, list[list[float]]] = field(default_factory=dict)  # metric -> per run
    base: str = ""  # one device's row of a variant measured on several: the variant's label
    device: str = ""  # and that device

    @property
    def first(self) -> dict[str, Any]:
        return self.records[0] if self.records else {}

    @property
    def ok(self) -> bool:
        return bool(self.records)

    @property
    def image(self) -> str | None:
        return next((r["image"] for r in self.records if r.get("image")), None)

    def get(self, key: str, default: Any = None) -> Any:
        return self.first.get(key, default)


def summarize_results(records: list[dict[str, Any]]) -> list[VariantSummary]:
    """One :class:`VariantSummary` per variant (and peer), in first-run order."""
    by: dict[str, VariantSummary] = {}
    for rec in records:
        v = by.setdefault(rec["variant"], VariantSummary(rec["variant"], rec.get("kind", "rfw")))
        if rec.get("error"):
            v.errors.append(rec["error"])
            v.failed.append(rec)
        elif rec.get("kind") == "peer" and not rec.get("available", False):
            v.errors.append(f"unavailable: {rec.get('reason', 'unknown')}")
            v.failed.append(rec)
        else:
            v.records.append(rec)
    for v in by.values():
        if v.kind == "peer":
            _fold_peer(v)
        else:
            _fold_rfw(v)
    return list(by.values())


def _fold_rfw(v: VariantSummary) -> None:
    for metric in ("gpu_ms", "cpu_ms"):
        runs = [r["frame"][metric] for r in v.records if r.get("frame", {}).get(metric)]
        v.samples[metric] = runs
        v.frame[metric] = summarize(runs) if runs else None
    # wall: one number per run (its frames' total / frames), see the module docstring
    walls = [wall_per_frame(r) for r in v.records]
    v.samples["wall_ms"] = [[w] for w in walls if w is not None]
    v.frame["wall_ms"] = summarize_runs(walls)
    names: list[str] = []
    for r in v.records:  # union of pass names, first-seen order
        names.extend(p["name"] for p in r.get("passes", []) if p["name"] not in names)
    for name in names:
        entry: dict[str, Any] = {"name": name}
        for metric in ("gpu_ms", "cpu_ms"):
            runs = [p[metric] for r in v.records for p in r.get("passes", [])
                    if p["name"] == name and p.get(metric)]
            entry[metric] = summarize(runs) if runs else None
            v.samples[f"{name}.{metric}"] = runs
        v.passes.append(entry)


def wall_per_frame(record: dict[str, Any]) -> float | None:
    """A run's wall ms per frame: the total wall time of its timed frames / their number."""
    wall = (record.get("frame") or {}).get("wall_ms")
    return sum(wall) / len(wall) if wall else None


def _fold_peer(v: VariantSummary) -> None:
    for metric in ("frame_ms", "gpu_ms"):
        runs = [r[metric] for r in v.records if r.get(metric)]
        v.samples[metric] = runs
        v.frame[metric] = summarize(runs) if runs else None
    rays = v.get("rays")
    med = (v.frame.get("frame_ms") or {}).get("median")
    if rays and med:
        v.frame["mrays_per_s"] = rays / (med * 1e-3) / 1e6


def mib(n: Any) -> str:
    return "-" if n is None else f"{n / MiB:.2f}"
