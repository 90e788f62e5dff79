"""One benchmark run in its own process: render a config, write every frame's timings.

    python -m rfw.bench.worker --config CONFIG [--set K=V]... [--scene S] [--size WxH]
        [--frames N] [--warmup N] [--backend NAME] --out DIR

Writes ``DIR/record.json`` (per pass and per frame: GPU ms from timestamps, CPU record ms;
whole-frame wall ms; memory, culling and ray counters where the run has them; along a
camera path, each frame's camera and, where there are culling counters, each frame's; along
a camera path or with a jittered camera the flicker index, :mod:`rfw.bench.temporal`; the
hashes of its config, graph, scene and shaders, :mod:`rfw.bench.inputs`) and
``DIR/image.png`` (the config's first output). A failure writes ``{"error": ...}`` and
exits 1, so the runner can report it instead of dropping the variant.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from ..config import parse_size
from ..errors import RfwError
from ..fileio import atomic_write
from .inputs import run_inputs, spirv_names, watching_shaders, watching_spirv
from .runner import gpu_clocks
from .temporal import along_run

# timings.json keys copied into the record as they are, where a run has them
EXTRA_KEYS = ("memory", "culling", "rays", "bridges", "bridge_ms_total", "default_light",
              "frames_in_flight", "camera_path")


ID_KEYS = ("uuid", "index", "uuid_via", "uuid_note")


def device_ids(timings: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per backend of the run, what its device said of itself: ``uuid`` (32 hex digits, or
    None where the backend cannot tell, with ``uuid_note`` saying why), ``index`` (its
    place in the driver's order, where a choice picked it) and ``uuid_via`` (the UUID a
    backend without UUIDs picked it by)."""
    sides = timings.get("backends") or {timings.get("backend"): timings}
    return {str(name): {k: d.get(k) for k in ID_KEYS if k in d} for name, d in sides.items()}


class FrameClock:
    """Wall time of every frame: wraps ``frame()`` of the executors while active."""

    def __init__(self) -> None:
        self.ends: list[float] = []
        self._patched: list[tuple[type, Any]] = []

    def patch(self, cls: type) -> None:
        original = cls.frame
        clock = self

        def frame(self: Any, drain: bool = False) -> None:
            t = time.perf_counter()
            original(self, drain)
            clock.ends.append((t, time.perf_counter()))

        cls.frame = frame  # type: ignore[method-assign]
        self._patched.append((cls, original))

    def restore(self) -> None:
        for cls, original in reversed(self._patched):
            cls.frame = original  # type: ignore[method-assign]
        self._patched.clear()

    def last(self, n: int) -> list[float]:
        return [(b - a) * 1e3 for a, b in self.ends[-n:]] if n else []


def _samples(frame: Any) -> dict[str, dict[str, list[float]]]:
    """Per-pass lists of per-frame ``gpu_ms`` and ``cpu_ms`` of a run's frame (every side's
    executor, and the bridges, which have CPU time only)."""
    out: dict[str, dict[str, list[float]]] = {}
    for ex in frame.executors.values():
        for name, t in ex.timings.items():
            if t.gpu_ms or t.cpu_ms:
                out[name] = {"gpu_ms": list(t.gpu_ms), "cpu_ms": list(t.cpu_ms)}
    for name, t in frame.bridge_timings.items():
        out[name] = {"gpu_ms": [], "cpu_ms": list(t.cpu_ms)}
    return out


def run(config: str, sets: list[str], *, scene: str | None, size: tuple[int, int] | None,
        backend: str, options: Any, truth: str | None = None
        ) -> tuple[dict[str, Any], Any, Any]:
    """Render once as ``options`` (:class:`rfw.options.RunOptions`, ``frames`` and
    ``warmup`` given) say; returns the record, the first output as 8-bit RGBA and, with
    ``truth`` (a component of ``--reference pathtrace``), the image it judges
    (:func:`truth_image`; None where the run has none)."""
    from ..backends.base import FrameExecutor
    from ..config import apply_overrides, load_config
    from ..frame import Frame
    from ..render import render, to_png_array

    cfg = load_config(config)
    sets = list(sets)
    if scene:
        sets.append(f"scene={scene}")
    if size:
        sets.append(f"size={size[0]}x{size[1]}")
    cfg = apply_overrides(cfg, sets)
    frames, warmup = options.frames, options.warmup
    clock = FrameClock()
    clock.patch(FrameExecutor)  # one backend: the executor's own frames
    clock.patch(Frame)  # mixed: the frame that walks every side (their own frame() idle)
    try:
        with watching_shaders() as shader_sources, watching_spirv() as spirv:
            t0 = time.perf_counter()
            result = render(cfg, backend=backend, options=options)
            total_s = time.perf_counter() - t0
    finally:
        clock.restore()
    clocks = gpu_clocks()  # right after the frames: the clocks they ran at, or close
    timings = result.timings
    samples = _samples(result.frame)
    order = [p["name"] for p in timings["passes"]]
    passes = []
    for name in order:
        s = samples.get(name, {"gpu_ms": [], "cpu_ms": []})
        passes.append({"name": name, "gpu_ms": s["gpu_ms"][-frames:],
                       "cpu_ms": s["cpu_ms"][-frames:]})
    # whole frame per frame index: the sums over passes of that frame
    gpu_frame = [sum(v) for v in zip(*(p["gpu_ms"] for p in passes if p["gpu_ms"]),
                                     strict=False)] if any(p["gpu_ms"] for p in passes) else []
    cpu_frame = [sum(v) for v in zip(*(p["cpu_ms"] for p in passes if p["cpu_ms"]),
                                     strict=False)]
    plan = result.frame.plan
    record: dict[str, Any] = {
        "device": timings.get("device"), "driver": timings.get("driver"),
        "api": timings.get("api"), "backend": timings.get("backend", backend),
        "config": timings.get("config"), "config_path": str(config),
        "variants": timings.get("variants", {}), "settings": list(sets),
        "scene": timings.get("scene"), "triangles": timings.get("triangles"),
        "size": timings.get("size"), "frames": frames, "warmup": warmup,
        "timestamps": bool(timings.get("timestamps")) and bool(gpu_frame),
        "passes": passes,
        "frame": {"gpu_ms": gpu_frame, "cpu_ms": cpu_frame,
                  "wall_ms": _with_camera_writes(clock.last(frames), timings)},
        "process_s": total_s, "gpu_clocks": clocks,
    }
    record.update(run_inputs(config, cfg, shader_sources))  # what compare says changed
    record["spirv"] = spirv_names(spirv)  # every SPIR-V module the run used (a bundle's)
    for key in EXTRA_KEYS:
        if key in timings:
            record[key] = timings[key]
    record["device_ids"] = device_ids(timings)  # which device of the machine each side used
    check_times(record)
    if "memory" not in record and hasattr(plan, "transient_bytes"):
        # wgpu allocates per texture: the plan's numbers are what there is
        record["memory"] = {"plan_transient_bytes": plan.transient_bytes,
                            "unaliased_bytes": plan.unaliased_bytes, "alias": None,
                            "source": "plan"}
    if "camera_path" in timings and timings.get("culling"):
        record["culling_frames"] = culling_along_path(cfg, backend=backend, options=options)
    # along a camera path or with a jittered camera: how much the image flickers
    temporal = along_run(cfg, backend=backend, options=options)
    if temporal is not None:
        record["temporal"] = temporal
    formats = {r.name: r.format for r in plan.resources}
    first = next(iter(result.images))
    record["output"] = first
    judged = None
    if truth:
        judged = truth_image(cfg, truth, backend=backend, options=options)
        record["hdr"] = {"component": truth, "file": HDR_FILE} if judged[2] is None else \
            {"component": truth, "missing": judged[2]}
        if judged[1] is not None:
            record["hdr"]["display"] = DISPLAY_FILE
    return record, to_png_array(result.images[first], formats[first]), judged


HDR_FILE, DISPLAY_FILE = "hdr.exr", "display.png"


def tonemap_input(cfg: Any) -> str | None:
    """The resource the enabled tonemap pass reads as its ``hdr`` input: the linear image
    before tone mapping (None without a tonemap pass)."""
    for p in cfg.passes:
        if p.enabled and p.use == "tonemap":
            return p.inputs.get("hdr")
    return None


def ao_input(cfg: Any) -> tuple[str | None, bool]:
    """``(resource, lit)``: what the enabled lighting pass reads as its ``ao`` input, None
    where its producer is disabled (the input is dropped: no occlusion); ``lit`` False
    without a lighting pass that has an ``ao`` input."""
    enabled = {p.name for p in cfg.passes if p.enabled}
    for p in cfg.passes:
        if p.enabled and "ao" in p.inputs:
            res = p.inputs["ao"]
            return (res if res.partition(".")[0] in enabled else None), True
    return None, False


def truth_image(cfg: Any, component: str, *, backend: str, options: Any
                ) -> tuple[Any, Any, str | None]:
    """The run's image the truth's ``component`` (:mod:`rfw.bench.truth`) judges, from an
    untimed replay of the same frames (histories and a camera path end where the timed
    run's did; the timed run reads nothing it would not read in any bench): ``full`` and
    ``direct*`` the tonemap pass's linear input (``direct*``: with the lighting pass's
    ambient term off), ``ao*`` the lighting pass's ambient occlusion at full size (ones
    where nothing occludes). ``(image, displayed, None)`` (``displayed``: the replay's
    first output as 8-bit RGBA, for ``direct*``, whose displayed image is not the run's) or
    ``(None, None, why not)``."""
    from dataclasses import replace

    import numpy as np

    from ..config import apply_overrides
    from ..errors import RfwError
    from ..render import render

    kind = component.partition("=")[0]
    if kind == "ao":
        name, lit = ao_input(cfg)
        if not lit:
            return None, None, "no lighting pass with an ao input"
        if name is None:
            return np.ones((cfg.size[1], cfg.size[0], 4), np.float32), None, None
    else:
        name = tonemap_input(cfg)
        if name is None:
            return None, None, "no tonemap pass"
        if kind.startswith("direct"):
            from ..registry import get_pass

            # the passes that light with the sky's ambient term (deferred_lighting, forward)
            lighting = [p.name for p in cfg.passes if p.enabled and p.use != "flat"
                        and "ambient" in getattr(get_pass(p.use).Params, "__annotations__", {})]
            try:
                cfg = apply_overrides(cfg, [f"{n}.ambient=0" for n in lighting])
            except RfwError as e:
                return None, None, f"the ambient term cannot be turned off ({e})"
    outputs = cfg.outputs if name in cfg.outputs else [*cfg.outputs, name]
    result = render(replace(cfg, outputs=outputs), backend=backend, options=options)
    image = np.asarray(result.images[name], np.float32)
    if image.shape[:2] != (cfg.size[1], cfg.size[0]):  # a half-size ao: as lighting reads it
        image = _resize(image, cfg.size)
    displayed = None
    if kind.startswith("direct"):
        from ..render import to_png_array

        first = cfg.outputs[0]
        fmt = {r.name: r.format for r in result.frame.plan.resources}[first]
        displayed = to_png_array(result.images[first], fmt)
    return image, displayed, None


def _resize(image: Any, size: tuple[int, int]) -> Any:
    """Bilinear, channel by channel (as a sampler reads a smaller texture)."""
    import numpy as np
    from PIL import Image

    return np.stack([np.asarray(Image.fromarray(np.ascontiguousarray(image[..., c]), "F")
                                .resize(size, Image.Resampling.BILINEAR))
                     for c in range(image.shape[2])], axis=2)


def check_times(record: dict[str, Any]) -> None:
    """Refuse a time that is not a finite number of ms at least 0 (a timestamp query read
    wrong): as a failed run, so results.jsonl never holds what compare must refuse."""
    from .records import check_record

    try:
        check_record({"variant": "run", **record})
    except RfwError as e:
        raise RuntimeError(f"timings: {e}") from None


def _with_camera_writes(wall_ms: list[float], timings: dict[str, Any]) -> list[float]:
    """Each frame's wall ms plus, along a camera path, the host time its camera write took
    before the frame (on vk it waits for the frames in flight: that is the frame's cost)."""
    cams = (timings.get("camera_path") or {}).get("frames")
    if not cams or len(cams) != len(wall_ms):
        return wall_ms
    return [w + c["write_ms"] for w, c in zip(wall_ms, cams, strict=True)]


def culling_along_path(cfg: Any, *, backend: str, options: Any) -> list[Any]:
    """The culling counters of each frame of ``cfg``'s camera path, from an untimed replay
    of the path (reading them back waits for each frame, which the timed run must not)."""
    from ..backend import get_backend
    from ..render import render

    be = get_backend(backend)
    counters: list[Any] = []

    def read(k: int, frame: Any) -> None:
        frame.drain()
        counters.append(be.collect(frame.executors[backend]).get("culling"))

    render(cfg, backend=backend, each_frame=read, options=options.replace(warmup=1))
    return counters


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m rfw.bench.worker")
    ap.add_argument("--config", required=True)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--scene")
    ap.add_argument("--size", type=parse_size)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--backend", default="wgpu", help="an installed backend (rfw.backends)")
    ap.add_argument("--truth", help="also write the image this component of the truth "
                    "judges as hdr.exr (full, ao[=R], direct, direct_centre)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        from ..options import RunOptions

        # this process is its own edge: its options from its arguments and environment
        options = RunOptions.from_env(frames=args.frames, warmup=max(1, args.warmup))
        record, rgba, judged = run(args.config, args.set, scene=args.scene,
                                   size=args.size, backend=args.backend, options=options,
                                   truth=args.truth)
    except Exception as e:
        message = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        _write_json(out / "record.json", {"error": f"{type(e).__name__}: {message}",
                                          "traceback": traceback.format_exc(limit=8)})
        print(f"rfw bench worker: {type(e).__name__}: {message}", file=sys.stderr)
        return 1
    from PIL import Image

    atomic_write(out / "image.png", lambda f: Image.fromarray(rgba, "RGBA").save(f, "PNG"))
    if judged is not None and judged[0] is not None:
        from ..fileio import write_exr

        write_exr(out / HDR_FILE, judged[0])
        if judged[1] is not None:
            atomic_write(out / DISPLAY_FILE,
                         lambda f: Image.fromarray(judged[1], "RGBA").save(f, "PNG"))
    _write_json(out / "record.json", record)  # last: a record means the run is complete
    return 0


def _write_json(path: Path, record: dict[str, Any]) -> None:
    data = json.dumps(record).encode()
    atomic_write(path, lambda f: f.write(data))


if __name__ == "__main__":
    sys.exit(main())
