"""Device memory of a compiled graph: its transient images and buffers in aliased heaps.

Images and buffers are created first, their real ``VkMemoryRequirements`` read, and only
then bound, at the offsets the frame-graph compiler planned: resources whose lifetimes do not
overlap share the bytes of one ``VkDeviceMemory``, so the aliasing is real.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

from rfw.graph.compile import CompiledGraph, MemoryOptions, ResourcePlan

from .allocation import DeviceMemory, PlanMismatchError, VkOutOfMemoryError, byte_text
from .blocks import BlockAllocator
from .buffers import BUFFER_USAGE, Buffer, buffer_create_info, device_buffer_flags, staging_buffer
from .consts import const, ffi, vk
from .device import VkDevice
from .images import Image, ImageView, image_create_info, image_usage_flags, image_view, vk_format

# BlockAllocator, Buffer, Image, ImageView, image_view and staging_buffer live in blocks,
# buffers and images; they are re-exported here while the modules that import them from here
# (the executor and its parts, accel, scene, rt, raycast) are being edited by others
__all__ = [
    "BlockAllocator", "Buffer", "Heap", "Image", "ImageView", "Placement", "TransientMemory",
    "image_view", "memory_options", "plan_heaps", "requirements", "staging_buffer",
]


class Heap(DeviceMemory):
    """One ``VkDeviceMemory`` that resources are bound into at chosen offsets (aliasing)."""

    @classmethod
    def for_resources(cls, device: VkDevice, resources: Iterable[Image | Buffer],
                      size: int | None = None, *, label: str = "") -> Heap:
        """A heap of a memory type every resource accepts (device-local preferred)."""
        resources = list(resources)
        bits = ~0
        for r in resources:
            bits &= r.type_bits
        if not bits:
            names = ", ".join(f"{r.label} ({r.type_bits:#x})" for r in resources)
            raise VkOutOfMemoryError(f"{label or 'heap'}: no memory type suits all of {names}")
        if size is None:
            size = max(r.size for r in resources)
        return cls(device, size, bits, label=label)

    def bind(self, resource: Image | Buffer, offset: int) -> None:
        resource.bind(self, offset)


# ---------------------------------------------------------------------------------------------
# transient memory of a compiled graph


@dataclass(frozen=True)
class Placement:
    """Where one transient resource went, and what the driver asked for."""

    name: str
    heap: int
    offset: int
    size: int  # bytes the driver requires
    alignment: int
    planned: int  # bytes the plan reserved


def _image_usages(r: ResourcePlan, readback: bool) -> set[str]:
    return set(r.usages) | ({"transfer_src"} if readback else set())


def _buffer_usages(r: ResourcePlan, readback: bool) -> set[str]:
    usages = set(r.usages) & set(BUFFER_USAGE) or {"storage"}
    return usages | ({"transfer_src"} if readback else set())


def _transients(plan: CompiledGraph) -> list[ResourcePlan]:
    return [r for r in plan.resources if r.transient and r.heap is not None]


def _requirements2() -> Any:
    # the package's wrapper would pass an output struct with sType 0 (a validation error)
    out = ffi.new("VkMemoryRequirements2*")
    out.sType = const("VK_STRUCTURE_TYPE_MEMORY_REQUIREMENTS_2")
    return out


def requirements(plan: CompiledGraph, device: VkDevice, *,
                 readback: bool = False) -> dict[str, tuple[int, int]]:
    """The driver's (size, alignment) for each transient resource of ``plan``, without
    creating anything (``vkGetDevice*MemoryRequirements``)."""
    out: dict[str, tuple[int, int]] = {}
    for r in _transients(plan):
        if r.kind == "image":
            usages = _image_usages(r, readback)
            info = image_create_info(vk_format(r.format, device, usages=usages), r.width,
                                     r.height, image_usage_flags(usages), r.mips, r.layers,
                                     r.samples)
            query = vk.VkDeviceImageMemoryRequirements(pCreateInfo=info, planeAspect=0)
            req = _requirements2()
            vk.vkGetDeviceImageMemoryRequirements(device.device, query, req)
        else:
            usage = device_buffer_flags(device, _buffer_usages(r, readback))
            query = vk.VkDeviceBufferMemoryRequirements(
                pCreateInfo=buffer_create_info(r.raw_bytes, usage))
            req = _requirements2()
            vk.vkGetDeviceBufferMemoryRequirements(device.device, query, req)
        mr = req.memoryRequirements
        out[r.name] = (int(mr.size), int(mr.alignment))
    return out


def memory_options(plan: CompiledGraph, device: VkDevice, *,
                   base: MemoryOptions | None = None, readback: bool = False) -> MemoryOptions:
    """Placement rules that fit this device: per kind, the largest alignment the driver asks
    for, and each resource's exact size from the driver (rows and tiles padded).
    Compile again with these to get a plan ``plan_heaps`` accepts without waste."""
    base = base or MemoryOptions()
    reqs = requirements(plan, device, readback=readback)
    chosen = {"image": base.image_alignment, "buffer": base.buffer_alignment}
    for kind in chosen:
        aligns = [reqs[r.name][1] for r in _transients(plan) if r.kind == kind]
        if aligns:
            chosen[kind] = max(aligns)
    sizes = tuple(sorted((name, size) for name, (size, _) in reqs.items()))
    return replace(base, image_alignment=chosen["image"], buffer_alignment=chosen["buffer"],
                   sizes=sizes)


class TransientMemory:
    """The transient images and buffers of a compiled graph, bound into aliased heaps.

    ``images``/``buffers`` map resource names to :class:`Image`/:class:`Buffer`; ``heaps``
    lists ``(VkDeviceMemory, size)``; ``allocated_bytes`` is the sum of what was allocated.
    """

    def __init__(self, device: VkDevice, plan: CompiledGraph, *, no_alias: bool):
        self.device, self.plan, self.no_alias = device, plan, no_alias
        self.images: dict[str, Image] = {}
        self.buffers: dict[str, Buffer] = {}
        self.memories: list[DeviceMemory] = []
        self.placements: dict[str, Placement] = {}
        device.register(self)

    @property
    def resources(self) -> dict[str, Image | Buffer]:
        return {**self.images, **self.buffers}

    @property
    def heaps(self) -> list[tuple[Any, int]]:
        return [(m.handle, m.size) for m in self.memories]

    @property
    def allocated_bytes(self) -> int:
        return sum(m.size for m in self.memories)

    def report(self) -> str:
        """One line per resource: heap, offset, driver size and alignment against the plan."""
        mode = "separate allocations" if self.no_alias else "aliased heaps"
        lines = [f"{self.plan.name}: {byte_text(self.allocated_bytes)} in {len(self.memories)} "
                 f"{mode} (plan: {byte_text(self.plan.transient_bytes)} aliased, "
                 f"{byte_text(self.plan.unaliased_bytes)} unaliased)"]
        for p in self.placements.values():
            lines.append(f"  {p.name:<28} heap {p.heap} @ {p.offset:>10}  size {p.size:>10}  "
                         f"align {p.alignment:>6}  planned {p.planned:>10}")
        return "\n".join(lines)

    def destroy(self) -> None:
        for r in [*self.images.values(), *self.buffers.values()]:
            r.destroy()
        for m in self.memories:
            m.destroy()
        self.images.clear()
        self.buffers.clear()
        self.memories.clear()
        self.device.unregister(self)


def plan_heaps(plan: CompiledGraph, device: VkDevice, *, no_alias: bool = False,
               readback: bool = False) -> TransientMemory:
    """Create the transient resources of ``plan`` and bind them where the plan says.

    Every resource's real requirements are checked against the plan: a driver that needs
    more bytes than planned, or an alignment the planned offset misses, raises
    :class:`PlanMismatchError` naming the resource and both numbers (compile with
    ``memory=memory_options(plan, device)`` to fit the device). ``no_alias=True`` gives each
    resource its own allocation of the driver's size instead, for comparison.
    ``readback=True`` adds transfer-source usage to every resource.
    """
    tm = TransientMemory(device, plan, no_alias=no_alias)
    try:
        members: dict[int, list[tuple[ResourcePlan, Image | Buffer]]] = {}
        for r in _transients(plan):
            if r.kind == "image":
                res: Image | Buffer = Image(device, r.width, r.height, r.format,
                                            _image_usages(r, readback), mips=r.mips,
                                            layers=r.layers, samples=r.samples, label=r.name)
                tm.images[r.name] = res
            else:
                res = Buffer(device, r.raw_bytes, _buffer_usages(r, readback), label=r.name)
                tm.buffers[r.name] = res
            members.setdefault(r.heap, []).append((r, res))
        if no_alias:
            for k, (r, res) in enumerate(pair for group in members.values() for pair in group):
                mem = DeviceMemory(device, res.size, res.type_bits, label=f"{r.name}:memory")
                tm.memories.append(mem)
                res.bind(mem, 0)
                tm.placements[r.name] = Placement(r.name, k, 0, res.size, res.alignment, r.bytes)
            return tm
        _check_plan(plan, device, members)
        for h, heap_bytes in enumerate(plan.heaps):
            group = members.get(h, [])
            if not group:
                continue
            heap = Heap.for_resources(device, [res for _, res in group], heap_bytes,
                                      label=f"{plan.name}:heap{h}")
            tm.memories.append(heap)
            for r, res in group:
                heap.bind(res, r.offset)
                tm.placements[r.name] = Placement(r.name, len(tm.memories) - 1, r.offset,
                                                  res.size, res.alignment, r.bytes)
    except BaseException:
        tm.destroy()
        raise
    return tm


def _check_plan(plan: CompiledGraph, device: VkDevice,
                members: Mapping[int, list[tuple[ResourcePlan, Image | Buffer]]]) -> None:
    problems = []
    granularity = device.limits["bufferImageGranularity"]
    for h, group in members.items():
        kinds = {r.kind for r, _ in group}
        for r, res in group:
            if res.size > r.bytes:
                problems.append(f"'{r.name}': the driver needs {res.size} bytes, the plan "
                                f"reserves {r.bytes}")
            if r.offset % res.alignment:
                problems.append(f"'{r.name}': planned offset {r.offset} is not a multiple of "
                                f"the driver's alignment {res.alignment}")
            if len(kinds) > 1 and (r.offset % granularity or r.bytes % granularity):
                problems.append(f"'{r.name}': heap {h} mixes images and buffers, so offsets "
                                f"and sizes must be multiples of bufferImageGranularity "
                                f"({granularity})")
    if problems:
        raise PlanMismatchError(
            f"the memory plan of '{plan.name}' does not fit {device.name}:\n  "
            + "\n  ".join(problems)
            + "\ncompile with memory=vkext.memory.memory_options(plan, device)")
