"""Render a config headless: images for each graph output and per-pass timings."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from .backend import Devices, get_backend
from .camera_path import path_for, run_path
from .config import MAX_FRAMES, Config, build, for_scene, pass_class, resolve_auto
from .errors import RfwError, check_number
from .fileio import to_png_array as to_png_array  # moved to fileio; imported from here
from .fileio import write_run
from .frame import (
    Frame,
    Result,
    camera_for,
    frame_record,
    load_scene_for,
    pass_timings,
    pinned_elsewhere,
    prepare,
    start,
)
from .options import RunOptions, check_options
from .timeline import timeline_for

# timings.json's fields a backend adds, in this order after the ones every run has
EXTRAS = ("memory", "culling", "techniques", "accel", "validation")


def render(cfg: Config, *, scene: Any = None, frames: int | None = None,
           warmup: int | None = None, device: Any = None, devices: Iterable[Any] = (),
           backend: str = "wgpu", validation: bool | None = None, alias: bool | None = None,
           frames_in_flight: int | None = None,
           each_frame: Callable[[int, Frame], None] | None = None,
           options: RunOptions | None = None) -> Result:
    """Build, compile and run ``cfg`` on ``backend`` (a name in the ``rfw.backends``
    entry-point group: ``wgpu``, ``vk`` or an installed one); returns images and timings
    (GPU ms from timestamps): the one frame driver of every backend.

    ``options`` (:class:`rfw.options.RunOptions`) say how the frames run; without them they
    are read from the environment here (``RunOptions.from_env``: render is an edge, as the
    CLI is). ``frames``, ``warmup``, ``validation``, ``alias`` and ``frames_in_flight``,
    when given, replace those of the options. Below this nothing reads the environment.

    ``device`` (and ``devices``) may be any backend's: each serves the backend that owns it,
    and a backend the run needs without one gets a device made here, with the validation
    layer when ``validation``, and destroyed here (``timings["validation"]`` then counts
    its messages, leak reports included). ``alias=False`` gives every transient its own
    allocation where the backend places memory itself (vk). A backend with
    ``auto_variants`` (vk) resolves auto variants for its device first
    (``timings["techniques"]`` reports what they chose).

    A config that pins passes to a backend other than ``backend`` runs on both
    (:mod:`rfw.mixed` plans it): ``backend`` is then the one of unpinned passes, bridges copy
    resources across through host memory and are timed as passes of their own.

    ``frames_in_flight`` frames run on the GPU while the next ones record (default: the
    config's ``frames_in_flight``, else ``RFW_FRAMES_IN_FLIGHT``, else 2; 1 waits for every
    frame: :mod:`rfw.frame`, ``RunOptions.in_flight``). Images
    and timing samples are the same either way: the frames are drained before anything is
    read, and the last timed frame's drain is part of its wall time.

    A camera path (``camera.path``, :mod:`rfw.camera_path`) gives each timed frame its
    camera (``timings["camera_path"]`` lists them); ``each_frame(k, frame)`` runs after timed
    frame ``k`` (e.g. to read its images). A scene with node animations plays them on the
    config's timeline (``animation``, :mod:`rfw.timeline`: timed frame ``k`` at
    ``start + k / fps`` seconds; ``timings["animation"]`` lists the times)."""
    run = get_backend(backend, file=cfg.source)
    check_outputs(cfg)
    if frames is not None:
        check_number(frames, "frames", kind=int, lo=1, hi=MAX_FRAMES, file=cfg.source)
    # a bad value fails before any device work
    given = {"frames": frames, "warmup": warmup, "validation": validation, "alias": alias,
             "frames_in_flight": frames_in_flight}
    options = RunOptions.from_env(**given) if options is None else \
        check_options(options).replace(**given)
    if options.frames is not None:
        check_number(options.frames, "frames", kind=int, lo=1, hi=MAX_FRAMES, file=cfg.source)
    in_flight = options.in_flight(cfg.frames_in_flight)
    options = options.replace(frames_in_flight=in_flight)  # what the executors keep
    devs = Devices((device, *devices), options=options)
    frame = None
    try:
        techniques: dict[str, str] = {}
        if run.auto_variants:  # the run's device decides what auto variants mean
            cfg, techniques = resolve_auto(cfg, run.caps(devs.get(run)))
        mix = pinned_elsewhere(cfg, backend)
        built = build(cfg)  # the config's errors before the scene's
        owned = scene is None  # loaded here, so nothing else holds its textures
        scene = load_scene_for(cfg, scene)
        if owned and not mix:  # uploaded once: its pixels go as they are uploaded
            scene.keep_pixels = False
        # passes with nothing to do on this scene (points_lines without strokes) left out
        if for_scene(cfg, scene) is not cfg:
            built = build(cfg, scene)
        frame_plan, sides = prepare(built, backend, devs, options=options, mix=mix)
        camera = camera_for(cfg, scene)
        path = path_for(cfg, camera)
        timeline = timeline_for(cfg, scene)  # None: a still scene
        if timeline is not None:
            scene = timeline.scene(scene)
        frame = start(frame_plan, sides, scene=scene, camera=camera, size=cfg.size,
                      options=options)
        n = options.frames or cfg.frames
        if path is None and each_frame is None and timeline is None:
            frame.run(options.warmup)
            frame.clear_timings()
            frame.run(n)
        else:  # a camera or a time per frame: rfw.camera_path drives the frames
            cameras = run_path(frame, path, warmup=options.warmup, frames=n,
                               each_frame=each_frame, timeline=timeline)
        frame.drain()  # run() has; said again for what reads results below
        images = {name: frame.read(name) for name in frame.plan.outputs}
        extras = {k: v for s in sides.values()  # e.g. what the frame allocated
                  for k, v in s.backend.collect(frame.executors[s.backend.name]).items()}
    finally:
        if frame is not None:
            frame.destroy()
        devs.close()  # leak reports arrive here, so count messages after it
    for s in sides.values():
        extras.update(s.backend.report(frame.executors[s.backend.name], s.device,
                                       validation=options.validation))
    extras["techniques"] = techniques or None
    timings = _mixed_record(frame, sides) if mix else _record(frame, sides[backend])
    timings.update(frame_record(cfg, n, scene, frame.default_light, timings.pop("passes"),
                                timestamps=all(s.backend.timestamps(s.device)
                                               for s in sides.values())))
    if mix:
        timings.update(_bridges(frame, timings["passes"]))
    timings["frames_in_flight"] = in_flight
    if path is not None:
        timings["camera_path"] = {"kind": path.kind, "frames": cameras}
    if timeline is not None:
        timings["animation"] = timeline.describe(n)
    known = sorted(extras, key=lambda k: EXTRAS.index(k) if k in EXTRAS else len(EXTRAS))
    timings.update({k: extras[k] for k in known if extras[k] is not None})
    return Result(cfg, images, timings, frame)


def check_outputs(cfg: Config) -> None:
    """A run needs something to render: without outputs the graph culls every pass."""
    if cfg.outputs:
        return
    last = [e for e in cfg.passes if e.enabled][-1:]
    slots = list(pass_class(cfg, last[0]).outputs) if last else []
    hint = f' (e.g. outputs = ["{last[0].name}.{slots[0]}"])' if slots else ""
    raise RfwError("names no outputs, so every pass would be culled and nothing rendered: "
                   "list the resources to write as images" + hint, file=cfg.source,
                   element="outputs")


def _record(frame: Frame, side: Any) -> dict[str, Any]:
    # one backend: its device's fields, then its passes
    ex = frame.executors[side.backend.name]
    return {**side.backend.describe(side.device), "passes": pass_timings(ex.plan.order,
                                                                        ex.timings)}


def _mixed_record(frame: Frame, sides: dict[str, Any]) -> dict[str, Any]:
    # each backend's device fields joined, and every pass with the backend it ran on
    described = {name: s.backend.describe(s.device) for name, s in sides.items()}
    return {**{k: " + ".join(dict.fromkeys(d[k] for d in described.values()))
               for k in ("device", "driver", "api")},
            "backend": "+".join(sides), "backends": described,
            "passes": frame.pass_timings()}


def _bridges(frame: Frame, passes: list[dict[str, Any]]) -> dict[str, Any]:
    # host copies are wall time, kept out of gpu_ms_total
    bridges = [p for p in passes if p["name"] in frame.frame_plan.bridges]
    return {"bridge_ms_total": sum(p["cpu_ms"] or 0.0 for p in bridges),
            "bridges": [p["name"] for p in bridges]}


def backend_for(cfg: Config) -> str:
    """The backend a run takes when none is asked for: the one every enabled pass is pinned
    to (in the config or by its class), else wgpu (pinned passes then mix in)."""
    pins = {e.backend or pass_class(cfg, e).backend for e in cfg.passes if e.enabled}
    return pins.pop() if len(pins) == 1 and None not in pins else "wgpu"


def write_outputs(result: Result, out_dir: Path, plan_formats: dict[str, str], *,
                  exr: bool = False) -> list[Path]:
    """``<output>.png`` per graph output (with ``exr``, ``<output>.exr`` too for each float
    output: :func:`rfw.fileio.exr_names`), then ``timings.json`` (last: it marks a complete
    run), each written atomically inside ``out_dir``."""
    return write_run(out_dir, result.images, plan_formats, result.timings, exr=exr,
                     source=result.config.source)


def table(timings: dict[str, Any]) -> str:
    rows = [f"{timings['config']} on {timings['device']} ({timings['driver']}), "
            f"{timings['size'][0]}x{timings['size'][1]}, {timings['frames']} frames, "
            f"{timings['triangles']:,} triangles"]
    w = max(24, *(len(p["name"]) for p in timings["passes"]))  # bridge names run long
    rows.append(f"  {'pass':<{w}} {'gpu ms':>9} {'cpu ms':>9}")
    for p in timings["passes"]:
        gpu = "-" if p["gpu_ms"] is None else f"{p['gpu_ms']:.3f}"
        rows.append(f"  {p['name']:<{w}} {gpu:>9} {p['cpu_ms']:>9.3f}")
    rows.append(f"  {'total':<{w}} {timings['gpu_ms_total']:>9.3f}")
    if timings.get("techniques"):  # what auto variants chose on this device
        rows.append("  techniques: " + ", ".join(f"{k}={v}" for k, v in
                                                 timings["techniques"].items()))
    if "bridge_ms_total" in timings:  # mixed backends: host copies, wall time
        rows.append(f"  {'bridges (host copies)':<{w}} {'-':>9} "
                    f"{timings['bridge_ms_total']:>9.3f}")
    return "\n".join(rows)
