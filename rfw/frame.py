"""A frame of a compiled graph on its backends, and what the frame driver
(:func:`rfw.render.render`) shares with the backends: the ``Result`` of a run, the scene and
camera a config asks for, and the fields of ``timings.json`` every backend writes.

``prepare`` plans the frame (one :class:`rfw.mixed.FramePlan` for every run: one side for a
frame on one backend, the per-backend sides and their bridges of a mixed one,
:func:`rfw.mixed.split`) and fits each side's graph to its device, ``start`` uploads the
scene and makes the executors, and the :class:`Frame` runs them.

**Frames in flight.** An executor submits a frame and returns without waiting for it: up to
``RunOptions.in_flight()`` frames (:mod:`rfw.options`; default 2, 1 waits for each, as
before) run on the GPU while the next ones record. Each has a slot (:class:`InFlight`) with
its own command buffer, fence, timestamp queries and readback; a frame waits only for the
frame that last used its slot, and that frame's timings are appended then. Everything that
reads results (``read``, bridges, ``clear_timings``, ``destroy``, the reports) drains the
frames in flight first, and ``run(n)`` returns with its frames done (the bench's wall time
counts that drain), so images and timing samples are what waiting for every frame gave."""

from __future__ import annotations

import statistics
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .backend import Backend, Devices, get_backend
from .config import Built, Config, pass_class
from .errors import (
    RfwError,
    RfwTypeError,
    RfwValueError,
    check_bool,
    check_number,
    check_path,
    did_you_mean,
    type_name,
)
from .graph import CompiledGraph
from .mixed import FramePlan, split
from .options import DEFAULT, DEFAULT_FRAMES_IN_FLIGHT, MAX_FRAMES_IN_FLIGHT, RunOptions

if TYPE_CHECKING:
    from .backends.base import FrameExecutor


def frames_in_flight(value: Any = None) -> int:
    """How many frames an executor keeps in flight: ``value`` checked (1 to 8), else 2. 1
    waits for every frame before the next one records (the same-run baseline). A run's
    setting is its :class:`rfw.options.RunOptions` (``in_flight``), which the frame driver
    hands the executors (:func:`start`)."""
    if value is None:
        return DEFAULT_FRAMES_IN_FLIGHT
    return check_number(value, "frames_in_flight", kind=int, lo=1, hi=MAX_FRAMES_IN_FLIGHT,
                        element="frames_in_flight")


class InFlight:
    """An executor's ring of frame slots and the frames submitted from them, oldest first.

    ``slot(i)`` hands frame ``i`` its slot once the frame that used it last is finished
    (frames finish in submission order, so every older one is finished first);
    ``submitted(slot, finish)`` records that ``finish()`` waits for a submitted frame and
    appends its timings; ``drain()`` finishes every frame in flight."""

    def __init__(self, slots: list[Any]):
        self.slots = slots
        self._pending: deque[tuple[Any, Callable[[], None]]] = deque()

    def __len__(self) -> int:
        return len(self.slots)

    @property
    def busy(self) -> int:
        """Frames submitted and not yet finished."""
        return len(self._pending)

    def slot(self, frame_index: int) -> Any:
        slot = self.slots[frame_index % len(self.slots)]
        while any(s is slot for s, _ in self._pending):
            self._finish_oldest()
        return slot

    def submitted(self, slot: Any, finish: Callable[[], None]) -> None:
        self._pending.append((slot, finish))

    def drain(self) -> None:
        while self._pending:
            self._finish_oldest()

    def forget(self) -> None:
        """Drop the frames in flight without their timings (the device is idle or gone)."""
        self._pending.clear()

    def _finish_oldest(self) -> None:
        _, finish = self._pending.popleft()
        finish()


def run_frames(executor: Any, frames: int) -> None:
    """``frames`` frames of ``executor``; the last one also drains the frames in flight, so
    ``run`` returns with its frames done and a per-frame clock around ``frame()`` (the
    bench's) counts the drain."""
    for k in range(frames):
        one_frame(executor, last=k == frames - 1)


def one_frame(executor: Any, *, last: bool) -> None:
    """One frame of ``executor``, draining the frames in flight inside it if ``last``."""
    from .signals import check

    check()  # a signal whose first raise was swallowed still ends the run here
    executor.frame(drain=last)


@dataclass
class Result:
    """What a render gives back: ``images`` (output -> (H, W, C) numpy array as read back:
    uint8 for 8-bit formats, float16/float32 for float ones), ``timings`` (what
    ``timings.json`` holds) and the run's :class:`Frame` (destroyed; its ``plan``, its
    frame plan and its executors' timings stay readable).
    In Jupyter a result shows its images and per-pass times."""

    config: Config
    images: dict[str, np.ndarray]  # output resource -> (H, W, C) array
    timings: dict[str, Any]  # what timings.json holds
    frame: Frame

    @property
    def executor(self) -> FrameExecutor:
        """The executor of a frame on one backend (its ``plan``, ``timings``, queues); a
        frame that mixes backends has one per backend, in ``frame.executors``."""
        if len(self.frame.executors) != 1:
            raise RfwError(f"this run mixes backends ({', '.join(self.frame.executors)}): "
                           "each has its executor in result.frame.executors",
                           file=self.config.source, element="Result.executor")
        (ex,) = self.frame.executors.values()
        return ex

    @property
    def formats(self) -> dict[str, str]:
        """Each output's format (``rgba8unorm``, ``rgba16float``, ...)."""
        return {r.name: r.format for r in self.frame.plan.resources if r.name in self.images}

    @property
    def gpu_ms(self) -> dict[str, float | None]:
        """Per pass, the median GPU ms over the timed frames (None: no timestamps)."""
        return {p["name"]: p["gpu_ms"] for p in self.timings["passes"]}

    @property
    def cpu_ms(self) -> dict[str, float]:
        """Per pass, the median CPU ms of recording it."""
        return {p["name"]: p["cpu_ms"] for p in self.timings["passes"]}

    @property
    def gpu_ms_total(self) -> float:
        return self.timings["gpu_ms_total"]

    def png(self, name: str | None = None) -> bytes:
        """Output ``name`` (default: the first) as the PNG ``rfw run`` writes for it."""
        from .fileio import png_bytes

        name = self._name(name)
        return png_bytes(self.images[name], self.formats[name])

    def save(self, out: str | Path, *, exr: bool = False) -> list[Path]:
        """Write what ``rfw run --out OUT [--exr]`` writes into folder ``out``; returns the
        paths written."""
        from .fileio import write_run

        out = check_path(out, "out", element="Result.save")
        exr = check_bool(exr, "exr", element="Result.save")
        if out.exists() and not out.is_dir():  # a file or device is never replaced
            raise RfwValueError(f"'out' must be a folder, and {str(out)!r} is not one",
                                element="Result.save")
        return write_run(out, self.images, self.formats, self.timings, exr=exr,
                         source=self.config.source)

    def _name(self, name: str | None) -> str:
        if name is None:
            return next(iter(self.images))
        if not isinstance(name, str):  # an output's name ('tonemap.ldr')
            raise RfwTypeError(f"'name' must be an output name (str), not {type_name(name)}",
                               file=self.config.source, element="Result")
        if name not in self.images:
            raise RfwError(f"no output '{name}'" + did_you_mean(name, self.images)
                           + f"; outputs: {', '.join(self.images)}", file=self.config.source,
                           element="outputs")
        return name

    def __repr__(self) -> str:
        t = self.timings
        outputs = ", ".join(f"{n} {a.shape[1]}x{a.shape[0]} {self.formats.get(n, a.dtype)}"
                            for n, a in self.images.items())
        return (f"<rfw.Result {t['config']!r} on {t['device']}, {t['frames']} frames: "
                f"{outputs}; gpu {t['gpu_ms_total']:.3f} ms>")

    def _repr_png_(self) -> bytes:
        return self.png()

    def _repr_html_(self) -> str:
        import base64
        import html

        cells = "".join(
            f'<figure style="display:inline-block;margin:4px"><img alt="{html.escape(n)}" '
            f'src="data:image/png;base64,{base64.b64encode(self.png(n)).decode()}"/>'
            f"<figcaption>{html.escape(n)} ({html.escape(self.formats[n])})</figcaption>"
            "</figure>" for n in self.images)
        rows = "".join(
            f"<tr><td>{html.escape(p['name'])}</td><td>"
            f"{'-' if p['gpu_ms'] is None else format(p['gpu_ms'], '.3f')}</td>"
            f"<td>{p['cpu_ms']:.3f}</td></tr>" for p in self.timings["passes"])
        t = self.timings
        head = html.escape(f"{t['config']} on {t['device']}, {t['size'][0]}x{t['size'][1]}, "
                           f"{t['frames']} frames")
        return (f"<div><p>{head}</p>{cells}<table><tr><th>pass</th><th>gpu ms</th>"
                f"<th>cpu ms</th></tr>{rows}<tr><td>total</td>"
                f"<td>{t['gpu_ms_total']:.3f}</td><td></td></tr></table></div>")


def load_scene_for(cfg: Config, scene: Any = None) -> Any:
    if scene is not None:
        return scene
    from .scene import default_scene, is_builtin, load_scene

    if cfg.scene == "default":
        return default_scene()
    if is_builtin(cfg.scene) and not Path(cfg.scene).exists():  # courtyard, stress:COUNT, ...
        return load_scene(cfg.scene)
    path = Path(cfg.scene)
    if not path.exists() and not path.suffix:
        # a fetched scene's name (rfw.run(scene="dragon"), scene = "dragon" in a config): its
        # cached GLB; else one line naming the config, with the close names
        from .scene.names import resolve_scene

        return load_scene(resolve_scene(cfg.scene, file=cfg.source, element="scene"))
    if not path.exists():  # say which config (or --scene) asked for it
        raise RfwError(f"scene file not found: {cfg.scene}", file=cfg.source,
                       element="scene")
    return load_scene(cfg.scene)


def camera_for(cfg: Config, scene: Any) -> Any:
    """The static camera of ``cfg``: the scene's camera (``camera.gltf``: by name or index,
    else its first, else one framing its bounds) with the ``camera`` table's keys over it
    (yfov in degrees). A path (``camera.path``) starts from it: :mod:`rfw.camera_path`."""
    from dataclasses import replace

    values = dict(cfg.camera or {})
    values.pop("path", None)
    chosen = values.pop("gltf", None)
    cam = scene.default_camera() if chosen is None else gltf_camera(cfg, scene, chosen)
    if "yfov" in values:
        values["yfov"] = float(np.radians(values["yfov"]))
    if values:
        cam = replace(cam, **{k: tuple(v) if isinstance(v, list) else v
                              for k, v in values.items()})
    try:  # position and target apart and finite: said now, naming the config
        cam.view()
    except RfwError as e:
        raise e.in_file(cfg.source if values else getattr(scene, "source", None)) from None
    if not cam.znear < cam.zfar:  # one of them from the scene's camera
        raise RfwError(f"znear {cam.znear:g} must be smaller than zfar {cam.zfar:g} (the "
                       f"other from the scene's camera)", file=cfg.source, element="camera")
    from .camera_path import check_camera

    # float32 keeps a picture: the config's keys over the scene's camera, checked together
    check_camera(cam, file=cfg.source if values else getattr(scene, "source", None),
                 element="camera.position" if "position" in values else "camera",
                 aspect=cfg.size[0] / cfg.size[1], up_given="up" in values,
                 up_element="camera.up")
    return cam


def gltf_camera(cfg: Config, scene: Any, chosen: str | int) -> Any:
    """The scene camera ``camera.gltf`` names (a name, or an index into the scene's
    cameras); anything else is one line listing the scene's cameras."""
    cams = list(scene.cameras)
    names = [c.name or f"#{i}" for i, c in enumerate(cams)]
    listed = ", ".join(f"{i}: {n!r}" for i, n in enumerate(names)) or "none"
    if isinstance(chosen, int):
        if 0 <= chosen < len(cams):
            return cams[chosen]
        raise RfwError(f"camera index {chosen} is out of range: scene "
                       f"{scene.source or scene.name!r} has {len(cams)} camera(s) ({listed})",
                       file=cfg.source, element="camera.gltf")
    for cam in cams:
        if cam.name == chosen:
            return cam
    raise RfwError(f"scene {scene.source or scene.name!r} has no camera named {chosen!r} "
                   f"(cameras: {listed})", file=cfg.source, element="camera.gltf",
                   suggest=(chosen, [c.name for c in cams if c.name]))


def pass_timings(order: Any, timings: dict[str, Any]) -> list[dict[str, Any]]:
    """``timings.json``'s per-pass entries: medians over the timed frames."""
    return [{"name": n, "gpu_ms": median(timings[n].gpu_ms),
             "cpu_ms": median(timings[n].cpu_ms)} for n in order]


def frame_record(cfg: Config, frames: int, scene: Any, default_light: bool,
                 passes: list[dict[str, Any]], *, timestamps: bool) -> dict[str, Any]:
    """The fields of ``timings.json`` every backend writes (the device's come first)."""
    return {"config": cfg.name, "variants": cfg.chosen, "size": list(cfg.size),
            "frames": frames, "scene": scene.name, "triangles": scene.triangle_count,
            "default_light": default_light, "timestamps": timestamps, "passes": passes,
            "gpu_ms_total": sum(p["gpu_ms"] or 0.0 for p in passes)}


def pinned_elsewhere(cfg: Config, backend: str) -> bool:
    """Whether an enabled pass of ``cfg`` is pinned (in the config or by its class) to a
    backend other than ``backend``: its frame then mixes backends."""
    return any(e.enabled and (e.backend or pass_class(cfg, e).backend) not in (None, backend)
               for e in cfg.passes)


def median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


@dataclass
class BridgeTiming:
    name: str
    cpu_ms: list[float] = field(default_factory=list)
    bytes: int = 0


class Frame:
    """A run of one graph: drives one executor per backend through the full plan's order,
    bridges in between (a frame on one backend is its executor's own frames).

    ``frame_plan`` is what each backend runs (:class:`rfw.mixed.FramePlan`), ``plan`` its
    full compiled plan; ``executors`` maps a backend's name to the executor built on that
    backend's sub-plan, ``backends`` to its :class:`rfw.backend.Backend` (which copies
    through the host at bridges), ``devices`` to the device each runs on."""

    def __init__(self, frame_plan: FramePlan, executors: dict[str, Any],
                 backends: dict[str, Backend] | None = None):
        self.frame_plan = frame_plan
        self.plan = frame_plan.plan
        self.executors = executors
        self.backends = backends if backends is not None else {}
        self.scenes: list[Any] = []  # each backend's upload of the scene, owned by the frame
        self.borrowed: list[Any] = []  # ... those of them the caller owns (start's uploads)
        self.devices: dict[str, Any] = {}
        self.frame_index = 0
        self.bridge_timings = {n: BridgeTiming(n) for n in frame_plan.bridges}
        self.default_light = False
        self._devices: Devices | None = None  # devices open_frame made, closed by destroy

    def run(self, frames: int = 1) -> None:
        """``frames`` frames; returns once they are done (the last one drains)."""
        if self.frame_plan.single:
            for ex in self.executors.values():  # one side: the executor's own frames
                ex.run(frames)
            self.frame_index += frames
            return
        run_frames(self, frames)

    def step(self, *, last: bool) -> None:
        """One frame as :meth:`run` drives it, draining the frames in flight only if
        ``last`` (``rfw.camera_path``: a camera between frames)."""
        if self.frame_plan.single:
            (ex,) = self.executors.values()
            one_frame(ex, last=last)
            self.frame_index += 1
            return
        one_frame(self, last=last)


    def keep_in_flight(self, frames: int) -> None:
        """Keep up to ``frames`` frames in flight on every executor that has frames in
        flight (one without them waits for each frame)."""
        for ex in self.executors.values():
            if hasattr(ex, "keep_in_flight") and len(ex.in_flight) != frames:
                ex.keep_in_flight(frames)

    def drain(self) -> None:
        """Wait for every executor's frames in flight (their timings are appended)."""
        for ex in self.executors.values():
            drain = getattr(ex, "drain", None)  # an executor without frames in flight waits
            if drain is not None:
                drain()

    def set_camera(self, camera: Any) -> None:
        """Render from ``camera`` from the next frame on: every backend's scene takes it for
        its next frame (:func:`rfw.camera_path.set_frame_camera`: frames in flight keep
        theirs, drained first only where a backend's camera write would race them)."""
        from .camera_path import set_frame_camera

        set_frame_camera(self, camera)

    def frame(self, drain: bool = False) -> None:
        exs = self.executors
        for ex in exs.values():
            ex.begin_frame()
        for name in self.plan.order:
            br = self.frame_plan.bridges.get(name)
            if br is None:
                exs[self.frame_plan.side[name]].record(name)
                continue
            src, dst = exs[br.src], exs[br.dst]
            src.record(name)  # vk: the plan's barriers to transfer src
            dst.record(name)  # vk: ... and to transfer dst, aliasing included
            src.flush()
            dst.flush()  # uploads go ahead of unsubmitted work: submit it first
            t = time.perf_counter()
            data = self.backends[br.src].read_bridge(src, name, br.resource)
            self.backends[br.dst].write_bridge(dst, name, br.copy, data)
            timing = self.bridge_timings[name]
            timing.cpu_ms.append((time.perf_counter() - t) * 1e3)
            timing.bytes = int(data.nbytes)
        for ex in exs.values():
            ex.end_frame()
        if drain:
            self.drain()
        self.frame_index += 1

    def clear_timings(self) -> None:
        self.drain()  # a frame in flight appends its timings when it finishes
        for ex in self.executors.values():
            for t in ex.timings.values():
                t.gpu_ms.clear()
                t.cpu_ms.clear()
        for t in self.bridge_timings.values():
            t.cpu_ms.clear()

    def read(self, resource: str) -> np.ndarray:
        """An output (or any resource) from the backend that holds it, after every frame in
        flight is done."""
        self.drain()
        return self.executors[self.frame_plan.owner[resource]].read(resource)

    def pass_timings(self) -> list[dict[str, Any]]:
        """timings.json's ``passes``: every pass of the full order, bridges included."""
        out = []
        for name in self.plan.order:
            side = self.frame_plan.backend_of(name)
            if name in self.frame_plan.bridges:
                t = self.bridge_timings[name]
                out.append({"name": name, "gpu_ms": None, "cpu_ms": median(t.cpu_ms),
                            "backend": side, "bytes": t.bytes})
            else:
                entry = pass_timings([name], self.executors[side].timings)[0]
                out.append({**entry, "backend": side})
        return out

    def destroy(self) -> None:
        """Destroy the executors (each drains first), then the scenes (then the devices
        open_frame made)."""
        for ex in self.executors.values():
            ex.destroy()
        for sc in reversed(self.scenes):
            if not any(sc is b for b in self.borrowed):
                sc.destroy()
        self.scenes, self.borrowed = [], []
        if self._devices is not None:
            self._devices.close()


@dataclass
class Side:
    """One backend's part of a frame: its plan fitted to its device."""

    backend: Backend
    device: Any
    plan: CompiledGraph
    fitted: Any  # what the backend's fit hands its executor
    passes: dict[str, Any]  # pass instances it records
    outputs: tuple[str, ...]  # graph outputs it holds


def prepare(built: Built, backend: str, devices: Devices, *, options: RunOptions = DEFAULT,
            mix: bool = True) -> tuple[FramePlan, dict[str, Side]]:
    """The frame's plan (split, ``split``), each backend's part compiled once for its device
    (fitted to its memory requirements, with ``options``: aliasing, vk's order seed), and
    checked that backend can run its passes. ``mix=False``: the whole graph on ``backend``
    (a frame of one side, no bridges: its plan is that side's)."""
    if not mix:
        return _whole(built, backend, devices, options)
    frame_plan = split(built, backend)
    sides: dict[str, Side] = {}
    for s in frame_plan.sides:
        be = get_backend(s, file=built.graph.source, element=None)
        device = devices.get(be)
        outputs = tuple(o for o in frame_plan.plan.outputs if frame_plan.owner.get(o) == s)
        plan, fitted = be.fit(frame_plan.graphs[s], device, readback=bool(outputs),
                              options=options)
        frame_plan.check(s, plan)
        passes = {n: built.passes[n] for n in plan.order if n in built.passes}
        sides[s] = Side(be, device, plan, fitted, passes, outputs)
    for side in sides.values():  # e.g. a missing GLSL source fails before any upload
        side.backend.check(side.plan, side.passes)
    return frame_plan, sides


def _whole(built: Built, backend: str, devices: Devices,
           options: RunOptions) -> tuple[FramePlan, dict[str, Side]]:
    be = get_backend(backend, file=built.graph.source)
    device = devices.get(be)
    plan, fitted = be.fit(built.graph, device, readback=True, options=options)
    be.check(plan, built.passes)  # e.g. a missing GLSL source fails before any upload
    whole = FramePlan.whole(plan, backend, built.graph, built.slots)
    return whole, {backend: Side(be, device, plan, fitted, built.passes, tuple(plan.outputs))}


def start(frame_plan: FramePlan, sides: dict[str, Side], *, scene: Any = None,
          camera: Any = None,
          size: tuple[int, int] | None = None, options: RunOptions = DEFAULT,
          uploads: dict[str, Any] | None = None) -> Frame:
    """Upload ``scene`` to each backend used and make its executor (with ``options``: frames
    in flight, vk's caches and fuzzing); the frame owns both. ``uploads`` maps a backend to a
    scene already uploaded there (e.g. ``rfw view``'s, kept across changes of config): used
    as it is, and left to the caller to destroy."""
    frame = Frame(frame_plan, {}, {s: side.backend for s, side in sides.items()})
    # one jitter for the whole frame, whichever side the pass that asks for it runs on
    jitter = max((p.camera_jitter() for side in sides.values() for p in side.passes.values()),
                 default=0)
    try:
        for s, side in sides.items():
            uploaded = (uploads or {}).get(s)
            if uploaded is not None:  # the caller's: the frame sets its camera, no more
                frame.scenes.append(uploaded)
                frame.borrowed.append(uploaded)
            elif scene is not None:
                uploaded = side.backend.scene(side.device, scene, camera,
                                              size or frame_plan.plan.size)
                frame.scenes.append(uploaded)
            frames = getattr(uploaded, "frames", None)  # a third-party scene may have none
            if frames is not None:
                frames.jitter = jitter
            elif uploaded is not None and jitter:
                raise RfwError(f"backend '{s}': its scene has no per-frame cameras "
                               "(CameraFrames), so no pass can have a jittered camera on it")
            frame.executors[s] = side.backend.executor(
                side.device, side.plan, side.passes, frame_plan.slots, uploaded,
                readback=side.outputs, fitted=side.fitted, options=options)
        frame.keep_in_flight(options.in_flight())  # each executor, whether it took options or not
    except BaseException:
        frame.destroy()
        raise
    frame.devices = {s: side.device for s, side in sides.items()}
    frame.default_light = bool(frame.scenes and frame.scenes[0].default_light)
    return frame


def open_frame(built: Built, backend: str = "wgpu", *, devices: Any = (), scene: Any = None,
               camera: Any = None, size: tuple[int, int] | None = None,
               options: RunOptions = DEFAULT) -> Frame:
    """``prepare`` and ``start`` in one: a frame of ``built`` ready to run. ``devices`` is
    a :class:`rfw.backend.Devices` or devices to use; a backend with passes and none of them
    gets a device made here (with ``options``: its validation layer, GPU, queues) that the
    frame's ``destroy()`` releases."""
    own = not isinstance(devices, Devices)
    devs = Devices(devices, options=options) if own else devices
    try:
        frame_plan, sides = prepare(built, backend, devs, options=options)
        frame = start(frame_plan, sides, scene=scene, camera=camera, size=size,
                      options=options)
    except BaseException:
        if own:
            devs.close()
        raise
    frame._devices = devs if own else None
    return frame
