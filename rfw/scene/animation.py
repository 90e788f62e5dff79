"""Node animations: the node hierarchy a glTF file places its instances by, the channels
that move its nodes (translation, rotation and scale, glTF 2.0 section 3.11), and their
poses at a time.

A channel holds one node's keyframes for one path: times in seconds (increasing), values
(``(K, 3)`` translations or scales, ``(K, 4)`` unit quaternions x y z w) and how to go
between them: ``STEP`` (the value of the key before), ``LINEAR`` (straight, spherical for
rotations: the shorter way round) or ``CUBICSPLINE`` (Hermite, values ``(K, 3, C)``: in-
tangent, value, out-tangent per key; rotations normalised after). Before the first key a
channel holds its first value, after the last its last.

:class:`Animator` poses the nodes that move (the targets of some channel and everything
below them) at a time: each one's local TRS, its rest values where no channel says
otherwise, under its parent's world matrix. Instances carry the node that places them
(``Instance.node``), so a backend finds an instance's transform at any time, and a parent's
animation moves its children's instances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

PATHS = ("translation", "rotation", "scale")
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


@dataclass
class Node:
    """A node of the hierarchy: its parent (-1: a root), its rest pose as TRS (``matrix``
    None) or as a matrix (glTF: such a node is never animated), and both as matrices."""

    name: str = ""
    parent: int = -1
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # unit, x y z w
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    matrix: np.ndarray | None = None  # (4, 4) float64 local matrix instead of TRS
    local: np.ndarray = field(default_factory=lambda: np.identity(4))  # rest, float64
    world: np.ndarray = field(default_factory=lambda: np.identity(4))  # rest, float64


@dataclass
class Channel:
    """One node's keyframes for one path (see the module docstring)."""

    node: int  # index into Scene.nodes
    path: str  # one of PATHS
    times: np.ndarray  # (K,) float64, increasing, >= 0
    values: np.ndarray  # (K, C) float64; CUBICSPLINE: (K, 3, C)
    interpolation: str = "LINEAR"  # one of INTERPOLATIONS

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> np.ndarray:
        """The channel's value at time ``t`` (seconds): (C,) float64."""
        times, v = self.times, self.values
        cubic = self.interpolation == "CUBICSPLINE"
        if len(times) == 1 or t <= times[0]:
            return (v[0, 1] if cubic else v[0]).copy()
        if t >= times[-1]:
            return (v[-1, 1] if cubic else v[-1]).copy()
        k = int(np.searchsorted(times, t, side="right")) - 1
        t0, t1 = float(times[k]), float(times[k + 1])
        u = (t - t0) / (t1 - t0)
        if self.interpolation == "STEP":
            return v[k].copy()
        if self.interpolation == "LINEAR":
            if self.path == "rotation":
                return slerp(v[k], v[k + 1], u)
            return (1.0 - u) * v[k] + u * v[k + 1]
        out = hermite(v[k, 1], (t1 - t0) * v[k, 2], v[k + 1, 1], (t1 - t0) * v[k + 1, 0], u)
        if self.path == "rotation":
            n = float(np.linalg.norm(out))
            return out / n if n > 0.0 else v[k, 1].copy()
        return out


@dataclass
class Animation:
    """A named set of channels played together (a glTF animation, a clip)."""

    name: str
    channels: list[Channel] = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Seconds from 0 to its last key (0 without channels)."""
        return max((c.end for c in self.channels), default=0.0)


def slerp(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    """Unit quaternions ``a`` to ``b`` along the great circle, the shorter way round (glTF:
    ``b`` is negated when the two are more than 90 degrees apart); normalised lerp where
    they nearly agree."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    dot = float(a @ b)
    if dot < 0.0:
        b, dot = -b, -dot
    dot = min(dot, 1.0)
    angle = math.acos(dot)
    if angle < 1e-6:
        out = (1.0 - u) * a + u * b
        return out / np.linalg.norm(out)
    s = math.sin(angle)
    return (math.sin((1.0 - u) * angle) / s) * a + (math.sin(u * angle) / s) * b


def hermite(p0: np.ndarray, m0: np.ndarray, p1: np.ndarray, m1: np.ndarray,
            u: float) -> np.ndarray:
    """The cubic Hermite spline from ``p0`` (tangent ``m0``) to ``p1`` (tangent ``m1``) at
    ``u`` in [0, 1]; tangents already scaled by the keys' time step (glTF appendix C)."""
    u2, u3 = u * u, u * u * u
    return ((2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0
            + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * m1)


def trs_matrix(t: Any, q: Any, s: Any) -> np.ndarray:
    """T @ R @ S as a 4x4 float64 matrix; ``q`` (x y z w) is normalised first."""
    x, y, z, w = np.asarray(q, np.float64) / np.linalg.norm(q)
    m = np.identity(4)
    m[:3, :3] = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]) * np.asarray(s, np.float64)[None, :]
    m[:3, 3] = t
    return m


class Animator:
    """Poses of the nodes ``animations`` move, at any time.

    ``moving`` holds the nodes whose world matrix depends on time: every channel's target
    and the nodes below it. ``world(t)`` gives each one's world matrix at ``t`` seconds
    (float64); the other nodes keep their rest ``Node.world``."""

    def __init__(self, nodes: list[Node], animations: list[Animation]):
        self.nodes = nodes
        self.channels = [c for a in animations for c in a.channels]
        targets = {c.node for c in self.channels}
        children: dict[int, list[int]] = {}
        for k, n in enumerate(nodes):
            if n.parent >= 0:
                children.setdefault(n.parent, []).append(k)
        # parents first: a moving node's parent is posed before it
        order, seen = [], set()
        stack = sorted((k for k in targets if not _below(nodes, k, targets)), reverse=True)
        while stack:
            k = stack.pop()
            if k in seen:
                continue
            seen.add(k)
            order.append(k)
            stack.extend(reversed(children.get(k, [])))
        self.order = order
        self.moving = frozenset(order)
        self.duration = max((c.end for c in self.channels), default=0.0)

    def world(self, t: float) -> dict[int, np.ndarray]:
        """The world matrix of every moving node at ``t`` seconds."""
        trs: dict[int, list[Any]] = {}
        for c in self.channels:  # a later channel on the same node and path wins
            n = self.nodes[c.node]
            parts = trs.setdefault(c.node, [n.translation, n.rotation, n.scale])
            parts[PATHS.index(c.path)] = c.at(t)
        out: dict[int, np.ndarray] = {}
        for k in self.order:
            n = self.nodes[k]
            local = trs_matrix(*trs[k]) if k in trs else n.local
            parent = out.get(n.parent) if n.parent >= 0 else None
            if parent is None:
                parent = self.nodes[n.parent].world if n.parent >= 0 else None
            out[k] = local if parent is None else parent @ local
        return out

    def key_times(self, limit: int = 256) -> np.ndarray:
        """Every channel's key times (at most ``limit`` of them, evenly picked), and 0."""
        times = np.unique(np.concatenate([[0.0], *(c.times for c in self.channels)]))
        if len(times) > limit:
            times = times[np.linspace(0, len(times) - 1, limit).round().astype(int)]
        return times


def _below(nodes: list[Node], k: int, targets: set[int]) -> bool:
    """Whether an ancestor of node ``k`` is among ``targets``."""
    p, steps = nodes[k].parent, 0
    while p >= 0 and steps <= len(nodes):
        if p in targets:
            return True
        p, steps = nodes[p].parent, steps + 1
    return False
