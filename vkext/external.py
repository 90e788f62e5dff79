"""Vulkan memory that CUDA maps: device-local buffers exported as opaque fds
(``VK_KHR_external_memory_fd``) and imported with the CUDA driver (``rfw.interop``), so rays,
hits and images reach PyTorch and CuPy without a host copy.

- :func:`cuda_link`: whether a device shares memory with CUDA (the extension, a CUDA driver,
  and a CUDA device whose UUID is Vulkan's ``deviceUUID``), or why not;
- :class:`ExportedBuffer`: a dedicated device-local allocation, exported; where there is a link
  it is imported into CUDA (``cuda_ptr``), else the fd is kept (lavapipe's is a memfd the
  tests map, the only way to read it there);
- :func:`ownership`: the queue-family transfers of external memory (acquire before Vulkan
  uses it, release after), so its contents are defined on both sides;
- :class:`ImageExport`: an image copied on the GPU into an exported buffer by one recorded
  command buffer, handed out as a :class:`rfw.interop.DeviceArray`; :func:`read_output` does it
  for an executor's resource.

Ordering is by fence: the host waits for Vulkan's work before CUDA reads, and
``cuCtxSynchronize`` before Vulkan reads what CUDA wrote.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import time
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from rfw import env
from rfw.errors import RfwError
from rfw.interop import DeviceArray, SharedMemory, cuda

from .allocation import DEVICE_LOCAL, byte_text, find_memory_type
from .buffers import device_buffer_flags
from .commands import (
    FENCE_TIMEOUT_NS,
    TRANSFER_SRC,
    CommandPool,
    as_state,
    copy_image_out,
    readback_bytes,
    texel_layout,
)
from .consts import const, ffi, lib, vk
from .device import VkDevice, physical_uuid

EXTENSION = "VK_KHR_external_memory_fd"
QUEUE_FAMILY_EXTERNAL = 0xFFFFFFFE  # VK_QUEUE_FAMILY_EXTERNAL (~1U)
NOT_READY = 1  # VK_NOT_READY
# how long Submitter.wait polls the fence before it blocks (a cast of 921,600 rays is ~0.4 ms
# on an H200; the blocking wait is the fallback for anything longer)
SPIN_NS = 2_000_000


@dataclass(frozen=True)
class CudaLink:
    """A Vulkan device and the CUDA device that is the same GPU."""

    ordinal: int  # the CUDA device ordinal
    uuid: bytes


_links: weakref.WeakKeyDictionary[VkDevice, CudaLink | str] = weakref.WeakKeyDictionary()


def device_uuid(device: VkDevice) -> bytes:
    """Vulkan's ``deviceUUID`` of the device (``VkPhysicalDeviceIDProperties``), read from
    the driver (under ``RFW_FAKE_GPUS``, not the synthetic one ``device.uuid`` holds)."""
    return bytes.fromhex(physical_uuid(device.physical_device))


def cuda_link(device: VkDevice) -> CudaLink | str:
    """The device's :class:`CudaLink`, or one line saying why it has none (found once per
    device)."""
    got = _links.get(device)
    if got is None:
        got = _links[device] = _find_link(device)
    return got


def _find_link(device: VkDevice) -> CudaLink | str:
    if not env.get("RFW_CUDA"):
        return "sharing memory with CUDA is off (RFW_CUDA=0)"
    if EXTENSION not in device.extensions:
        return f"{device.name} has no {EXTENSION}"
    try:
        driver = cuda()
        uuid = device_uuid(device)
        ordinal = driver.ordinal_of_uuid(uuid)
    except RfwError as e:
        return e.message
    if ordinal is None:
        return (f"no CUDA device is {device.name} (deviceUUID {uuid.hex()}; CUDA has "
                f"{driver.devices()} device(s))")
    return CudaLink(ordinal, uuid)


class ExportedBuffer(SharedMemory):
    """A device-local buffer in a dedicated allocation exported as an opaque fd; with
    ``link`` imported into CUDA (``cuda_ptr``). Arrays of it (:meth:`array`) keep it alive:
    the owner calls :meth:`release` when done and the memory goes with the last array (or
    with the device)."""

    def __init__(self, device: VkDevice, size: int, usage: tuple[str, ...], *,
                 link: CudaLink | None, label: str = "exported"):
        super().__init__()
        if EXTENSION not in device.extensions:
            raise RfwError(f"{device.name} has no {EXTENSION}: its memory cannot be exported")
        self.device, self.label, self.link = device, label, link
        self.bytes = int(size)
        self.handle = self.memory = None
        self.fd: int | None = None
        self.cuda_ptr = self._external = None
        self._map: mmap.mmap | None = None
        handle_type = const("VK_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD_BIT")
        dev = device.device
        try:
            ext = ffi.new("VkExternalMemoryBufferCreateInfo*")
            ext.sType = const("VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO")
            ext.handleTypes = handle_type
            info = ffi.new("VkBufferCreateInfo*")
            info.sType = const("VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO")
            info.pNext, info.size = ext, self.bytes
            info.usage = device_buffer_flags(device, usage)
            info.sharingMode = vk.VK_SHARING_MODE_EXCLUSIVE
            self.handle = vk.vkCreateBuffer(dev, info, None)
            device.register(self)
            device.set_name(self.handle, "BUFFER", label)
            req = vk.vkGetBufferMemoryRequirements(dev, self.handle)
            self.size = int(req.size)
            type_index = find_memory_type(device, int(req.memoryTypeBits), [DEVICE_LOCAL])
            self.memory = self._allocate(type_index, handle_type)
            vk.vkBindBufferMemory(dev, self.handle, self.memory, 0)
            get = ffi.new("VkMemoryGetFdInfoKHR*")
            get.sType = const("VK_STRUCTURE_TYPE_MEMORY_GET_FD_INFO_KHR")
            get.memory, get.handleType = self.memory, handle_type
            self.fd = int(device.fn.vkGetMemoryFdKHR(dev, get))
            if link is not None:
                fd, self.fd = self.fd, None  # CUDA owns it once imported
                try:
                    self._external, self.cuda_ptr = cuda().import_memory(fd, self.size,
                                                                         link.ordinal)
                except BaseException:
                    os.close(fd)
                    raise
        except BaseException:
            self.free()
            raise

    def _allocate(self, type_index: int, handle_type: int) -> Any:
        dedicated = ffi.new("VkMemoryDedicatedAllocateInfo*")
        dedicated.sType = const("VK_STRUCTURE_TYPE_MEMORY_DEDICATED_ALLOCATE_INFO")
        dedicated.buffer = self.handle
        export = ffi.new("VkExportMemoryAllocateInfo*")
        export.sType = const("VK_STRUCTURE_TYPE_EXPORT_MEMORY_ALLOCATE_INFO")
        export.handleTypes, export.pNext = handle_type, dedicated
        info = ffi.new("VkMemoryAllocateInfo*")
        info.sType = const("VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO")
        info.allocationSize, info.memoryTypeIndex, info.pNext = self.size, type_index, export
        if "buffer_device_address" in self.device.caps:
            flags = ffi.new("VkMemoryAllocateFlagsInfo*")
            flags.sType = const("VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO")
            flags.flags = const("VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT")
            dedicated.pNext = flags
        try:
            return vk.vkAllocateMemory(self.device.device, info, None)
        except (vk.VkErrorOutOfDeviceMemory, vk.VkErrorOutOfHostMemory) as e:
            raise RfwError(f"{self.label}: the driver refused {byte_text(self.size)} of "
                           f"exportable memory ({type(e).__name__})") from None

    def binding(self, offset: int = 0, size: int | None = None) -> tuple[Any, int, int]:
        """(handle, offset, range) as ``BindingSet.write`` takes a buffer."""
        return (self.handle, offset, self.bytes - offset if size is None else size)

    def array(self, offset: int, shape: tuple[int, ...], dtype: Any) -> DeviceArray:
        """A zero-copy view at ``offset`` bytes (needs the CUDA link)."""
        if self.cuda_ptr is None:
            raise RfwError(f"{self.label} is not mapped into CUDA")
        dtype = np.dtype(dtype)
        if offset + int(np.prod(shape)) * dtype.itemsize > self.bytes:
            raise ValueError(f"{self.label}: a view of {shape} {dtype} at {offset} overruns it")
        return DeviceArray(ptr=self.cuda_ptr + offset, shape=shape, dtype=dtype,
                           ordinal=self.link.ordinal, owner=self)

    def host_view(self) -> np.ndarray:
        """The exported bytes through a mapping of the fd (no link: e.g. lavapipe's memfd),
        for tests of the export itself; raises where the fd cannot be mapped."""
        if self.fd is None:
            raise RfwError(f"{self.label}: its fd went to CUDA")
        if self._map is None:
            self._map = mmap.mmap(self.fd, os.fstat(self.fd).st_size)
        head = np.frombuffer(self._map, np.uint64, count=2)
        # llvmpipe's memfd starts with a header: (file size, offset of the data)
        offset = int(head[1]) if int(head[0]) == len(self._map) else 0
        return np.frombuffer(self._map, np.uint8, count=self.bytes, offset=offset)

    def destroy(self) -> None:
        """With the device (it registers): the Vulkan side goes now (the device is going);
        the CUDA import of the memory stays while arrays of it live (the payload is the
        import's too) and goes with the last of them. Freeing it here, as this once did,
        left a tensor of a finished render pointing at unmapped memory (torch's
        ``cudaErrorInvalidValue`` on the first read after ``render`` returned)."""
        self._free_vulkan()
        self.release()

    def free(self) -> None:
        if self.cuda_ptr is not None and self.link is not None:
            ptr, ext, self.cuda_ptr = self.cuda_ptr, self._external, None
            with contextlib.suppress(RfwError):  # at exit CUDA may be gone before us
                cuda().free_import(ext, ptr, self.link.ordinal)
        self._free_vulkan()

    def _free_vulkan(self) -> None:
        if self._map is not None:
            with contextlib.suppress(BufferError):  # a numpy view of it lives: it stays
                self._map.close()
            self._map = None
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        alive = self.device.alive
        if self.handle is not None and alive:
            vk.vkDestroyBuffer(self.device.device, self.handle, None)
        if self.memory is not None and alive:
            vk.vkFreeMemory(self.device.device, self.memory, None)
        self.handle = self.memory = None
        self.device.unregister(self)

    def __repr__(self) -> str:
        where = f"cuda:{self.link.ordinal}" if self.cuda_ptr is not None else "fd"
        return f"<ExportedBuffer '{self.label}' {self.bytes} B -> {where}>"


def ownership(device: VkDevice, cmd: Any, buffers: list[ExportedBuffer], *,
              acquire: bool) -> None:
    """Record the queue-family transfer of ``buffers`` from (``acquire``) or to the external
    world, ordered against every command before or after."""
    if not buffers:
        return
    ours = device.queue_family
    all_commands = const("VK_PIPELINE_STAGE_2_ALL_COMMANDS_BIT")
    memory = const("VK_ACCESS_2_MEMORY_READ_BIT") | const("VK_ACCESS_2_MEMORY_WRITE_BIT")
    bars = ffi.new("VkBufferMemoryBarrier2[]", len(buffers))
    for b, buf in zip(bars, buffers, strict=True):
        b.sType = const("VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER_2")
        if acquire:
            b.srcQueueFamilyIndex, b.dstQueueFamilyIndex = QUEUE_FAMILY_EXTERNAL, ours
            b.dstStageMask, b.dstAccessMask = all_commands, memory
        else:
            b.srcQueueFamilyIndex, b.dstQueueFamilyIndex = ours, QUEUE_FAMILY_EXTERNAL
            b.srcStageMask, b.srcAccessMask = all_commands, memory
        b.buffer, b.offset, b.size = buf.handle, 0, const("VK_WHOLE_SIZE")
    dep = ffi.new("VkDependencyInfo*")
    dep.sType = const("VK_STRUCTURE_TYPE_DEPENDENCY_INFO")
    dep.bufferMemoryBarrierCount, dep.pBufferMemoryBarriers = len(buffers), bars
    lib.vkCmdPipelineBarrier2(cmd, dep)


class Submitter:
    """One command buffer and fence, submitted and waited for again and again."""

    def __init__(self, device: VkDevice, *, label: str):
        self.device, self.label = device, label
        self.pool = CommandPool(device, transient=False, label=f"{label}:commands")
        self.cmd = self.pool.allocate(1)[0]
        self.fence = vk.vkCreateFence(device.device, vk.VkFenceCreateInfo(), None)
        self.key: Any = None
        self._info = ffi.new("VkSubmitInfo*")
        self._info.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO")
        self._cmds = ffi.new("VkCommandBuffer[1]", [self.cmd])
        self._info.commandBufferCount, self._info.pCommandBuffers = 1, self._cmds
        self._fences = ffi.new("VkFence[1]", [self.fence])
        # a CPU device (lavapipe) works on the host's cores: spinning there takes one from it
        self.spin_ns = 0 if getattr(device, "device_type", None) == "cpu" else SPIN_NS
        device.register(self)

    def begin(self) -> Any:
        vk.vkResetCommandBuffer(self.cmd, 0)
        vk.vkBeginCommandBuffer(self.cmd, vk.VkCommandBufferBeginInfo())
        return self.cmd

    def end(self, key: Any) -> None:
        vk.vkEndCommandBuffer(self.cmd)
        self.key = key

    def run(self) -> None:
        """Submit and wait: three calls straight into the loader (``lib``: no wrapper
        objects), the wait spinning on ``vkGetFenceStatus`` for up to :data:`SPIN_NS` (a
        blocking wait's wake-up can cost more than a short cast; not on a CPU device), then
        blocking."""
        dev = self.device.device
        result = lib.vkResetFences(dev, 1, self._fences)
        if result == 0:
            result = lib.vkQueueSubmit(self.device.queue, 1, self._info, self.fence)
        if result != 0:
            raise RfwError(f"{self.label}: vkResetFences/vkQueueSubmit failed with VkResult "
                           f"{result}")
        self.wait()

    def wait(self) -> None:
        """Until the fence of the last :meth:`run` is signalled."""
        dev, fence = self.device.device, self.fence
        status = lib.vkGetFenceStatus(dev, fence)
        if status == NOT_READY and self.spin_ns:
            clock = time.perf_counter_ns
            until = clock() + self.spin_ns
            while status == NOT_READY and clock() < until:
                status = lib.vkGetFenceStatus(dev, fence)
        if status == NOT_READY:
            status = lib.vkWaitForFences(dev, 1, self._fences, 1, FENCE_TIMEOUT_NS)
        if status != 0:
            raise RfwError(f"{self.label}: waiting for its fence failed with VkResult "
                           f"{status}")

    def destroy(self) -> None:
        if self.fence is not None and self.device.alive:
            vk.vkDestroyFence(self.device.device, self.fence, None)
        self.fence = None
        if self.pool is not None:
            self.pool.destroy()
            self.pool = None
        self.device.unregister(self)


class ImageExport:
    """An image copied on the GPU into an :class:`ExportedBuffer` (its bytes as
    ``copy_image_to_buffer`` packs them) by a command buffer recorded once; :meth:`read`
    submits it, waits, and returns the (h, w, channels) :class:`DeviceArray` of the buffer
    (the same memory every read: the next read overwrites it). ``layout_now`` is the state
    the image is in when the copy runs, ``layout_after`` the one it is left in."""

    def __init__(self, device: VkDevice, image: Any, *, layout_now: Any, layout_after: Any,
                 link: CudaLink | None, label: str = ""):
        self.device, self.image = device, image
        self.label = label or f"{image.label}:export"
        size = readback_bytes(image)
        self.shape, self.dtype = texel_layout(image)
        self.buffer = ExportedBuffer(device, size, ("transfer_dst",), link=link,
                                     label=self.label)
        try:
            self.submitter = Submitter(device, label=self.label)
            now = as_state(layout_now, source=True)
            after = as_state(layout_after if layout_after is not None else TRANSFER_SRC,
                             source=False)
            cmd = self.submitter.begin()
            ownership(device, cmd, [self.buffer], acquire=True)
            copy_image_out(cmd, image, self.buffer, now, after)  # it reads the handle alone
            ownership(device, cmd, [self.buffer], acquire=False)
            self.submitter.end(image.handle)
        except BaseException:
            self.buffer.release()
            raise
        # without a link (tests on lavapipe) only run() and buffer.host_view() serve
        self.view = self.buffer.array(0, self.shape, self.dtype) if link is not None else None

    def run(self) -> None:
        """The copy, submitted and waited for."""
        self.submitter.run()

    def read(self) -> DeviceArray:
        self.run()
        return self.view

    def destroy(self) -> None:
        self.submitter.destroy()
        self.buffer.release()
        self.view = None  # the buffer goes with the last array of it


_exports: weakref.WeakKeyDictionary[Any, dict[str, ImageExport]] = weakref.WeakKeyDictionary()


class FrameExports:
    """Graph outputs copied into exported memory by the frame's own command buffer: at its
    end (after the last pass, before ``vkEndCommandBuffer``) each image goes to a buffer of
    the frame's slot (one per slot: a frame in flight never overwrites another's), so once
    the frame's fence is waited for (the wait the frame does anyway) the output is a
    :class:`DeviceArray` of memory CUDA already maps: no submit, no wait of its own.

    ``link`` None (no CUDA: lavapipe) still records the copies (``record_without_cuda``:
    tests read them through the buffers' fds). The copies are timed apart (two timestamps
    per slot): :meth:`read_timer` reads the last frame's into ``gpu_ms``."""

    def __init__(self, executor: Any, names: tuple[str, ...], link: CudaLink | None):
        self.executor, self.device, self.names, self.link = executor, executor.device, names, link
        self.buffers: dict[tuple[int, str], ExportedBuffer] = {}
        self.timers: dict[int, Any] = {}
        self.views: dict[tuple[int, str], DeviceArray] = {}
        # what read_device's wrap made of a view, by (slot, name, wrap): made once
        self.wrapped: dict[tuple[int, str, Any], Any] = {}
        self.last: Any = None  # the slot of the last frame submitted with the copies
        self.gpu_ms: list[float] = []
        self._timed: set[int] = set()

    def buffer(self, slot: Any, name: str) -> ExportedBuffer:
        key = (id(slot), name)
        buf = self.buffers.get(key)
        if buf is None:
            image = self.executor.image(name)
            buf = self.buffers[key] = ExportedBuffer(
                self.device, readback_bytes(image), ("transfer_dst",), link=self.link,
                label=f"{name}:frame export")
        return buf

    def record(self, cmd: Any, slot: Any) -> None:
        """The copies, at the end of the frame's command buffer ``cmd``."""
        from .commands import TimestampPool

        ex = self.executor
        bufs = [self.buffer(slot, n) for n in self.names]
        timer = self.timers.get(id(slot))
        if timer is None and "timestamp" in self.device.caps:
            timer = self.timers[id(slot)] = TimestampPool(self.device, 2,
                                                          label="rfw:frame export timestamps")
        if timer is not None:
            timer.reset(cmd)
            timer.write(cmd, "ALL_COMMANDS", 0)
        ownership(self.device, cmd, bufs, acquire=True)
        for name, buf in zip(self.names, bufs, strict=True):
            image, state = ex.image(name), ex._final.get(name)
            now = as_state(state or "UNDEFINED", source=True)
            after = as_state(state, source=False) if state is not None else None
            copy_image_out(cmd, image, buf, now, after)
        ownership(self.device, cmd, bufs, acquire=False)
        if timer is not None:
            timer.write(cmd, "ALL_COMMANDS", 1)

    def submitted(self, slot: Any) -> None:
        self.last = slot
        self._timed.discard(id(slot))

    def array(self, name: str, wrap: Any = None) -> Any:
        """The last finished frame's ``name`` (the caller waited for its fence); with
        ``wrap``, what ``wrap`` made of that view the first time (kept until
        :meth:`destroy`)."""
        slot = self.last
        if slot is None:
            raise RfwError(f"no frame has copied '{name}' into exported memory yet")
        key = (id(slot), name)
        view = self.views.get(key)
        if view is None:
            shape, dtype = texel_layout(self.executor.image(name))
            view = self.views[key] = self.buffers[key].array(0, shape, dtype)
        if wrap is None:
            return view
        made = self.wrapped.get((*key, wrap))
        if made is None:
            made = self.wrapped[(*key, wrap)] = wrap(view)
        return made

    def read_timer(self) -> float | None:
        """The last finished frame's copy time in GPU ms (appended to ``gpu_ms`` once per
        frame; None without timestamps). Apart from :meth:`array`, which reads nothing."""
        slot = self.last
        timer = self.timers.get(id(slot)) if slot is not None else None
        if timer is None:
            return None
        if id(slot) not in self._timed:
            self._timed.add(id(slot))
            a, b = timer.results(0, 2)
            self.gpu_ms.append(max(0, int(b) - int(a)) / 1e6)
        return self.gpu_ms[-1]

    def destroy(self) -> None:
        for timer in self.timers.values():
            timer.destroy()
        for buf in self.buffers.values():
            buf.release()  # arrays handed out keep theirs
        # the wrapped tensors hold their views, which hold the memory: let go of both
        self.timers, self.buffers, self.views, self.wrapped, self.last = {}, {}, {}, {}, None


def export_outputs(executor: Any, names: Any, *, record_without_cuda: bool = False) -> str | None:
    """From the next frame on, copy the images ``names`` of a vk executor into exported
    memory inside each frame's submission (:class:`FrameExports`); ``()`` stops it. Returns
    None, or why the frames record no copy (no CUDA link: :func:`read_output` then reads
    through the host)."""
    names = tuple(dict.fromkeys(names))
    for n in names:
        if n in executor.buffers or n not in executor.images:
            raise RfwError(f"device outputs are images of the plan: '{n}' is not one")
    if names and getattr(executor, "queues", None) is not None:
        raise RfwError("device outputs need the frame on one queue (async compute is on)")
    link = cuda_link(executor.device)
    link = link if isinstance(link, CudaLink) else None
    executor.drain()
    old = getattr(executor, "frame_exports", None)
    if old is not None:
        old.destroy()
    executor.frame_exports = None
    for slot in executor.in_flight.slots:  # command buffers held for replay lack (or have) them
        slot.holds = None
    if not names:
        return None
    if link is None and not record_without_cuda:
        return cuda_link(executor.device)
    if EXTENSION not in executor.device.extensions:
        return f"{executor.device.name} has no {EXTENSION}"
    executor.frame_exports = FrameExports(executor, names, link)
    return None


def read_output(executor: Any, resource: str, *, wrap: Any = None) -> Any:
    """A vk executor's image ``resource`` (a graph output) as a :class:`DeviceArray`, after
    every frame in flight: zero-copy where the device shares memory with CUDA. Where the
    frames copy it themselves (:func:`export_outputs`), the last frame's copy (nothing
    submitted here); else the export recorded once per executor and image, so a read is one
    submit and a wait. Without a link a host copy (``zero_copy`` False). ``wrap``: the
    array as it makes it (:func:`rfw.interop.read_device`): once per buffer where the
    frames copy, else on each read."""
    executor.drain()
    frames = getattr(executor, "frame_exports", None)
    if frames is not None and frames.link is not None and resource in frames.names \
            and frames.last is not None:
        return frames.array(resource, wrap)
    array = _read_output(executor, resource)
    return array if wrap is None else wrap(array)


def _read_output(executor: Any, resource: str) -> DeviceArray:
    device = executor.device
    link = cuda_link(device)
    if resource in executor.buffers or not isinstance(link, CudaLink):
        return DeviceArray.of_host(executor.read(resource))
    image = executor.image(resource)
    made = _exports.setdefault(executor, {})
    export = made.get(resource)
    if export is None or export.image is not image or export.submitter.key != image.handle:
        if export is not None:
            export.destroy()
        state = executor._final.get(resource)
        export = made[resource] = ImageExport(
            device, image, layout_now=state or "UNDEFINED", layout_after=state, link=link,
            label=f"{resource}:export")
    return export.read()
