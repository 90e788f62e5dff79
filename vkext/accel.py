"""Acceleration structures of a scene: one BLAS per mesh, one TLAS over the instances.

A BLAS holds a mesh's triangles in the mesh's own space and is built once, however many
instances place it: the TLAS refers to it by device address with each instance's transform
(the talk's sofas and chairs). Triangles come from device buffers through their buffer
device addresses: all meshes' positions in one buffer, all indices in another, kept after the
build and readable by shaders (``positions``/``indices``, offsets in ``mesh_ranges``).

Building follows the talk's order, with what it leaves out made explicit:

1. size queries (``vkGetAccelerationStructureBuildSizesKHR``) for every BLAS and the TLAS;
2. BLAS builds in one command, each with its own range of one scratch buffer whose ranges
   are aligned to ``minAccelerationStructureScratchOffsetAlignment``; when the scratch of all
   of them would exceed ``scratch_budget`` they are built in batches reusing the scratch, with
   a barrier between batches;
3. with ``compact``: the compacted sizes are queried, the BLAS copied into structures of that
   size (``VK_COPY_ACCELERATION_STRUCTURE_MODE_COMPACT_KHR``) and the originals freed;
4. a barrier (acceleration-structure write -> acceleration-structure read, both in the build
   stage): the TLAS build reads the BLAS, so it must wait for them;
5. the TLAS build, then a barrier that makes it visible to any later reader (ray queries in
   any stage, ray-tracing pipelines).

Instances carry ``instanceCustomIndex`` = the scene's instance index (instances of empty
meshes are left out of the TLAS, so ``gl_InstanceID`` is not that index; the custom index
is), a mask bit per alpha mode (:data:`ALPHA_MASK`: shadow rays may skip blended surfaces),
an SBT record offset per alpha mode (``hit_groups``: alpha-tested geometry can get a hit group
with an any-hit shader) and ``TRIANGLE_FACING_CULL_DISABLE``: a ray query answers for both
faces, as a rasteriser with culling off would. Geometry of OPAQUE materials is flagged opaque
(any-hit shaders never run for it); MASK and BLEND geometry is not, with
``NO_DUPLICATE_ANY_HIT_INVOCATION`` so an alpha test runs once per triangle.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.scene.model import Scene
from rfw.units import MiB, align_up

from .commands import TimestampPool, barrier, one_time, upload_buffer
from .consts import const, ffi, new, vk
from .device import VkDevice
from .memory import BlockAllocator, Buffer

# TLAS instance mask bits by material alpha mode (cull masks of rays test against them)
MASK_OPAQUE, MASK_ALPHA_TEST, MASK_BLEND = 0x1, 0x2, 0x4
ALPHA_MASK = {"OPAQUE": MASK_OPAQUE, "MASK": MASK_ALPHA_TEST, "BLEND": MASK_BLEND}
PREFER = {"fast_trace": "VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_TRACE_BIT_KHR",
          "fast_build": "VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_BUILD_BIT_KHR",
          None: None}

# VkAccelerationStructureInstanceKHR: a row-major 3x4 transform, then two words of 24 + 8
# bitfields (custom index | mask << 24, SBT record offset | flags << 24), then the BLAS address
INSTANCE_DTYPE = np.dtype([("transform", "<f4", (3, 4)), ("index_mask", "<u4"),
                           ("sbt_flags", "<u4"), ("reference", "<u8")])
assert INSTANCE_DTYPE.itemsize == 64

# build-stage accesses (the spec's rules for vkCmdBuildAccelerationStructuresKHR): structures
# and scratch are acceleration-structure accesses, geometry and instance inputs shader reads
_BUILD = frozenset({"ACCELERATION_STRUCTURE_BUILD_KHR"})
_AS_WRITE = State(None, _BUILD, frozenset({"ACCELERATION_STRUCTURE_WRITE_KHR"}))
_AS_READ = State(None, _BUILD, frozenset({"ACCELERATION_STRUCTURE_READ_KHR"}))
_AS_RW = State(None, _BUILD, frozenset({"ACCELERATION_STRUCTURE_READ_KHR",
                                        "ACCELERATION_STRUCTURE_WRITE_KHR"}))
_INPUT_READ = State(None, _BUILD, frozenset({"SHADER_READ"}))
# any later use: ray queries in any stage, ray-tracing pipelines, copies
_ANY_READ = State(None, frozenset({"ALL_COMMANDS"}),
                  frozenset({"ACCELERATION_STRUCTURE_READ_KHR"}))


class AccelerationStructure:
    """One ``VkAccelerationStructureKHR`` at offset 0 of a buffer it owns.

    ``allocator`` sub-allocates the buffer from a :class:`BlockAllocator`; without one it gets
    memory of its own (for structures that live only until compaction).
    """

    def __init__(self, device: VkDevice, level: str, size: int, *,
                 allocator: BlockAllocator | None = None, label: str = ""):
        if level not in ("bottom", "top"):
            raise ValueError(f"level is 'bottom' or 'top', not {level!r}")
        self.device, self.level, self.size = device, level, int(size)
        self.label = label or f"{level}-level"
        self.handle = None
        usage = ("acceleration_structure",)
        if allocator is not None:
            self.buffer = allocator.create_buffer(self.size, usage, label=f"{self.label}:buffer")
        else:
            self.buffer = Buffer(device, self.size, usage, label=f"{self.label}:buffer")
            try:
                self.buffer.allocate()
            except BaseException:
                self.buffer.destroy()
                raise
        info = new("VkAccelerationStructureCreateInfoKHR", buffer=self.buffer.handle, offset=0,
                   size=self.size,
                   type=const(f"VK_ACCELERATION_STRUCTURE_TYPE_{level.upper()}_LEVEL_KHR"))
        try:
            self.handle = device.fn.vkCreateAccelerationStructureKHR(device.device, info, ffi.NULL)
        except BaseException:
            self.buffer.destroy()
            raise
        device.register(self)
        device.set_name(self.handle, "ACCELERATION_STRUCTURE_KHR", self.label)
        addr = new("VkAccelerationStructureDeviceAddressInfoKHR",
                   accelerationStructure=self.handle)
        self.address = int(device.fn.vkGetAccelerationStructureDeviceAddressKHR(device.device,
                                                                                addr))

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            self.device.fn.vkDestroyAccelerationStructureKHR(self.device.device, self.handle,
                                                             ffi.NULL)
        self.handle = None
        self.buffer.destroy()
        self.device.unregister(self)

    def __repr__(self) -> str:
        return f"<AccelerationStructure '{self.label}' {self.level} {self.size} B>"


def build_sizes(device: VkDevice, info: Any, counts: Sequence[int]) -> tuple[int, int, int]:
    """(structure, build scratch, update scratch) bytes for a build described by ``info``
    (a ``VkAccelerationStructureBuildGeometryInfoKHR*``) with ``counts`` primitives per
    geometry."""
    out = new("VkAccelerationStructureBuildSizesInfoKHR")
    prims = ffi.new("uint32_t[]", [int(c) for c in counts] or [0])
    device.fn.vkGetAccelerationStructureBuildSizesKHR(
        device.device, const("VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR"), info, prims, out)
    return (int(out.accelerationStructureSize), int(out.buildScratchSize),
            int(out.updateScratchSize))


class _Timer:
    """Times between marks in ms: GPU timestamps written after everything recorded before
    each mark, where the device has them, else the host's clock around submit-and-wait
    (which then includes the submit)."""

    def __init__(self, device: VkDevice, marks: int, label: str):
        self.pool = TimestampPool(device, marks, label=f"{label}:timestamps") \
            if "timestamp" in device.caps else None
        self.kind = "gpu" if self.pool is not None else "cpu"
        self._host: list[float] = []

    def start(self, cmd: Any) -> None:
        """Before the first mark of a command buffer."""
        if self.pool is not None:
            self.pool.reset(cmd)
        self._host = [time.perf_counter()]

    def mark(self, cmd: Any, index: int) -> None:
        if self.pool is not None:
            self.pool.write(cmd, "ALL_COMMANDS", index)

    def span(self, a: int, b: int) -> float:
        """ms from mark ``a`` to mark ``b`` of the last command buffer, once its submit was
        waited for; on the host clock, the whole submit (each phase of it reports that)."""
        if self.pool is None:
            return (time.perf_counter() - self._host[0]) * 1e3
        t = self.pool.results(a, b - a + 1)
        return (t[-1] - t[0]) / 1e6

    def destroy(self) -> None:
        if self.pool is not None:
            self.pool.destroy()
            self.pool = None


class SceneAccel:
    """BLAS per mesh and a TLAS over the instances of an :class:`rfw.scene.model.Scene`.

    Parameters
    ----------
    prefer
        ``"fast_trace"`` (default: a better tree, a slower build), ``"fast_build"`` or None.
    allow_update
        Build the TLAS so :meth:`update` can refit it for moved instances instead of
        rebuilding (an update keeps the tree's topology, so traversal slows as instances
        drift far from where they were built).
    compact
        Compact every BLAS after its build (query the compacted size, copy, free the
        original); ``stats()`` reports the bytes before and after.
    hit_groups
        Shader-binding-table record offset per alpha mode (default 0 for all), for pipelines
        with several hit groups (an any-hit alpha test for MASK); ``hit_records`` is then the
        number of hit records a table must hold.
    scratch_budget
        The most scratch memory BLAS builds use at once; more BLAS are built in batches.

    ``blas[m]`` is mesh ``m``'s structure (None for a mesh without triangles), shared by
    every instance of the mesh; ``tlas`` the top level; ``transforms`` the instances' current
    (N, 4, 4) world matrices.
    """

    def __init__(self, device: VkDevice, scene: Scene, *, prefer: str | None = "fast_trace",
                 allow_update: bool = False, compact: bool = False,
                 hit_groups: Mapping[str, int] | None = None, scratch_budget: int = 64 * MiB,
                 label: str = "accel"):
        device.require("VK_KHR_acceleration_structure", "buffer_device_address")
        if prefer not in PREFER:
            raise ValueError(f"prefer is one of {', '.join(map(repr, PREFER))}, not {prefer!r}")
        unknown = sorted(set(hit_groups or {}) - set(ALPHA_MASK))
        if unknown:
            raise ValueError(f"hit_groups: unknown alpha mode(s) {', '.join(unknown)} "
                             f"(known: {', '.join(ALPHA_MASK)})")
        self.device, self.scene, self.label = device, scene, label
        self.prefer, self.allow_update, self.compact = prefer, allow_update, compact
        self.hit_groups = {m: int((hit_groups or {}).get(m, 0)) for m in ALPHA_MASK}
        self.hit_records = max(self.hit_groups.values()) + 1
        self.scratch_budget = int(scratch_budget)
        self.blas: list[AccelerationStructure | None] = []
        self.tlas: AccelerationStructure | None = None
        self.transforms = np.array([np.asarray(i.transform, np.float32)
                                    for i in scene.instances], np.float32).reshape(-1, 4, 4)
        self._owned: list[Any] = []  # buffers and timers destroyed with the structures
        self._times: dict[str, float] = {}
        self._update_scratch: Buffer | None = None
        self._frame_scratch: Buffer | None = None  # record_tlas's, made on first use
        self.frame_builds = {"build": 0, "update": 0}
        self.allocator = BlockAllocator(device, block_size=32 * MiB, label=f"{label}:blocks")
        device.register(self)
        try:
            self._timer = self._own(_Timer(device, 3, label))
            self._upload_geometry()
            self._build()
        except BaseException:
            self.destroy()
            raise

    def _own(self, obj: Any) -> Any:
        self._owned.append(obj)
        return obj

    # geometry ------------------------------------------------------------------------------

    def _upload_geometry(self) -> None:
        """All positions in one buffer, all indices in another: the BLAS builds read them
        through device addresses, and shaders may read them later (storage usage)."""
        pos_parts, idx_parts, uv_parts = [], [], []
        self.mesh_ranges: list[tuple[int, int, int, int]] = []  # (first vertex, V, first index, 3T)
        v0 = i0 = 0
        for k, m in enumerate(self.scene.meshes):
            pos = np.ascontiguousarray(m.positions, np.float32).reshape(-1, 3)
            idx = np.ascontiguousarray(m.indices).reshape(-1)
            if len(idx) % 3:
                raise ValueError(f"mesh {k} ('{m.name}'): {len(idx)} indices is not a "
                                 "multiple of 3")
            if len(idx) and (int(idx.min()) < 0 or int(idx.max()) >= len(pos)):
                raise ValueError(f"mesh {k} ('{m.name}'): indices outside its {len(pos)} "
                                 "vertices (a build would read past the vertex buffer)")
            self.mesh_ranges.append((v0, len(pos), i0, len(idx)))
            pos_parts.append(pos)
            idx_parts.append(idx.astype(np.uint32))
            uv = np.ascontiguousarray(m.uvs, np.float32).reshape(-1, 2)
            uv_parts.append(uv if len(uv) == len(pos) else np.zeros((len(pos), 2), np.float32))
            v0 += len(pos)
            i0 += len(idx)
        usage = ("acceleration_structure_input", "storage", "transfer_dst")
        positions = np.concatenate(pos_parts) if pos_parts else np.zeros((0, 3), np.float32)
        indices = np.concatenate(idx_parts) if idx_parts else np.zeros(0, np.uint32)
        self.positions = self.allocator.create_buffer(max(16, positions.nbytes), usage,
                                                      label=f"{self.label}.positions")
        self.indices = self.allocator.create_buffer(max(16, indices.nbytes), usage,
                                                    label=f"{self.label}.indices")
        # texture coordinates, for shaders that shade what they hit (never built from)
        uvs = np.concatenate(uv_parts) if uv_parts else np.zeros((0, 2), np.float32)
        self.uvs = self.allocator.create_buffer(max(16, uvs.nbytes), ("storage", "transfer_dst"),
                                                label=f"{self.label}.uvs")
        for buf, data in ((self.positions, positions), (self.indices, indices),
                          (self.uvs, uvs)):
            if data.nbytes:
                upload_buffer(self.device, buf, data, _INPUT_READ)

    def _geometry(self, m: int) -> Any:
        mesh = self.scene.meshes[m]
        v0, nv, i0, _ = self.mesh_ranges[m]
        g = new("VkAccelerationStructureGeometryKHR")
        g.geometryType = const("VK_GEOMETRY_TYPE_TRIANGLES_KHR")
        opaque = self.scene.materials[mesh.material].alpha_mode == "OPAQUE"
        g.flags = const("VK_GEOMETRY_OPAQUE_BIT_KHR") if opaque \
            else const("VK_GEOMETRY_NO_DUPLICATE_ANY_HIT_INVOCATION_BIT_KHR")
        t = g.geometry.triangles
        t.sType = const("VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_TRIANGLES_DATA_KHR")
        t.vertexFormat = const("VK_FORMAT_R32G32B32_SFLOAT")
        t.vertexData.deviceAddress = self.positions.address + 12 * v0
        t.vertexStride = 12
        t.maxVertex = max(0, nv - 1)  # the highest index any triangle uses may be
        t.indexType = const("VK_INDEX_TYPE_UINT32")
        t.indexData.deviceAddress = self.indices.address + 4 * i0
        t.transformData.deviceAddress = 0  # instances place the mesh
        return g

    def _build_info(self, level: str, geometry: Any, flags: int, *, update: bool = False) -> Any:
        info = new("VkAccelerationStructureBuildGeometryInfoKHR")
        info.type = const(f"VK_ACCELERATION_STRUCTURE_TYPE_{level.upper()}_LEVEL_KHR")
        info.flags = flags
        info.mode = const("VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR" if update
                          else "VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR")
        info.geometryCount, info.pGeometries = 1, geometry
        return info

    def _flags(self, *extra: str) -> int:
        out = const(PREFER[self.prefer]) if self.prefer else 0
        for name in extra:
            out |= const(name)
        return out

    # instances -----------------------------------------------------------------------------

    def _instance_records(self) -> np.ndarray:
        scene = self.scene
        rows = []
        self.tlas_instances: list[int] = []  # scene instance index of each TLAS record
        cull_off = const("VK_GEOMETRY_INSTANCE_TRIANGLE_FACING_CULL_DISABLE_BIT_KHR")
        # no TRIANGLE_FLIP_FACING for mirrored instances: ray tracing decides facing in
        # object space, where an instance transform cannot change the winding, so a mirrored
        # instance faces out where its mesh does (and facing culling is off anyway)
        for k, inst in enumerate(scene.instances):
            blas = self.blas[inst.mesh]
            if blas is None:
                continue
            alpha = scene.materials[scene.meshes[inst.mesh].material].alpha_mode
            rows.append((np.zeros((3, 4), np.float32), k | ALPHA_MASK.get(alpha, 1) << 24,
                         self.hit_groups.get(alpha, 0) | cull_off << 24, blas.address))
            self.tlas_instances.append(k)
        records = np.array(rows, INSTANCE_DTYPE)
        if len(records):
            records["transform"] = self.transforms[self.tlas_instances, :3, :]
        return records

    # building ------------------------------------------------------------------------------

    def _build(self) -> None:
        dev = self.device
        n_inst = len(self.scene.instances)
        if n_inst >= 1 << 24:
            raise ValueError(f"{n_inst} instances: instanceCustomIndex holds 24 bits")
        align = int(dev.extension_properties["VK_KHR_acceleration_structure"]
                    ["minAccelerationStructureScratchOffsetAlignment"])
        compact_flag = ("VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_COMPACTION_BIT_KHR",) \
            if self.compact else ()
        blas_flags = self._flags(*compact_flag)
        keep: list[Any] = []  # cffi structs that must live until the commands are recorded

        # 1. sizes of every BLAS
        jobs = []  # (mesh, geometry, info, range, size, scratch)
        for m in range(len(self.scene.meshes)):
            tris = self.mesh_ranges[m][3] // 3
            if tris == 0:
                continue
            g = self._geometry(m)
            info = self._build_info("bottom", g, blas_flags)
            size, scratch, _ = build_sizes(dev, info, [tris])
            rng = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*")
            rng.primitiveCount = tris
            jobs.append((m, g, info, rng, size, scratch))
            keep += [g, info, rng]
        self.triangles = sum(j[3].primitiveCount for j in jobs)
        self.blas = [None] * len(self.scene.meshes)
        for m, _g, _info, _rng, size, _s in jobs:
            # compacted copies live in the block allocator; the originals die after the copy
            self.blas[m] = AccelerationStructure(
                dev, "bottom", size, allocator=None if self.compact else self.allocator,
                label=f"{self.label}.blas{m}:{self.scene.meshes[m].name}")
        self.blas_bytes_built = sum(j[4] for j in jobs)

        # batches of BLAS whose scratch fits the budget (one BLAS larger than it goes alone)
        batches: list[list[tuple]] = []
        used = self.scratch_budget + 1
        for job in jobs:
            need = align_up(job[5], align)
            if used + need > self.scratch_budget:
                batches.append([])
                used = 0
            batches[-1].append(job)
            used += need
        blas_scratch = max((sum(align_up(j[5], align) for j in b) for b in batches), default=0)
        self.blas_batches = len(batches)

        # the TLAS: instance records in a host-visible buffer (written again by update())
        self._tlas_flags = self._flags(*(("VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_UPDATE_BIT_KHR",)
                                         if self.allow_update else ()))
        self.instance_buffer = self.allocator.create_buffer(
            max(64, 64 * n_inst), ("acceleration_structure_input",), host_visible=True,
            label=f"{self.label}.instances")
        self._tlas_geometry = new("VkAccelerationStructureGeometryKHR")
        g = self._tlas_geometry
        g.geometryType = const("VK_GEOMETRY_TYPE_INSTANCES_KHR")
        g.geometry.instances.sType = const(
            "VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_INSTANCES_DATA_KHR")
        g.geometry.instances.arrayOfPointers = 0
        g.geometry.instances.data.deviceAddress = self.instance_buffer.address
        # records need the BLAS addresses, which compaction changes: count them now, write
        # them once the BLAS are final
        n_records = sum(1 for i in self.scene.instances if self.blas[i.mesh] is not None)
        tinfo = self._build_info("top", g, self._tlas_flags)
        tsize, tscratch, tupdate = build_sizes(dev, tinfo, [n_records])
        self._tlas_scratch_bytes = max(tscratch, tupdate if self.allow_update else 0)
        self.tlas = AccelerationStructure(dev, "top", tsize, allocator=self.allocator,
                                          label=f"{self.label}.tlas")
        if self.allow_update:
            self._update_scratch = self._scratch(tupdate, align, "update")

        scratch = self._scratch(max(blas_scratch, tscratch), align, "build")
        try:
            base = align_up(scratch.address, align)
            tinfo.scratchData.deviceAddress = base  # the BLAS are done with it by then
            tinfo.dstAccelerationStructure = self.tlas.handle

            # 2. BLAS builds, batch by batch; without compaction the TLAS follows in the same
            # command buffer, behind the barrier that makes it wait for them
            with one_time(dev, label=f"{self.label}: build") as cmd:
                self._timer.start(cmd)
                self._timer.mark(cmd, 0)
                for b, batch in enumerate(batches):
                    if b:  # the next batch reuses the scratch the previous one wrote
                        barrier(cmd, memory_barriers=[(_AS_RW, _AS_RW)])
                    infos = ffi.new("VkAccelerationStructureBuildGeometryInfoKHR[]", len(batch))
                    ranges = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[]", len(batch))
                    offset = 0
                    for i, (m, _g, info, rng, _size, s) in enumerate(batch):
                        info.dstAccelerationStructure = self.blas[m].handle
                        info.scratchData.deviceAddress = base + offset
                        infos[i] = info[0]
                        ranges[i] = rng
                        offset += align_up(s, align)
                    keep += [infos, ranges]
                    dev.fn.vkCmdBuildAccelerationStructuresKHR(cmd, len(batch), infos, ranges)
                self._timer.mark(cmd, 1)
                if self.compact and jobs:
                    query = self._compaction_query(cmd, [self.blas[j[0]] for j in jobs])
                else:
                    self._record_tlas(cmd, tinfo, keep)
            if self.compact and jobs:
                self._times["blas"] = self._timer.span(0, 1)
                # 3. compaction: sizes back to the host, copies into structures of that size
                self._compact(jobs, query)
                with one_time(dev, label=f"{self.label}: tlas") as cmd:
                    self._timer.start(cmd)
                    self._timer.mark(cmd, 1)
                    self._record_tlas(cmd, tinfo, keep)
                self._times["tlas"] = self._timer.span(1, 2)
            else:
                self._times["blas"] = self._timer.span(0, 1)
                self._times["tlas"] = self._timer.span(1, 2)
            self.scratch_bytes = scratch.bytes
        finally:
            scratch.destroy()
            del keep

    def _record_tlas(self, cmd: Any, tinfo: Any, keep: list[Any]) -> None:
        """4. and 5.: the TLAS build waits for the BLAS builds (or compacting copies) and
        reuses their scratch; then anyone may read the TLAS. Timer mark 2 after the build."""
        records = self._instance_records()
        if len(records):
            self.instance_buffer.write(records)  # host writes: the submit makes them visible
        rng = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*")
        rng.primitiveCount = len(records)
        ranges = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[1]", [rng])
        keep += [rng, ranges]
        barrier(cmd, memory_barriers=[(_AS_WRITE, _AS_RW)])
        self.device.fn.vkCmdBuildAccelerationStructuresKHR(cmd, 1, tinfo, ranges)
        self._timer.mark(cmd, 2)
        barrier(cmd, memory_barriers=[(_AS_WRITE, _ANY_READ)])

    def _scratch(self, size: int, align: int, what: str) -> Buffer:
        # a buffer of its own, with room to align its address up
        buf = Buffer(self.device, max(16, size + align), ("storage",),
                     label=f"{self.label}:{what} scratch")
        try:
            buf.allocate()
        except BaseException:
            buf.destroy()
            raise
        return buf

    def _compaction_query(self, cmd: Any, structures: list[AccelerationStructure]) -> Any:
        info = vk.VkQueryPoolCreateInfo(
            queryType=const("VK_QUERY_TYPE_ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR"),
            queryCount=len(structures))
        pool = vk.vkCreateQueryPool(self.device.device, info, None)
        self._query_pool = pool
        vk.vkCmdResetQueryPool(cmd, pool, 0, len(structures))
        # the property is read from the finished structures
        barrier(cmd, memory_barriers=[(_AS_WRITE, _AS_READ)])
        handles = ffi.new("VkAccelerationStructureKHR[]", [s.handle for s in structures])
        self.device.fn.vkCmdWriteAccelerationStructuresPropertiesKHR(
            cmd, len(structures), handles,
            const("VK_QUERY_TYPE_ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR"), pool, 0)
        return pool

    def _compact(self, jobs: list[tuple], pool: Any) -> None:
        dev = self.device
        n = len(jobs)
        sizes = ffi.new("uint64_t[]", n)
        try:
            vk.vkGetQueryPoolResults(dev.device, pool, 0, n, 8 * n, sizes, 8,
                                     vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
        finally:
            vk.vkDestroyQueryPool(dev.device, pool, None)
            self._query_pool = None
        originals = [self.blas[j[0]] for j in jobs]
        compacted = []
        try:
            for old, size in zip(originals, sizes, strict=True):
                compacted.append(AccelerationStructure(dev, "bottom", int(size),
                                                       allocator=self.allocator,
                                                       label=old.label))
            with one_time(dev, label=f"{self.label}: compact") as cmd:
                self._timer.start(cmd)
                self._timer.mark(cmd, 0)
                for old, new_ in zip(originals, compacted, strict=True):
                    info = new("VkCopyAccelerationStructureInfoKHR", src=old.handle,
                               dst=new_.handle,
                               mode=const("VK_COPY_ACCELERATION_STRUCTURE_MODE_COMPACT_KHR"))
                    dev.fn.vkCmdCopyAccelerationStructureKHR(cmd, info)
                self._timer.mark(cmd, 1)
            self._times["compact"] = self._timer.span(0, 1)
        except BaseException:
            for c in compacted:
                c.destroy()
            raise
        for (m, *_), old, c in zip(jobs, originals, compacted, strict=True):
            old.destroy()
            self.blas[m] = c

    # per frame ------------------------------------------------------------------------------

    def record_tlas(self, cmd: Any, *, update: bool = False) -> str:
        """Record a TLAS build from the current ``transforms`` into ``cmd`` (a frame's
        command buffer), or with ``update`` (needs ``allow_update``) a refit of it in place.
        No barrier is recorded: a frame graph plans the TLAS's (build stage write, then
        reads by tracing passes). The scratch buffer is this object's own; the instance
        records are written from the host now, so the previous user of the TLAS must be
        done (frames are waited for). Returns ``"build"`` or ``"update"``."""
        if update and not self.allow_update:
            raise ValueError(f"'{self.label}' was built without allow_update=True: it can "
                             "only be rebuilt")
        dev = self.device
        align = int(dev.extension_properties["VK_KHR_acceleration_structure"]
                    ["minAccelerationStructureScratchOffsetAlignment"])
        if self._frame_scratch is None:
            self._frame_scratch = self._scratch(self._tlas_scratch_bytes, align, "frame")
        records = self._instance_records()
        if len(records):
            self.instance_buffer.write(records)
        rng = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*")
        rng.primitiveCount = len(records)
        ranges = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[1]", [rng])
        info = self._build_info("top", self._tlas_geometry, self._tlas_flags, update=update)
        if update:
            info.srcAccelerationStructure = self.tlas.handle
        info.dstAccelerationStructure = self.tlas.handle
        info.scratchData.deviceAddress = align_up(self._frame_scratch.address, align)
        # the scratch is reused frame after frame: the last build's use of it comes first
        barrier(cmd, memory_barriers=[(_AS_RW, _AS_RW)])
        dev.fn.vkCmdBuildAccelerationStructuresKHR(cmd, 1, info, ranges)
        mode = "update" if update else "build"
        self.frame_builds[mode] += 1
        return mode

    # refit ---------------------------------------------------------------------------------

    def update(self, transforms: Mapping[int, Any] | Any) -> None:
        """Refit the TLAS for moved instances: ``transforms`` is (N, 4, 4) for every scene
        instance, or ``{instance index: 4x4}`` for some. Needs ``allow_update=True``.

        The instance records are rewritten in place and the TLAS updated from itself
        (``VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR``); the call waits for the GPU,
        so no trace still reads the records it overwrites."""
        if not self.allow_update:
            raise ValueError(f"'{self.label}' was built without allow_update=True: rebuild it "
                             "to move instances")
        n = len(self.scene.instances)
        new_t = self.transforms.copy()
        if isinstance(transforms, Mapping):
            for k, t in transforms.items():
                if not 0 <= int(k) < n:
                    raise ValueError(f"update: instance {k} is not among the scene's {n}")
                new_t[int(k)] = _matrix(t, f"transforms[{k}]")
        else:
            arr = np.asarray(transforms, np.float32)
            if arr.shape != (n, 4, 4):
                raise ValueError(f"update: transforms has shape {arr.shape}, expected "
                                 f"({n}, 4, 4) or a dict of 4x4 matrices")
            new_t = arr.copy()
        if not np.isfinite(new_t).all():
            raise ValueError("update: transforms must be finite")
        self.transforms = new_t
        records = self._instance_records()
        dev = self.device
        if len(records):
            self.instance_buffer.write(records)
        rng = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*")
        rng.primitiveCount = len(records)
        ranges = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[1]", [rng])
        info = self._build_info("top", self._tlas_geometry, self._tlas_flags, update=True)
        info.srcAccelerationStructure = info.dstAccelerationStructure = self.tlas.handle
        align = int(dev.extension_properties["VK_KHR_acceleration_structure"]
                    ["minAccelerationStructureScratchOffsetAlignment"])
        info.scratchData.deviceAddress = align_up(self._update_scratch.address, align)
        with one_time(dev, label=f"{self.label}: update") as cmd:
            # earlier readers of the TLAS (any stage) finish before it is rewritten
            barrier(cmd, memory_barriers=[(_ANY_READ, _AS_RW)])
            self._timer.start(cmd)
            self._timer.mark(cmd, 0)
            dev.fn.vkCmdBuildAccelerationStructuresKHR(cmd, 1, info, ranges)
            self._timer.mark(cmd, 1)
            barrier(cmd, memory_barriers=[(_AS_WRITE, _ANY_READ)])
        self._times["update"] = self._timer.span(0, 1)

    # reporting and teardown ----------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        """What was built and what it cost: structure counts and bytes (BLAS bytes as built
        and now, after any compaction), build times in ms per phase and how they were
        measured (``"gpu"`` timestamps or the ``"cpu"`` clock)."""
        built = [b for b in self.blas if b is not None]
        return {
            "blas": len(built),
            "instances": len(getattr(self, "tlas_instances", ())),
            "triangles": int(getattr(self, "triangles", 0)),
            "instance_triangles": sum(self.mesh_ranges[i.mesh][3] // 3
                                      for i in self.scene.instances),
            "blas_bytes_built": int(getattr(self, "blas_bytes_built", 0)),
            "blas_bytes": sum(b.size for b in built),
            "tlas_bytes": self.tlas.size if self.tlas is not None else 0,
            "scratch_bytes": int(getattr(self, "scratch_bytes", 0)),
            "blas_batches": int(getattr(self, "blas_batches", 0)),
            "build_ms": dict(self._times),
            "timer": self._timer.kind if getattr(self, "_timer", None) else "cpu",
            "prefer": self.prefer, "allow_update": self.allow_update, "compact": self.compact,
            "frame_builds": dict(self.frame_builds),
        }

    def destroy(self) -> None:
        """Destroy the structures, buffers and pools (safe to call twice)."""
        if getattr(self, "_query_pool", None) is not None and self.device.alive:
            vk.vkDestroyQueryPool(self.device.device, self._query_pool, None)
            self._query_pool = None
        if self.tlas is not None:
            self.tlas.destroy()
            self.tlas = None
        for b in self.blas:
            if b is not None:
                b.destroy()
        self.blas = []
        for scratch in (self._update_scratch, self._frame_scratch):
            if scratch is not None:
                scratch.destroy()
        self._update_scratch = self._frame_scratch = None
        for obj in reversed(self._owned):
            obj.destroy()
        self._owned.clear()
        if self.allocator is not None:
            self.allocator.destroy()
            self.allocator = None
        self.device.unregister(self)

    def __enter__(self) -> SceneAccel:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.destroy()


def _matrix(t: Any, what: str) -> np.ndarray:
    m = np.asarray(t, np.float32)
    if m.shape != (4, 4):
        raise ValueError(f"update: {what} has shape {m.shape}, expected (4, 4)")
    return m
