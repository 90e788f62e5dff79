"""The backend-independent half of a pass context: what ``Pass.record`` reaches the same way
on every backend (a slot's resource, size, mips, format, buffer and samplers), and the
replay hooks of a backend that never replays. A backend's context subclasses
:class:`ContextCore` and adds how work is recorded (``dispatch``, ``draw_scene``, ...)."""

from __future__ import annotations

from typing import Any

from ..graph.formats import format_info
from ..shaders import ShaderError


class ContextCore:
    """A pass's resources reached by slot name, over the executor recording it."""

    pass_: Any
    slots: dict[str, str]  # slot -> resource

    def __init__(self, executor: Any, pass_: Any, slots: dict[str, str]):
        self.executor = executor
        self.pass_ = pass_
        self.slots = slots
        self.scene = executor.scene
        self.frame = executor.frame_index

    def resource(self, slot: str) -> str:
        try:
            return self.slots[slot]
        except KeyError:
            raise ShaderError(f"pass '{self.pass_.name}' has no slot '{slot}' "
                              f"(slots: {', '.join(self.slots)})") from None

    def has(self, slot: str) -> bool:
        return slot in self.slots

    def extent(self, slot: str) -> tuple[int, int]:
        r = self.executor.plan.resource(self.resource(slot))
        return r.width, r.height

    def mips(self, slot: str) -> int:
        return self.executor.plan.resource(self.resource(slot)).mips

    def format(self, slot: str) -> str:
        """The format's WebGPU name where it has one (what the wgpu backend allocates)."""
        name = self.executor.plan.resource(self.resource(slot)).format
        return format_info(name).wgpu or name

    def buffer(self, slot: str) -> Any:
        """The buffer behind a buffer slot."""
        return self.executor.buffer(self.resource(slot))

    def sampler(self, *, filter: str = "linear", address: str = "clamp-to-edge",
                compare: str | None = None) -> Any:
        """A sampler the executor makes once per (filter, address, compare) and keeps
        (``filter``: linear | nearest for magnification, minification and mips;
        ``address``: clamp-to-edge | repeat | mirror-repeat on every axis; ``compare``: a
        depth comparison)."""
        return self.executor.sampler(filter=filter, address=address, compare=compare)

    def shader_name(self, shader: str | None) -> str:
        """``shader``, else the pass's own; a ShaderError if the pass declares none."""
        name = shader or self.pass_.shader
        if not name:
            raise ShaderError(f"pass '{self.pass_.name}' records work but declares no shader")
        return name

    # replay (rfw.exec.replay): a backend that keeps recorded commands overrides these
    def can_replay(self) -> bool:
        """Whether the executor may build the pass's replay key: never by default."""
        return False

    def slot_objects(self) -> list[Any]:
        """The objects behind the pass's slots, for its replay key."""
        return []

    def replayed(self, key: tuple) -> bool:
        """Execute again what was recorded for ``key``: nothing kept by default."""
        return False

    def finish(self) -> None:
        """After ``record``: nothing to close by default."""
