"""The report's "How this was measured" section: how the runs ran (one process after another,
or Ray tasks at once), the timers, the statistics and how every CI is made."""

from __future__ import annotations

from typing import Any

from ..stats import MIN_RUNS, MIN_SAMPLES
from .document import Doc

# how every CI of the reports is made and when a difference gets a mark, said once
CI_METHOD = ("95% CI of the median: a percentile bootstrap (2000 resamples, seeded) that "
             "resamples runs, then frames in each run, so run-to-run noise widens it (wall ms: "
             "the runs' numbers resampled). A difference is marked `*` when Welch's t-test of "
             "the two sides' log run medians (each run's median frame; the run is the unit "
             "that repeats) puts the 95% CI of their ratio clear of 1, `(n.s.)` when it does "
             "not (within the noise); on synthetic A/A pairs it marks at most 5% "
             "(tests/bench/test_stats_calibration.py). "
             f"Below {MIN_SAMPLES} samples or {MIN_RUNS} runs there is no "
             "mark (e.g. `(n=3<6: no mark)`, `(1 run: no mark)`) and the CI carries that note: "
             f"under {MIN_SAMPLES} samples no 95% interval of a median exists without assuming a "
             "distribution (even the samples' full range covers the median with probability "
             "1 - 2·0.5^n, 94% at n=5) and the bootstrap returns about that range; one run does "
             "not measure the noise between runs.")


def _method(doc: Doc, records: list[dict[str, Any]], devices: list[str]) -> None:
    doc.h(2, "How this was measured")
    doc.bullets([
        _how_runs_ran(records, devices),
        "GPU ms are timestamp queries around each pass (wgpu timestamp queries; "
        "`vkCmdWriteTimestamp2` on vk); CPU record ms is the host time of the pass's "
        "`record()`; wall ms per frame is a run's wall time over its timed frames (record, "
        "submit, the waits for frame-in-flight slots, the last frame's wait for the rest) / "
        "frames.",
        "Statistics: GPU and CPU ms: median, p5 and p95 over single frames; wall ms: each "
        "run's total wall time / frames, median over runs. " + CI_METHOD,
        "Results: `results.jsonl` (one line per run, every frame's numbers); re-run the report "
        "with `rfw bench report DIR`, compare two result sets with "
        "`rfw bench compare OLD NEW`.",
        "Timings are never asserted by the tests; on lavapipe the 'GPU' is the CPU.",
    ])


def _how_runs_ran(records: list[dict[str, Any]], devices: list[str]) -> str:
    """The first bullet of "How this was measured": one process after another here, or Ray
    tasks running concurrently (``--executor ray``); ``devices``: those the rfw runs that
    worked measured (the "Per device" section exists for two or more)."""
    worker = ("load the config, build the scene, render warm-up frames, then the timed "
              "frames; nothing is shared between runs but the shader cache on disk")
    rays = [r for r in records if r.get("executor") == "ray"]
    if not rays:
        return ("Every run is its own process (`python -m rfw.bench.worker`), one after "
                f"another on this machine: {worker}.")
    cluster = next((r["ray_cluster"] for r in rays if r.get("ray_cluster")), {})
    gpus, cpus = cluster.get("gpus") or 0, cluster.get("cpus") or 0
    submitted = cluster.get("submitted") or len(rays)
    per_task = "one GPU" if gpus else "one CPU (the cluster has no GPU)"
    slots = int(gpus or cpus) or submitted
    hosts = len({(r.get("ray") or {}).get("host") for r in rays})
    return (f"Runs went through Ray (`--executor ray`), concurrently: all {submitted} runs "
            f"were submitted at once as Ray tasks asking for {per_task} each, so up to "
            f"{min(submitted, slots)} ran at the same time (cluster resources: "
            f"{gpus:g} GPU, {cpus:g} CPU; {hosts} host(s)). Each task ran its run in its own "
            f"process (`python -m rfw.bench.worker`): {worker}. Runs sharing a machine "
            f"could slow each other down{_devices_pointer(devices)}.")


def _devices_pointer(devices: list[str]) -> str:
    """Where a Ray report sends the reader to compare devices: the "Per device" section,
    which exists only when the runs measured two devices or more."""
    if len(devices) > 1:
        return (f": compare the {len(devices)} devices in the per-device table "
                "(\"Per device\")")
    if devices:
        return (f"; all runs measured one device ({devices[0]}), so there is no per-device "
                "table")
    return ""
