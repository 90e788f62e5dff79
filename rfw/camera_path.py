"""Camera paths: one camera per frame, from keyframes or an orbit (a turntable).

A config's ``[camera.path]`` table (or ``--set camera.path=orbit``,
``--set camera.path.turns=0.5``) gives the path; the static camera (the ``camera`` table
over the scene's camera) is its base: what a keyframe or the orbit leaves unsaid.

```toml
[camera.path]
kind = "keyframes"              # or "orbit"
target_interpolation = "slerp"  # "linear" (default): the target moves on a straight line
keys = [
  { position = [0, 1, 5], target = [0, 0, 0] },          # t = 0
  { t = 0.25, position = [3, 1, 4] },                     # target: the base camera's
  { position = [5, 2, 0], target = [0, 0.5, 0], yfov = 40 },  # t = 1
]
```

Without ``kind`` the keys say it, in any order: ``keys`` or ``target_interpolation`` make
keyframes, an orbit key (or none) an orbit; keys of both kinds are one error.

Keyframes: frame ``k`` of ``N`` sits at ``t = k / (N - 1)`` (the first frame is the first
key, the last frame the last key, exactly); positions and fields of view interpolate
linearly between the keys around ``t``, targets linearly or, with ``slerp``, by the view
direction (spherical) and the distance to the target (linear).

Orbit: around ``center`` (default: the base camera's target) at ``radius`` and ``height``
(default: where the base camera is), starting at ``start`` degrees (default: the base
camera's angle), ``turns`` turns over the run, looking at the center. Frame ``k`` of ``N``
sits at ``t = k / N``: a whole turn does not repeat its first frame.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import RfwError, check_number, did_you_mean

PATH_KINDS = ("keyframes", "orbit")
PATH_KEYS = ("kind", "keys", "target_interpolation", "center", "radius", "height", "start",
             "turns")
KEY_KEYS = ("t", "position", "target", "yfov")
KEYFRAMES_ONLY = ("keys", "target_interpolation")
ORBIT_ONLY = ("center", "radius", "height", "start", "turns")
TARGET_INTERPOLATIONS = ("linear", "slerp")
MAX_KEYS = 10_000


FLOAT32_MAX = float(np.finfo(np.float32).max)


def check_vector(value: Any, where: str, source: str | None) -> list[float]:
    """Three numbers, each finite as a 32-bit float (the GPU's): ``1e39`` is refused here,
    naming ``where``, not an OverflowError when the camera is packed."""
    if not (isinstance(value, list) and len(value) == 3):
        raise RfwError(f"must be three numbers [x, y, z], not {value!r}", file=source,
                       element=where)
    out = [float(check_number(x, where, file=source, element=where)) for x in value]
    for x in out:
        if abs(x) > FLOAT32_MAX:
            raise RfwError(f"'{where}' must fit a 32-bit float (at most {FLOAT32_MAX:.4g} "
                           f"in size), not {x!r}", file=source, element=where)
    return out


def check_camera(cam: Any, *, file: str | None, element: str, aspect: float = 16 / 9,
                 up_given: bool = False, up_element: str | None = None) -> None:
    """Refuse a camera (:class:`rfw.scene.Camera`) whose float32 matrices keep no picture,
    naming ``element`` (``camera.position``): its position so far out that 32-bit floats
    step by more than the depth range there (every depth is then rounding noise), a
    view-projection that is singular or not finite as float32, or, when the up vector was
    given (``up_given``), an up along the view direction."""
    eye = np.asarray(cam.position, np.float64)
    step = float(np.spacing(np.float32(np.max(np.abs(eye)))))
    depth = float(cam.zfar) - float(cam.znear)
    if not step < depth:
        raise RfwError(f"{_shown(cam.position)} is too far from the origin for 32-bit floats: "
                       f"they step by {step:.3g} there, not less than the depth range "
                       f"zfar - znear = {depth:.4g}, so no depth survives", file=file,
                       element=element)
    if up_given:
        view = np.asarray(cam.target, np.float64) - eye
        up = np.asarray(cam.up, np.float64)
        if np.linalg.norm(np.cross(view, up)) <= 1e-6 * np.linalg.norm(view) * \
                np.linalg.norm(up):
            raise RfwError(f"{_shown(cam.up)} is parallel to the view direction (target - "
                           f"position = {_shown(view)}): it gives the image no top", file=file,
                           element=up_element or element)
    with np.errstate(all="ignore"):
        try:
            view = cam.view()
        except RfwError as e:  # position and target not apart
            raise RfwError(e.message, file=file, element=element) from None
        proj = cam.projection(aspect)
        vp = proj.astype(np.float64) @ view.astype(np.float64)  # as the camera uniform is
        try:
            inv = np.linalg.inv(vp)
        except np.linalg.LinAlgError:
            inv = None
        finite = all(np.all(np.isfinite(np.asarray(m, np.float32)))
                     for m in (view, proj, vp) + (() if inv is None else (inv,)))
    if inv is None or not finite:
        why = "singular" if inv is None else "not finite as 32-bit floats"
        raise RfwError(f"the camera's view-projection is {why} (position {_shown(cam.position)}, target {_shown(cam.target)}, znear "
                       f"{cam.znear:g}, zfar {cam.zfar:g})", file=file, element=element)


def _shown(v: Any) -> str:
    return "[" + ", ".join(f"{float(x):.6g}" for x in v) + "]"


def check_path(value: Any, source: str | None, where: str = "camera.path") -> dict[str, Any]:
    """``[camera.path]`` checked and normalised (plain values, ``kind`` always present); a
    bad key or value is one error naming it (``camera.path.keys[1].position``)."""
    if isinstance(value, str):  # --set camera.path=orbit
        value = {"kind": value}
    if not isinstance(value, dict):
        raise RfwError(f"must be a table or one of {', '.join(PATH_KINDS)}, not {value!r}",
                       file=source, element=where)
    for key in value:
        if key not in PATH_KEYS:
            raise RfwError(f"unknown key '{key}'" + did_you_mean(key, PATH_KEYS),
                           file=source, element=where)
    kind = value.get("kind") or _implied_kind(value, source, where)
    if kind not in PATH_KINDS:
        raise RfwError(f"'kind' must be one of {', '.join(PATH_KINDS)}, not {kind!r}"
                       + did_you_mean(str(kind), PATH_KINDS), file=source,
                       element=f"{where}.kind")
    out: dict[str, Any] = {"kind": kind}
    if kind == "keyframes":
        stray = [k for k in ORBIT_ONLY if k in value]
        if stray:
            raise RfwError(f"'{stray[0]}' belongs to an orbit, not to keyframes", file=source,
                           element=f"{where}.{stray[0]}")
        interp = value.get("target_interpolation", "linear")
        if interp not in TARGET_INTERPOLATIONS:
            raise RfwError(f"must be one of {', '.join(TARGET_INTERPOLATIONS)}, not "
                           f"{interp!r}", file=source, element=f"{where}.target_interpolation")
        out["target_interpolation"] = interp
        out["keys"] = _keys(value.get("keys"), source, f"{where}.keys")
        return out
    stray = [k for k in KEYFRAMES_ONLY if k in value]
    if stray:
        raise RfwError(f"an orbit has no {stray[0]} (kind = \"keyframes\" has)", file=source,
                       element=f"{where}.{stray[0]}")
    if "center" in value:
        out["center"] = check_vector(value["center"], f"{where}.center", source)
    for key, lo in (("radius", 1e-6), ("height", -1e9), ("start", -1e6), ("turns", -1e6)):
        if key in value:
            out[key] = float(check_number(value[key], key, lo=lo, hi=1e9, file=source,
                                          element=f"{where}.{key}"))
    return out


def _implied_kind(value: dict[str, Any], source: str | None, where: str) -> str:
    """The kind a path without ``kind`` implies: keyframes for a keyframe-only key, an
    orbit for an orbit-only key (or none), whatever order ``--set`` gave them in."""
    frames = [k for k in KEYFRAMES_ONLY if k in value]
    orbit = [k for k in ORBIT_ONLY if k in value]
    if frames and orbit:
        raise RfwError(f"mixes keyframe keys ({', '.join(frames)}) with orbit keys "
                       f"({', '.join(orbit)}): a path is one kind", file=source, element=where)
    return "keyframes" if frames else "orbit"


def _keys(keys: Any, source: str | None, where: str) -> list[dict[str, Any]]:
    if not isinstance(keys, list) or not 2 <= len(keys) <= MAX_KEYS:
        raise RfwError(f"must be a list of at least two keyframes (tables with position, "
                       f"target, yfov, t), not {keys!r}"[:200], file=source, element=where)
    out = []
    for i, key in enumerate(keys):
        kw = f"{where}[{i}]"
        if not isinstance(key, dict):
            raise RfwError(f"must be a table, not {key!r}", file=source, element=kw)
        for k in key:
            if k not in KEY_KEYS:
                raise RfwError(f"unknown key '{k}'" + did_you_mean(k, KEY_KEYS), file=source,
                               element=kw)
        entry: dict[str, Any] = {}
        if "t" in key:
            entry["t"] = float(check_number(key["t"], "t", lo=0.0, hi=1.0, file=source,
                                            element=f"{kw}.t"))
        for k in ("position", "target"):
            if k in key:
                entry[k] = check_vector(key[k], f"{kw}.{k}", source)
        if "yfov" in key:
            entry["yfov"] = float(check_number(key["yfov"], "yfov", lo=0.01, hi=179.0,
                                               file=source, element=f"{kw}.yfov"))
        out.append(entry)
    times = key_times(out)
    if times[0] != 0.0 or times[-1] != 1.0:
        raise RfwError("the first keyframe's t must be 0 and the last one's 1", file=source,
                       element=where)
    if any(b <= a for a, b in itertools.pairwise(times)):
        raise RfwError(f"keyframe times must increase, not {times}", file=source,
                       element=where)
    return out


def key_times(keys: list[dict[str, Any]]) -> list[float]:
    """Each key's t: its own, else evenly spaced over [0, 1] (by index)."""
    n = len(keys)
    return [k.get("t", i / (n - 1)) for i, k in enumerate(keys)]


def _lerp(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    # (1 - u) a + u b: exactly a at u = 0 and exactly b at u = 1
    return (1.0 - u) * a + u * b


def _slerp(a: np.ndarray, b: np.ndarray, u: float, up: np.ndarray) -> np.ndarray:
    """Unit vectors ``a`` to ``b`` along the great circle (linear when nearly parallel).
    Opposite directions have no one great circle: the turn goes around ``up`` (the camera's
    up; another axis where ``a`` runs along it), the same way every time."""
    dot = float(np.clip(a @ b, -1.0, 1.0))
    angle = math.acos(dot)
    if angle < 1e-6:
        v = _lerp(a, b, u)
        return v / np.linalg.norm(v)
    side = b - dot * a  # the turn's direction, square to a
    if np.linalg.norm(side) < 1e-6:
        # opposite: turn in the plane square to the axis (up with its part along a removed)
        for axis in (np.asarray(up, np.float64), np.array([0.0, 1.0, 0.0]),
                     np.array([1.0, 0.0, 0.0])):
            axis = axis - (axis @ a) * a
            if np.linalg.norm(axis) > 1e-6:
                break
        side = np.cross(axis, a)
    side = side / np.linalg.norm(side)
    v = math.cos(u * angle) * a + math.sin(u * angle) * side
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class CameraPath:
    """A checked ``[camera.path]`` over a base camera (:class:`rfw.scene.Camera`)."""

    spec: dict[str, Any]
    base: Any  # the static camera: what the path leaves unsaid

    @property
    def kind(self) -> str:
        return self.spec["kind"]

    def param(self, frame: int, frames: int) -> float:
        """The path parameter t of frame ``frame`` (0-based) of ``frames``."""
        if self.kind == "orbit":
            return frame / frames
        return frame / (frames - 1) if frames > 1 else 0.0

    def at(self, t: float) -> Any:
        """The camera at parameter ``t`` in [0, 1]."""
        return self._orbit(t) if self.kind == "orbit" else self._keyframes(t)

    def camera(self, frame: int, frames: int) -> Any:
        return self.at(self.param(frame, frames))

    def _orbit(self, t: float) -> Any:
        base = self.base
        s = self.spec
        center = np.array(s.get("center", base.target), np.float64)
        offset = np.array(base.position, np.float64) - center
        radius = s.get("radius", float(math.hypot(offset[0], offset[2])) or 1.0)
        height = s.get("height", float(offset[1]))
        start = s.get("start", math.degrees(math.atan2(offset[0], offset[2])))
        angle = math.radians(start) + 2.0 * math.pi * s.get("turns", 1.0) * t
        eye = center + np.array([radius * math.sin(angle), height, radius * math.cos(angle)])
        return replace(base, position=tuple(map(float, eye)),
                       target=tuple(map(float, center)))

    def _keyframes(self, t: float) -> Any:
        keys = self.spec["keys"]
        times = key_times(keys)
        t = min(max(float(t), 0.0), 1.0)
        i = max(0, min(len(keys) - 2, int(np.searchsorted(times, t, side="right")) - 1))
        t0, t1 = times[i], times[i + 1]
        u = (t - t0) / (t1 - t0)
        a, b = self._key(keys[i]), self._key(keys[i + 1])
        if u <= 0.0:
            return a
        if u >= 1.0:
            return b
        pa, pb = (np.array(c.position, np.float64) for c in (a, b))
        ta, tb = (np.array(c.target, np.float64) for c in (a, b))
        eye = _lerp(pa, pb, u)
        if self.spec["target_interpolation"] == "slerp":
            da, db = ta - pa, tb - pb
        if self.spec["target_interpolation"] == "slerp" and np.linalg.norm(da) > 0 \
                and np.linalg.norm(db) > 0:
            la, lb = float(np.linalg.norm(da)), float(np.linalg.norm(db))
            at = eye + _slerp(da / la, db / lb, u, np.array(a.up, np.float64)) * (
                (1 - u) * la + u * lb)
        else:
            at = _lerp(ta, tb, u)
        return replace(a, position=tuple(map(float, eye)), target=tuple(map(float, at)),
                       yfov=float((1 - u) * a.yfov + u * b.yfov))

    def _key(self, key: dict[str, Any]) -> Any:
        """A keyframe as a camera: the base camera with the key's fields."""
        values: dict[str, Any] = {k: tuple(key[k]) for k in ("position", "target") if k in key}
        if "yfov" in key:
            values["yfov"] = float(np.radians(key["yfov"]))
        return replace(self.base, **values)


def path_for(cfg: Any, base: Any) -> CameraPath | None:
    """The camera path ``cfg`` asks for over its static camera ``base``
    (``rfw.frame.camera_for``), or None."""
    spec = (cfg.camera or {}).get("path")
    if not spec:
        return None
    path = CameraPath(spec, base)
    check_cameras(path, cfg)
    return path


def check_cameras(path: CameraPath, cfg: Any) -> None:
    """Every keyframe's camera (the cameras between two keys lie between theirs), or eight
    of an orbit's, through :func:`check_camera`, naming the key: a path that would leave
    the float32 range mid-run is refused before its first frame."""
    up_given = "up" in (cfg.camera or {})
    aspect = cfg.size[0] / cfg.size[1]
    if path.kind == "keyframes":
        for i, key in enumerate(path.spec["keys"]):
            where = f"camera.path.keys[{i}]"
            check_camera(path._key(key), file=cfg.source, aspect=aspect, up_given=up_given,
                         element=f"{where}.position" if "position" in key else where,
                         up_element=where)
        return
    for k in range(8):
        try:
            check_camera(path.at(k / 8), file=cfg.source, element="camera.path",
                         aspect=aspect, up_given=up_given)
        except RfwError as e:
            raise RfwError(f"the orbit's camera at t = {k / 8:g}: {e.message}",
                           file=cfg.source, element="camera.path") from None


def describe(camera: Any, t: float) -> dict[str, Any]:
    """A frame's camera parameter as a record holds it (yfov in degrees)."""
    return {"t": round(float(t), 9), "position": [float(v) for v in camera.position],
            "target": [float(v) for v in camera.target],
            "yfov": float(np.degrees(camera.yfov))}


def _queued_writes(scene: Any) -> bool:
    """Whether a camera set on ``scene`` (a backend's upload) between frames is the next
    frame's alone, so frames in flight keep theirs without a drain: wgpu's
    ``queue.write_buffer`` lands after every frame submitted before it; vk's scene
    (``camera_per_frame``) hands each frame the cameras it began with, copied in by the
    frame's own command buffer. Anything else is written by the CPU at once and must wait
    for the frames that read it."""
    return getattr(type(scene), "camera_per_frame", False) is True


def set_frame_camera(frame: Any, camera: Any) -> None:
    """Render ``frame``'s next frame from ``camera`` (every backend's scene), draining the
    frames in flight only where a backend's camera write would race them."""
    if not all(_queued_writes(sc) for sc in frame.scenes):
        frame.drain()
    for sc in frame.scenes:
        sc.camera = camera
        sc.set_viewport(sc.size)


def run_path(frame: Any, path: CameraPath | None, *, warmup: int, frames: int,
             each_frame: Callable[[int, Any], None] | None = None,
             timeline: Any = None) -> list[dict[str, Any]]:
    """``warmup`` untimed frames from the path's first camera, then ``frames`` timed ones,
    frame ``k`` from ``path.camera(k, frames)``; ``each_frame(k, frame)`` after frame k.
    A ``timeline`` (:class:`rfw.timeline.Timeline`) shows the scene's animations at
    ``timeline.time(k)`` in timed frame ``k`` (the warm-up frames at frame 0's time).
    Returns each timed frame's camera (:func:`describe`, with ``write_ms``: the host time of
    writing it, waits for frames in flight included), empty without a path."""
    from .timeline import set_frame_time

    if path is not None:
        set_frame_camera(frame, path.camera(0, frames))
    if timeline is not None:
        set_frame_time(frame, timeline.time(0))
    frame.run(warmup)
    frame.clear_timings()
    cameras = []
    for k in range(frames):
        if timeline is not None and k:
            set_frame_time(frame, timeline.time(k))
        if path is not None:
            cam = path.camera(k, frames)
            start = time.perf_counter()
            if k:
                set_frame_camera(frame, cam)
            # a write's wait for frames in flight (a backend that needs one) is frame time
            cameras.append({**describe(cam, path.param(k, frames)),
                            "write_ms": (time.perf_counter() - start) * 1e3})
        frame.step(last=k == frames - 1)
        if each_frame is not None:
            each_frame(k, frame)
    return cameras


FRAMES_DIR = "frames"  # per-frame images go here, inside --out


def old_frames(out_dir: Path) -> list[Path]:
    """The per-frame images (``<output>.<k>.png`` and ``.exr``) in ``<out_dir>/frames``."""
    folder = out_dir / FRAMES_DIR
    if not folder.is_dir() or folder.is_symlink():
        return []
    return sorted(p for pattern in ("*.[0-9][0-9][0-9][0-9].png", "*.[0-9][0-9][0-9][0-9].exr")
                  for p in folder.glob(pattern) if p.is_file() or p.is_symlink())


def frame_writer(out_dir: Path, every: int, frames: int, *,
                 exr: bool = False) -> Callable[[int, Any], None]:
    """An ``each_frame`` callback writing every output of timed frames ``0, every, 2 *
    every, ...`` and the last one as ``<out_dir>/frames/<output>.<k>.png`` (k 4 digits),
    with ``exr`` also ``<output>.<k>.exr`` for each float output (as ``rfw run --exr``).
    ``rfw run`` gives it its staging folder and, on success, replaces the earlier frames
    (:func:`old_frames`) with these (:mod:`rfw.outdir`)."""
    from .fileio import atomic_write, inside, is_float_image, png_bytes, write_exr

    folder = inside(out_dir, FRAMES_DIR)

    def write(k: int, frame: Any) -> None:
        if k % every and k != frames - 1:
            return
        folder.mkdir(parents=True, exist_ok=True)
        for name in frame.plan.outputs:
            image = frame.read(name)
            data = png_bytes(image, frame.plan.resource(name).format)
            atomic_write(inside(out_dir, f"{FRAMES_DIR}/{name}.{k:04d}.png"),
                         lambda f, d=data: f.write(d))
            if exr and is_float_image(image):  # the exact values, as --exr writes the last
                write_exr(inside(out_dir, f"{FRAMES_DIR}/{name}.{k:04d}.exr"), image)

    return write
