"""The frame timeline: the time, in seconds, at which each frame shows the scene's node
animations (:mod:`rfw.scene.animation`, read from glTF files).

A camera path has no clock: its keys are spread over the run, frame ``k`` of ``N`` at
``t = k / (N - 1)`` (:mod:`rfw.camera_path`). Animations have one, their keys are seconds,
so they are played by a frame rate instead: timed frame ``k`` shows them at
``start + k / fps`` seconds (the warm-up frames at ``start``, as they take a path's first
camera), and with ``loop`` a time past the clip's end comes round again from 0. A config's
``[animation]`` table (or ``--set animation.fps=30``) sets it:

```toml
[animation]
fps = 60       # frames per second of the timeline (default 60)
start = 0.0    # seconds at the first timed frame (default 0)
loop = true    # past the end of the clip, from its start again (false: hold the last pose)
clip = "walk"  # the scene's animation to play, by name or index (default: all at once)
```

A scene without animations takes no notice of it: its frames run as they always did.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from .errors import RfwError, check_number, did_you_mean

ANIMATION_KEYS = ("fps", "start", "loop", "clip")
DEFAULT_FPS = 60.0
_BOOLEANS = {"true": True, "on": True, "yes": True, "1": True,
             "false": False, "off": False, "no": False, "0": False}


def check_animation(value: Any, source: str | None, where: str = "animation") -> dict[str, Any]:
    """The ``[animation]`` table checked; a bad key or value is one error naming it."""
    if not isinstance(value, dict):
        raise RfwError(f"must be a table (fps, start, loop, clip), not {value!r}",
                       file=source, element=where)
    out: dict[str, Any] = {}
    for key, v in value.items():
        kw = f"{where}.{key}"
        if key not in ANIMATION_KEYS:
            raise RfwError(f"unknown key '{key}'" + did_you_mean(key, ANIMATION_KEYS),
                           file=source, element=where)
        if key == "fps":
            out[key] = float(check_number(v, key, lo=1e-3, hi=1e6, file=source, element=kw))
        elif key == "start":
            out[key] = float(check_number(v, key, lo=0.0, hi=1e9, file=source, element=kw))
        elif key == "loop":
            if isinstance(v, str) and v.lower() in _BOOLEANS:
                v = _BOOLEANS[v.lower()]
            if not isinstance(v, bool):
                raise RfwError(f"'loop' must be true or false, not {v!r}", file=source,
                               element=kw)
            out[key] = v
        else:
            if isinstance(v, bool) or not isinstance(v, str | int):
                raise RfwError(f"must be an animation's name or index, not {v!r}",
                               file=source, element=kw)
            out[key] = v
    return out


@dataclass(frozen=True)
class Timeline:
    """When each frame shows the animations ``clips`` (indices into the scene's)."""

    clips: tuple[int, ...]
    names: tuple[str, ...]
    duration: float  # seconds: the chosen clips' last key
    fps: float = DEFAULT_FPS
    start: float = 0.0
    loop: bool = True

    def time(self, frame: int) -> float:
        """Seconds at timed frame ``frame`` (0-based; warm-up frames are at frame 0's)."""
        t = self.start + frame / self.fps
        if self.loop and self.duration > 0.0 and t >= self.duration:
            t = math.fmod(t, self.duration)
        return t

    def scene(self, scene: Any) -> Any:
        """``scene`` with the chosen clips alone (itself when they are all of them)."""
        if len(self.clips) == len(scene.animations):
            return scene
        return replace(scene, animations=[scene.animations[k] for k in self.clips])

    def describe(self, frames: int) -> dict[str, Any]:
        """What ``timings.json`` says of the run's animation: the clips and each timed
        frame's time."""
        return {"clips": list(self.names), "fps": self.fps, "start": self.start,
                "loop": self.loop, "duration": self.duration,
                "times": [round(self.time(k), 9) for k in range(frames)]}


def timeline_for(cfg: Any, scene: Any) -> Timeline | None:
    """The timeline ``cfg`` plays ``scene``'s animations on, or None for a still scene."""
    spec = getattr(cfg, "animation", None) or {}
    animations = list(getattr(scene, "animations", None) or [])
    clips = tuple(range(len(animations)))
    if "clip" in spec:
        clips = (_clip(spec["clip"], animations, cfg, scene),)
    if not animations:
        return None
    chosen = [animations[k] for k in clips]
    return Timeline(clips, tuple(a.name for a in chosen),
                    max((a.duration for a in chosen), default=0.0),
                    spec.get("fps", DEFAULT_FPS), spec.get("start", 0.0),
                    spec.get("loop", True))


def _clip(chosen: str | int, animations: list[Any], cfg: Any, scene: Any) -> int:
    names = [a.name for a in animations]
    listed = ", ".join(f"{i}: {n!r}" for i, n in enumerate(names)) or "none"
    where = getattr(scene, "source", None) or getattr(scene, "name", "the scene")
    if isinstance(chosen, int):
        if 0 <= chosen < len(animations):
            return chosen
        raise RfwError(f"animation index {chosen} is out of range: scene {where!r} has "
                       f"{len(animations)} animation(s) ({listed})", file=cfg.source,
                       element="animation.clip")
    if chosen in names:
        return names.index(chosen)
    raise RfwError(f"scene {where!r} has no animation named {chosen!r} (animations: "
                   f"{listed})", file=cfg.source, element="animation.clip",
                   suggest=(chosen, names))


def set_frame_time(frame: Any, t: float) -> None:
    """Show the scene's animations at ``t`` seconds from ``frame``'s next frame on, on
    every backend's scene that plays them (``poses``: frames in flight keep theirs, as they
    keep their cameras)."""
    for sc in frame.scenes:
        poses = getattr(sc, "poses", None)
        if poses is not None:
            poses.time = float(t)
