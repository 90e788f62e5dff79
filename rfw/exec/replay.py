"""Replay keys: when an executor may execute again what a pass recorded instead of calling
its ``record``.

A pass declares ``replay = "auto"`` when its commands depend on nothing but its settings,
the resources behind its slots and the scene, plus ``replay_key(ctx)`` for anything else.
The executor builds the key before ``record`` (:func:`replay_key`); a backend that keeps
recorded commands (vk: a secondary command buffer per pass, ``vkext.bundles``) executes
the ones kept for an equal key and skips ``record``. A backend that cannot (wgpu replays
render bundles of scene draws only, inside ``draw_scene``) records every frame: the key is
not asked for. No pass calls any of this.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..passes import Pass


def settings_key(params: Any) -> tuple:
    """A pass's settings as a key: their type and values."""
    return (type(params), tuple(vars(params).items())) if params is not None else ()


def replay_key(pass_: Pass, ctx: Any, slot_objects: Iterable[Any]) -> tuple | None:
    """The key under which ``pass_``'s commands recorded through ``ctx`` may be executed
    again: its type, settings, the objects behind its slots (history images swap between
    frames, so objects, not names), the scene and ``pass_.replay_key(ctx)``. None: record
    (the pass does not declare replay, or a part of the key cannot be hashed)."""
    if pass_.replay != "auto":  # False (register_pass refused anything else)
        return None
    key = ("pass", type(pass_), settings_key(pass_.params), tuple(slot_objects), ctx.scene,
           pass_.replay_key(ctx))
    try:
        hash(key)
    except TypeError:  # an unhashable part: recorded every frame
        return None
    return key
