"""Work recorded once and replayed: a frame records no Python per draw.

Two caches of the executor, both kept per *call site*: (pass, n-th call of its record).

* :class:`SetCache`: a pass's own descriptor sets (set 0 and the like), written once under a
  key of their descriptors (the objects and handles bound) and their uniform values' sizes.
  Uniform values (``Settings``, bytes) live in the set's own host-visible buffer, rewritten
  each frame with one write, so a changed setting changes no descriptor.
* :class:`BundleCache`: ``ctx.draw_scene``'s draws (viewport, pipeline, the cached sets, push
  constants, then every instance) in a secondary command buffer that each frame executes
  inside the pass's rendering, under a key of everything it baked in: the pipeline (shader
  variant, targets' formats, samples and fixed state), the viewport, the camera and alpha
  modes, the push constants, the sets and the scene. Another setting, shader, scene or size
  makes another key, and a new bundle is recorded.

Each call site keeps :data:`KEEP` entries, least recently used out first: two let a pass that
reads a history image (swapped each frame) alternate between its two without re-recording.
Frames are waited for before the next one records (the executor's contract), so a host write
never races the GPU, and a bundle is never pending when it is executed or freed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rfw.spirv import DescriptorInfo
from rfw.units import align_up

from .blocks import BlockAllocator
from .buffers import Buffer
from .consts import const, ffi, new, vk
from .device import VkDevice
from .objects import DescriptorPool, update_descriptors

KEEP = 2

Slot = tuple[str, int]  # (pass, n-th call of its record)


class _Kept:
    """Entries per call site, most recently used last; an evicted entry is destroyed."""

    def __init__(self, free: Callable[[Any], None]):
        self.slots: dict[Slot, list[Any]] = {}
        self.free = free

    def find(self, slot: Slot, key: tuple) -> Any:
        kept = self.slots.get(slot)
        if not kept:
            return None
        for k, entry in enumerate(kept):
            if entry.key == key:
                if k != len(kept) - 1:
                    kept.append(kept.pop(k))
                return entry
        return None

    def make_room(self, slot: Slot) -> None:
        kept = self.slots.setdefault(slot, [])
        while len(kept) >= KEEP:
            self.free(kept.pop(0))

    def add(self, slot: Slot, entry: Any) -> None:
        self.slots.setdefault(slot, []).append(entry)

    def clear(self) -> None:
        for kept in self.slots.values():
            for entry in kept:
                self.free(entry)
        self.slots.clear()


def uniform_bytes(d: DescriptorInfo, value: Any) -> bytes | None:
    """A uniform value given as data (``Settings``, bytes, an array), zero-padded to whole
    16 bytes; None for anything else (a buffer, an image, ...)."""
    if d.kind != "uniform_buffer":
        return None
    if hasattr(value, "pack"):  # rfw.passes.Settings
        raw = _packed(value)
    elif isinstance(value, np.ndarray):
        raw = value.tobytes()
    elif isinstance(value, bytes | bytearray):
        raw = bytes(value)
    else:
        return None
    return raw + b"\0" * (max(16, align_up(len(raw), 16)) - len(raw))


_PACKED: dict[tuple, bytes] = {}


def _packed(settings: Any) -> bytes:
    """``Settings.pack()``, memoized by type and values: packing reads the type hints, tens
    of microseconds a call, and the values rarely change between frames."""
    try:
        key = (type(settings), tuple(vars(settings).items()))
        raw = _PACKED.get(key)
    except TypeError:  # an unhashable value: pack every time
        return settings.pack()
    if raw is None:
        if len(_PACKED) > 1024:
            _PACKED.clear()
        raw = _PACKED[key] = settings.pack()
    return raw


@dataclass(eq=False)
class CachedSet:
    """One written descriptor set: its pool, its uniform buffer and where each uniform value
    goes in it; ``pinned`` keeps the bound objects alive, so their ids stay theirs."""

    key: tuple
    pool: DescriptorPool
    handle: Any  # VkDescriptorSet[1]
    uniforms: Buffer | None = None
    offsets: list[int] = field(default_factory=list)
    pinned: list[Any] = field(default_factory=list)
    mapped: Any = None  # the uniform buffer's bytes, mapped once
    data: list[bytes] = field(default_factory=list)  # the uniform values it holds
    alive: bool = True

    def write(self, data: Sequence[bytes]) -> None:
        """This frame's uniform values, in binding order (written where they changed)."""
        if not data or data == self.data:
            return
        if self.mapped is None:
            self.mapped = self.uniforms.map()  # type: ignore[union-attr]
        for off, raw in zip(self.offsets, data, strict=True):
            self.mapped[off:off + len(raw)] = np.frombuffer(raw, np.uint8)
        self.data = list(data)

    def destroy(self) -> None:
        for obj in (self.pool, self.uniforms):
            if obj is not None:
                obj.destroy()
        self.uniforms = self.mapped = None
        self.alive = False


class SetCache:
    """A pass's own descriptor sets per call site (see the module docstring).
    ``written`` counts sets written (what tests read)."""

    def __init__(self, device: VkDevice, allocator: BlockAllocator):
        self.device, self.allocator = device, allocator
        self.alignment = max(16, int(device.limits["minUniformBufferOffsetAlignment"]))
        self.kept = _Kept(lambda s: s.destroy())
        # per call site, the last sets found by their bound values: [(values, set)]
        self.quick: dict[Slot, list[tuple[tuple, CachedSet]]] = {}
        self.written = 0

    def get(self, slot: Slot, layout: Any, wanted: Sequence[DescriptorInfo],
            values: dict[str, Any], payload: Callable[[DescriptorInfo, Any], Any],
            owners: Callable[[Any], list[Any]]) -> CachedSet:
        """The set of ``layout`` binding ``wanted`` (sorted by binding) to ``values``;
        ``payload(d, value)`` gives a descriptor's write payload (as
        ``vkext.objects.update_descriptors`` takes it), ``owners(value)`` the objects that
        keep its handles alive: their identities go into the key (and the set keeps them),
        so a handle the driver reuses after its object was destroyed never matches an old
        set. This frame's uniform values are written before it returns.

        A call site that binds the very objects it bound last time (equal values, kept alive
        by the memo) finds its set without working out payloads: ``quick`` remembers the
        last :data:`KEEP` sets per call site by their bound values."""
        data: list[bytes] = []
        seen: list[Any] = [layout]
        for d in wanted:
            value = values[d.name]
            raw = uniform_bytes(d, value)
            if raw is not None:
                data.append(raw)
                seen.append(len(raw))
            else:
                seen.append(tuple(value) if isinstance(value, list) else value)
        quick = tuple(seen)
        entry = self._quick(slot, quick)
        if entry is None:
            entry = self._find(slot, layout, wanted, values, data, payload, owners)
            memo = self.quick.setdefault(slot, [])
            kept = [m for m in memo if m[1] is not entry][-(KEEP - 1):]
            memo[:] = [*kept, (quick, entry)]
        entry.write(data)
        return entry

    def _quick(self, slot: Slot, quick: tuple) -> CachedSet | None:
        """The set this call site wrote for the same bound values, while it is kept."""
        try:
            for seen, entry in self.quick.get(slot, ()):
                if seen == quick and self.kept.find(slot, entry.key) is entry:
                    return entry
        except (TypeError, ValueError):  # a value == cannot answer (an array): in full
            return None
        return None

    def _find(self, slot: Slot, layout: Any, wanted: Sequence[DescriptorInfo],
              values: dict[str, Any], data: list[bytes],
              payload: Callable[[DescriptorInfo, Any], Any],
              owners: Callable[[Any], list[Any]]) -> CachedSet:
        """The kept set of these descriptors (keyed by their payloads), or a new one."""
        fixed: list[Any] = []
        pins: list[Any] = []
        for d in wanted:
            value = values[d.name]
            raw = uniform_bytes(d, value)
            if raw is not None:
                fixed.append((d.binding, len(raw)))
                continue
            p = payload(d, value)
            objs = owners(value)
            pins += objs
            fixed.append((d.binding, tuple(p) if isinstance(p, list) else p,
                          tuple(id(o) for o in objs)))
        key = (layout, tuple(fixed))
        entry = self.kept.find(slot, key)
        if entry is None:
            self.kept.make_room(slot)
            entry = self._write(key, slot, layout, wanted, values, data, payload)
            entry.pinned = pins
            self.kept.add(slot, entry)
        return entry

    def _write(self, key: tuple, slot: Slot, layout: Any, wanted: Sequence[DescriptorInfo],
               values: dict[str, Any], data: list[bytes],
               payload: Callable[[DescriptorInfo, Any], Any]) -> CachedSet:
        sizes: dict[str, int] = {}
        for d in wanted:
            sizes[d.kind] = sizes.get(d.kind, 0) + max(1, d.count)
        pool = DescriptorPool(self.device, 1, sizes, label=f"{slot[0]}:set{slot[1]}")
        entry = CachedSet(key, pool, pool.allocate([layout]))
        try:
            if data:
                offset = 0
                for raw in data:
                    entry.offsets.append(offset)
                    offset = align_up(offset + len(raw), self.alignment)
                entry.uniforms = self.allocator.create_buffer(
                    offset, ("uniform",), host_visible=True, label=f"{slot[0]}:uniforms")
            writes, k = [], 0
            for d in wanted:
                value = values[d.name]
                raw = uniform_bytes(d, value)
                if raw is not None:
                    p: Any = (entry.uniforms.handle, entry.offsets[k], len(raw))
                    k += 1
                else:
                    p = payload(d, value)
                writes.append((entry.handle[0], d.binding, d.kind, p))
            update_descriptors(self.device, writes)
        except BaseException:
            entry.destroy()
            raise
        self.written += 1
        return entry

    def destroy(self) -> None:
        self.kept.clear()
        self.quick.clear()


@dataclass(eq=False)
class Bundle:
    """One recorded draw call: its secondary command buffer, the draws in it and the cached
    sets it binds (kept alive with it, so their ids stay in its key)."""

    key: tuple
    cmd: Any  # VkCommandBuffer (secondary)
    draws: int = 0
    sets: list[CachedSet] = field(default_factory=list)
    # a pass's bundle: the uniform values its sets held when it was recorded (rewritten
    # when it is replayed: another bundle of the call site may have changed them)
    writes: list[tuple[CachedSet, list[bytes]]] = field(default_factory=list)

    def usable(self) -> bool:
        """Whether every set it binds is still kept (an evicted one was destroyed)."""
        return all(s.alive for s in self.sets)

    def __post_init__(self) -> None:
        self.handles = ffi.new("VkCommandBuffer[1]", [self.cmd])  # vkCmdExecuteCommands'


class BundleCache:
    """The executor's recorded draw calls per call site (see the module docstring).
    ``recorded`` counts bundles recorded (what tests read)."""

    def __init__(self, device: VkDevice, *, label: str = "rfw:bundles"):
        self.device, self.label = device, label
        info = vk.VkCommandPoolCreateInfo(flags=vk.VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT,
                                          queueFamilyIndex=device.queue_family)
        self.handle = vk.vkCreateCommandPool(device.device, info, None)
        device.register(self)
        device.set_name(self.handle, "COMMAND_POOL", label)
        self.kept = _Kept(self._free)
        self.recorded = 0

    def find(self, slot: Slot, key: tuple) -> Bundle | None:
        return self.kept.find(slot, key)

    def record(self, slot: Slot, key: tuple, *, colors: Sequence[int], depth: int,
               stencil: int, samples: int, fill: Callable[[Any], int]) -> Bundle:
        """Record a new bundle for ``slot``: a secondary command buffer that continues a
        rendering of ``colors``/``depth``/``stencil`` formats (0: none) at ``samples``;
        ``fill(cmd)`` records its commands and returns the draws."""
        bundle = self._allocate(slot, key)
        try:
            self._begin(bundle.cmd, colors, depth, stencil, samples)
            bundle.draws = fill(bundle.cmd)
            vk.vkEndCommandBuffer(bundle.cmd)
        except BaseException:
            self._free(bundle)
            raise
        self.kept.add(slot, bundle)
        self.recorded += 1
        return bundle

    def begin(self, slot: Slot, key: tuple) -> Bundle:
        """Begin a bundle of a whole pass's commands outside any rendering (dispatches,
        barriers, renderings begun inside it); :meth:`end` keeps it for ``slot``."""
        bundle = self._allocate(slot, key)
        try:
            inherit = new("VkCommandBufferInheritanceInfo")
            # simultaneous use, as for a rendering's bundles (frames in flight)
            vk.vkBeginCommandBuffer(bundle.cmd, new(
                "VkCommandBufferBeginInfo", pInheritanceInfo=inherit,
                flags=const("VK_COMMAND_BUFFER_USAGE_SIMULTANEOUS_USE_BIT")))
        except BaseException:
            self._free(bundle)
            raise
        return bundle

    def end(self, slot: Slot, bundle: Bundle) -> None:
        vk.vkEndCommandBuffer(bundle.cmd)
        self.kept.add(slot, bundle)
        self.recorded += 1

    def _allocate(self, slot: Slot, key: tuple) -> Bundle:
        # a secondary command buffer for a new bundle of ``slot`` (room made first)
        self.kept.make_room(slot)
        alloc = vk.VkCommandBufferAllocateInfo(
            commandPool=self.handle, level=vk.VK_COMMAND_BUFFER_LEVEL_SECONDARY,
            commandBufferCount=1)
        return Bundle(key, vk.vkAllocateCommandBuffers(self.device.device, alloc)[0])

    def _begin(self, cmd: Any, colors: Sequence[int], depth: int, stencil: int,
               samples: int) -> None:
        formats = ffi.new("VkFormat[]", max(1, len(colors)))
        for i, f in enumerate(colors):
            formats[i] = f
        rendering = new("VkCommandBufferInheritanceRenderingInfo",
                        colorAttachmentCount=len(colors), pColorAttachmentFormats=formats,
                        depthAttachmentFormat=depth, stencilAttachmentFormat=stencil,
                        rasterizationSamples=samples)
        inherit = new("VkCommandBufferInheritanceInfo", pNext=rendering)
        # simultaneous use: frames in flight (vkext.executor) replay a bundle in the next
        # frame's primary while the last one's is still pending
        info = new("VkCommandBufferBeginInfo",
                   flags=const("VK_COMMAND_BUFFER_USAGE_RENDER_PASS_CONTINUE_BIT")
                   | const("VK_COMMAND_BUFFER_USAGE_SIMULTANEOUS_USE_BIT"),
                   pInheritanceInfo=inherit)
        vk.vkBeginCommandBuffer(cmd, info)

    def _free(self, bundle: Bundle) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkFreeCommandBuffers(self.device.device, self.handle, 1, [bundle.cmd])
        bundle.sets = []

    def destroy(self) -> None:
        self.kept.clear()
        if self.handle is not None and self.device.alive:
            vk.vkDestroyCommandPool(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)
