"""A wgpu frame's fixed calls, made with descriptors built once.

wgpu-py builds and checks every descriptor as cffi structs on each call: for a frame of one
render pass (command encoder, pass, finish, submit) that is about 50 µs of Python on a
2-core Xeon, more than the pass's own work. A frame that repeats the last one repeats its
descriptors too, so :class:`FrameCalls` keeps each one, keyed by what it holds (and holding
those objects, so their ids stay theirs), and calls wgpu-native through wgpu-py's function
table (``libf``: a validation error still raises as wgpu-py's own calls raise it). Passes
that a caller goes on recording into come back as wgpu-py's objects; the backend's own
whole passes (a bundle replay, one dispatch) go through :meth:`FrameCalls.bundles` and
:meth:`FrameCalls.dispatch` without one.

Submits go through ``wgpuQueueSubmitForIndex``: :meth:`FrameCalls.wait` blocks on a
submission by its index (``wgpuDevicePoll``), which is what a frame in flight waits for;
no buffer is mapped for it.

This uses wgpu-py's backend module (``wgpu.backends.wgpu_native._api``), which is not its
public API: ``pyproject.toml`` pins wgpu, and ``tests/backends/test_wgpu_calls.py`` checks these
calls against wgpu-py's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from wgpu.backends.wgpu_native import _api

_ffi, _lib, _libf = _api.ffi, _api.lib, _api.libf

# descriptors kept per executor before the oldest half goes (a resize or a hot reload makes
# new views and pipelines, and the ones they replace must not stay alive through this)
LIMIT = 512


def _timestamps(writes: dict | None) -> Any:
    if writes is None:
        return _ffi.NULL
    return _api.new_struct_p(
        "WGPUPassTimestampWrites *", querySet=writes["query_set"]._internal,
        beginningOfPassWriteIndex=writes["beginning_of_pass_write_index"],
        endOfPassWriteIndex=writes["end_of_pass_write_index"])


def _writes_key(writes: dict | None) -> tuple:
    if writes is None:
        return ()
    return (writes["query_set"], writes["beginning_of_pass_write_index"],
            writes["end_of_pass_write_index"])


def wait_idle(device: Any) -> None:
    """Submit what the queue holds (``write_texture`` staging among it) and block until all
    of it is done, so wgpu-native frees its staging copies (wgpu-py's
    ``on_submitted_work_done_sync`` fails against wgpu-native's callback type in 0.32)."""
    device.queue.submit([])
    _libf.wgpuDevicePoll(device._internal, True, _ffi.NULL)


class FrameCalls:
    """One device's frame calls with kept descriptors (see the module's text)."""

    def __init__(self, device: Any, label: str = "rfw:frame"):
        self.device = device
        self.label = label
        view = _api.to_c_string_view(label)
        self._encoder = _api.new_struct_p("WGPUCommandEncoderDescriptor *", label=view)
        self._finish = _api.new_struct_p("WGPUCommandBufferDescriptor *", label=view)
        self._commands = _ffi.new("WGPUCommandBuffer[1]")
        self._index = _ffi.new("WGPUSubmissionIndex *")
        self._kept: dict[tuple, tuple[Any, ...]] = {}  # key -> (descriptor, what it names)
        self.made = 0  # descriptors built (a test counts them)

    def _keep(self, key: tuple, make: Any) -> Any:
        hit = self._kept.get(key)
        if hit is None:
            if len(self._kept) >= LIMIT:
                for old in list(self._kept)[:LIMIT // 2]:
                    del self._kept[old]
            hit = self._kept[key] = (make(), key)
            self.made += 1
        return hit[0]

    # encoders ---------------------------------------------------------------------------
    def encoder(self) -> Any:
        """A new command encoder (wgpu-py's ``GPUCommandEncoder``)."""
        raw = _libf.wgpuDeviceCreateCommandEncoder(self.device._internal, self._encoder)
        return _api.GPUCommandEncoder(self.label, raw, self.device)

    def submit(self, encoder: Any) -> int:
        """Finish ``encoder`` and submit it: the submission's index, for :meth:`wait`."""
        raw = _libf.wgpuCommandEncoderFinish(encoder._internal, self._finish)
        self._commands[0] = raw
        try:
            return int(_libf.wgpuQueueSubmitForIndex(self.device.queue._internal, 1,
                                                     self._commands))
        finally:
            _lib.wgpuCommandBufferRelease(raw)

    def wait(self, index: int) -> None:
        """Block until submission ``index`` (and every one before it) is done."""
        self._index[0] = index
        _libf.wgpuDevicePoll(self.device._internal, True, self._index)

    # passes -----------------------------------------------------------------------------
    def _render_descriptor(self, encoder: Any, label: str, color: Sequence[dict],
                           depth: dict | None, writes: dict | None) -> Any:
        # the structs wgpu-py's begin_render_pass makes, built by its own helpers
        attachments = [encoder._create_render_pass_color_attachment(a) for a in color]
        return _api.new_struct_p(
            "WGPURenderPassDescriptor *", label=_api.to_c_string_view(label),
            colorAttachments=_api.new_array("WGPURenderPassColorAttachment[]", attachments),
            colorAttachmentCount=len(attachments),
            depthStencilAttachment=_ffi.NULL if depth is None else
            encoder._create_render_pass_stencil_attachment(depth),
            timestampWrites=_timestamps(writes), occlusionQuerySet=_ffi.NULL)

    def begin_render(self, encoder: Any, label: str, color: Sequence[dict],
                     depth: dict | None, writes: dict | None) -> Any:
        """``wgpuCommandEncoderBeginRenderPass`` with the kept descriptor for these
        attachments (dicts as wgpu-py's ``begin_render_pass`` takes them) and timestamp
        writes: the raw pass encoder, to be ended and released (:meth:`end_render`)."""
        key = ("render", label,
               tuple((a["view"], a["load_op"], a["store_op"], tuple(a["clear_value"]))
                     for a in color),
               None if depth is None else tuple(sorted(depth.items())), _writes_key(writes))
        desc = self._keep(key, lambda: self._render_descriptor(encoder, label, color, depth,
                                                               writes))
        return _libf.wgpuCommandEncoderBeginRenderPass(encoder._internal, desc)

    def render_pass(self, encoder: Any, label: str, color: Sequence[dict],
                    depth: dict | None, writes: dict | None) -> Any:
        """:meth:`begin_render` as wgpu-py's ``GPURenderPassEncoder``."""
        raw = self.begin_render(encoder, label, color, depth, writes)
        return _api.GPURenderPassEncoder(label, raw, self.device)

    def bundles(self, encoder: Any, label: str, color: Sequence[dict], depth: dict | None,
                writes: dict | None, bundles: Sequence[Any]) -> None:
        """A whole render pass that executes ``bundles``."""
        raw = self.begin_render(encoder, label, color, depth, writes)
        try:
            handles = self._keep(("bundles", *bundles), lambda: _ffi.new(
                "WGPURenderBundle[]", [b._internal for b in bundles]))
            _libf.wgpuRenderPassEncoderExecuteBundles(raw, len(bundles), handles)
            _libf.wgpuRenderPassEncoderEnd(raw)
        finally:
            _lib.wgpuRenderPassEncoderRelease(raw)

    def dispatch(self, encoder: Any, label: str, writes: dict | None, pipeline: Any,
                 groups: Sequence[Any], size: tuple[int, int, int]) -> None:
        """A whole compute pass: ``pipeline``, bind groups 0.. ``groups``, one dispatch."""
        desc = self._keep(("compute", label, _writes_key(writes)), lambda: _api.new_struct_p(
            "WGPUComputePassDescriptor *", label=_api.to_c_string_view(label),
            timestampWrites=_timestamps(writes)))
        raw = _libf.wgpuCommandEncoderBeginComputePass(encoder._internal, desc)
        try:
            _libf.wgpuComputePassEncoderSetPipeline(raw, pipeline._internal)
            for g, group in enumerate(groups):
                _libf.wgpuComputePassEncoderSetBindGroup(raw, g, group._internal, 0, _ffi.NULL)
            _libf.wgpuComputePassEncoderDispatchWorkgroups(raw, *size)
            _libf.wgpuComputePassEncoderEnd(raw)
        finally:
            _lib.wgpuComputePassEncoderRelease(raw)

    def clear(self) -> None:
        """Drop every kept descriptor (and what it holds)."""
        self._kept.clear()
