"""Animations: channels that move nodes by translation, rotation and scale, read into the
scene's clips (:mod:`rfw.scene.animation`) with their samplers' keyframes checked (indices
in range, times increasing from 0, as many values as times, no NaN, no zero quaternion).
Channels of morph target weights are left out without a word (morph targets are not read);
those of other paths (an extension's) with a warning."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..animation import INTERPOLATIONS, PATHS, Animation, Animator, Channel
from ..model import Scene
from .accessors import Accessors
from .file import GltfFile

_FLOAT = 5126


class Animations:
    """Reads the file's animations into ``scene.animations``; ``scene.nodes`` (the node
    hierarchy the scene graph kept) must be there already."""

    def __init__(self, file: GltfFile, accessors: Accessors, scene: Scene):
        self.file = file
        self.accessors = accessors
        self.scene = scene

    def read(self) -> None:
        for a, anim in enumerate(self.file.doc.animations or []):
            label = f"animations[{a}]" + (f" ({json.dumps(anim.name)})" if anim.name else "")
            with self.file.element(label):
                clip = self.animation(anim, label)
            if clip.channels:
                self.scene.animations.append(clip)
        if not self.scene.animations:  # weights alone, or nothing: a still scene
            self.scene.nodes = []
            for inst in (*self.scene.instances, *self.scene.stroke_instances):
                inst.node = None
            return
        self.check_followers()

    def animation(self, anim: Any, label: str) -> Animation:
        channels, samplers = anim.channels or [], anim.samplers or []
        clip = Animation(anim.name or label)
        read: dict[tuple[int, str], tuple[np.ndarray, np.ndarray, str]] = {}
        for c, ch in enumerate(channels):
            where = f"{label}.channels[{c}]"
            target = ch.target
            if target is None:
                self.file.fail(where, "has no target")
            if target.path == "weights" or target.node is None:
                continue  # morph weights (not read), or a target an extension names
            if target.path not in PATHS:
                self.file.warn(f"{where}: path {json.dumps(target.path)} not read (only "
                               "translation, rotation and scale are animated)")
                continue
            node = self.file.item("nodes", target.node, f"{where}.target.node")
            if node.matrix is not None:
                self.file.fail(where, f"targets nodes[{target.node}], which has a matrix "
                                      "(glTF animates only nodes given by TRS)")
            s = ch.sampler
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < len(samplers):
                self.file.fail(where, f"sampler {json.dumps(s)} is not an index into the "
                                      f"animation's {len(samplers)} samplers")
            key = (s, target.path)
            if key not in read:
                read[key] = self.sampler(samplers[s], f"{label}.samplers[{s}]", target.path)
            times, values, interpolation = read[key]
            clip.channels.append(Channel(target.node, target.path, times, values,
                                         interpolation))
            self.check_mirroring(clip.channels[-1], f"{label}.samplers[{s}]")
        return clip

    def sampler(self, sampler: Any, where: str,
                path: str) -> tuple[np.ndarray, np.ndarray, str]:
        """The checked (times, values, interpolation) of a sampler driving ``path``."""
        interpolation = "LINEAR" if sampler.interpolation is None else sampler.interpolation
        if interpolation not in INTERPOLATIONS:
            self.file.fail(where, f"interpolation {json.dumps(interpolation)} must be one of "
                                  f"{', '.join(INTERPOLATIONS)}")
        for name in ("input", "output"):
            if getattr(sampler, name) is None:
                self.file.fail(where, f"{name} is required")
        acc = self.file.item("accessors", sampler.input, f"input of {where}")
        if acc.componentType != _FLOAT:
            self.file.fail(f"accessors[{sampler.input}] (input of {where})",
                           "keyframe times must be FLOAT")
        times = self.accessors.accessor(sampler.input, f"input of {where}", ("SCALAR",))[:, 0]
        if times[0] < 0.0:
            self.file.fail(where, f"keyframe times must be >= 0, the first is {times[0]:g}")
        back = np.flatnonzero(np.diff(times) <= 0.0)
        if len(back):
            k = int(back[0]) + 1
            self.file.fail(where, f"keyframe times must increase: key {k} at {times[k]:g} s "
                                  f"follows {times[k - 1]:g} s")
        types = ("VEC4",) if path == "rotation" else ("VEC3",)
        values = self.accessors.accessor(sampler.output, f"output of {where}", types)
        cubic = interpolation == "CUBICSPLINE"
        want = len(times) * (3 if cubic else 1)
        if len(values) != want:
            per = " (an in-tangent, a value and an out-tangent per key)" if cubic else ""
            self.file.fail(where, f"output has {len(values)} values for {len(times)} keyframe "
                                  f"times: {interpolation} needs {want}{per}")
        if cubic:
            values = values.reshape(len(times), 3, -1)
        if path == "rotation":
            keys = values[:, 1] if cubic else values
            norm = np.linalg.norm(keys, axis=-1)
            zero = np.flatnonzero(norm < 1e-12)
            if len(zero):
                self.file.fail(where, f"output key {int(zero[0])} is a zero quaternion")
            if cubic:
                values = values.copy()
                values[:, 1] /= norm[:, None]
            else:
                values = values / norm[:, None]
        return times, np.ascontiguousarray(values), interpolation

    def check_mirroring(self, channel: Channel, where: str) -> None:
        """A scale whose sign changes turns the node inside out mid-clip: its winding is
        the rest pose's throughout (said once)."""
        if channel.path != "scale":
            return
        # a zero scale at rest is drawn unmirrored
        rest = np.sign(np.prod(self.scene.nodes[channel.node].scale)) or 1.0
        keys = channel.values[:, 1] if channel.interpolation == "CUBICSPLINE" \
            else channel.values
        signs = np.sign(np.prod(keys, axis=-1))
        if np.any((signs != 0) & (signs != rest)):
            self.file.warn(f"{where}: a scale changes sign (mirrors nodes[{channel.node}]): "
                           "its triangles are wound as in the rest pose throughout")

    def check_followers(self) -> None:
        """Cameras and lights stay where the rest pose puts them: said once where an
        animation moves a node that carries one."""
        moving = Animator(self.scene.nodes, self.scene.animations).moving
        doc = self.file.doc
        carried = [k for k in sorted(moving) if k < len(doc.nodes or [])
                   and (doc.nodes[k].camera is not None
                        or "KHR_lights_punctual" in (doc.nodes[k].extensions or {}))]
        if carried:
            more = f" and {len(carried) - 1} more" if len(carried) > 1 else ""
            self.file.warn(f"nodes[{carried[0]}]{more}: animated, but cameras and lights do "
                           "not follow animations (they stay in the rest pose)")
