"""Run a compiled frame graph on wgpu: textures from the plan, passes with timestamps, readback.

WebGPU cannot alias memory, so transient resources with identical descriptions and disjoint
lifetimes share one texture instead; everything else follows the compiled plan.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import wgpu

from ...exec.core import ExecutorCore
from ...graph import CompiledGraph
from ...graph.compile import IMPLIED_CAPS
from ...graph.formats import format_info
from ...options import RunOptions, check_options
from ...passes import Pass, Settings
from ...shaders import ShaderError
from ...units import align_up
from .calls import FrameCalls
from .context import PassContext
from .device import Device
from .programs import Binding, ShaderCache
from .resources import buffer_usage, share_textures, texture_usage, usage_flags, wgpu_format
from .timestamps import STAMP_BATCH, FrameSlot, Stamps


def check_caps(passes: dict[str, Pass], caps: frozenset[str]) -> None:
    """A ShaderError naming the first pass that needs what wgpu lacks (mesh shaders, ray
    queries, acceleration structures), before any of its work is set up."""
    for name, p in passes.items():
        lacking = [c for c in (*IMPLIED_CAPS.get(p.type, ()), *p.requires) if c not in caps]
        if lacking:
            raise ShaderError(f"pass '{name}' ({type(p).id or type(p).__name__}) needs "
                              f"{', '.join(lacking)}, which the wgpu backend does not have "
                              "(run it on vk: --backend vk, or backend = \"vk\" on the pass)")


def _identity(resource: Any) -> Any:
    """What makes two bound resources the same: the objects (by id) and any numbers
    (a buffer binding's offset and size)."""
    if isinstance(resource, dict):
        return tuple((k, v if isinstance(v, int) else id(v))
                     for k, v in sorted(resource.items()))
    return id(resource)


class Executor(ExecutorCore):
    """Owns the textures of one compiled graph on one device and records its frames."""

    def __init__(self, device: Device, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: Any = None,
                 readback: tuple[str, ...] = (), present: tuple[str, ...] = (), *,
                 options: RunOptions | None = None):
        self.device = device
        self._init_core(plan, passes, slots, scene, readback, check_options(options))
        self.present = tuple(present)  # outputs a window samples to show them
        self.shaders = ShaderCache(device)
        # a bridge's side on this backend (rfw.frame): the host copies, nothing is recorded
        self._bridges = tuple(name for name in plan.bridges if name not in passes)
        for name in self._bridges:
            if len(plan.accesses[name]) > 1:
                raise ShaderError(f"pass '{name}' copies between backends: the plan mixes "
                                  "them, and runs through rfw.render.render (rfw.frame "
                                  "gives each backend its part of it)")
        self._textures: dict[str, Any] = {}
        self._views: dict[tuple[str, int | None], Any] = {}  # (resource, mip) -> view
        self._uniforms: dict[tuple[str, str], Any] = {}
        # per call site (pass, n-th dispatch or scene draw): the last call and what it found
        self.call_sites: dict[tuple, tuple] = {}
        # bind groups by layout and bound objects: [group, what it holds, frame last used]
        self._bind_groups: dict[tuple, list] = {}
        # (pass, its n-th scene draw) -> (key, bundle, draws): replayed while the key holds
        self._bundles: dict[tuple[str, int], tuple[tuple, Any, int]] = {}
        self.bundles_recorded = 0
        self._written: dict[tuple[str, str], bytes] = {}  # what each uniform buffer holds
        self._packs: dict[tuple[str, str], tuple[tuple, bytes]] = {}  # Settings.pack() kept
        self._allocate()
        self._timestamp_enabled = "timestamp-query" in device.features
        self._query_set = None  # the frame's slot's
        self.calls = FrameCalls(device.device)
        self.stamps: Stamps | None = None
        self._made: list[Any] = []  # buffers passes made in setup
        self.keep_in_flight(self.options.in_flight())
        check_caps(passes, device.caps)
        self._setup_passes(frozenset(device.caps))

    # resources ----------------------------------------------------------------------------
    def _allocate(self) -> None:
        names = list(self.plan.order)
        pos = {n: i for i, n in enumerate(names)}
        spans = {r.name: (pos.get(r.first, 0), pos.get(r.last, len(names)))
                 for r in self.plan.resources}
        images = [r for r in self.plan.resources if r.kind == "image" and r.format]
        self.owner = share_textures(images, set(self.readback) | set(self.present), spans)
        # a history pair's textures trade places every frame: one read back, both copyable
        readback = set(self.readback)
        for copy, name in self.history:
            if copy in readback or name in readback:
                readback |= {copy, name}
        for r in images:
            if self.owner[r.name] != r.name:
                continue
            # user-owned images are filled by the user: they take copies in
            upload = wgpu.TextureUsage.COPY_DST if r.external else 0
            if r.name in self.present:
                upload |= wgpu.TextureUsage.TEXTURE_BINDING
            self._textures[r.name] = self.device.device.create_texture(
                size=(r.width, r.height, r.layers), format=wgpu_format(r.format),
                usage=(texture_usage(r, r.name in readback) | upload) or
                wgpu.TextureUsage.TEXTURE_BINDING,
                mip_level_count=r.mips, sample_count=r.samples, label=r.name)
        self.texture_count = len(self._textures)
        self._buffers: dict[str, Any] = {}
        for r in self.plan.resources:
            if r.kind == "buffer" and r.raw_bytes > 0:
                self._buffers[r.name] = self.device.device.create_buffer(
                    size=align_up(r.raw_bytes, 4), usage=buffer_usage(r), label=r.name)

    def texture(self, resource: str) -> Any:
        return self._textures[self.owner[resource]]

    def buffer(self, resource: str) -> Any:
        return self._buffers[resource]

    def view(self, resource: str, *, mip: int | None = None) -> Any:
        """The resource's view (every mip), or a view of mip ``mip`` alone."""
        key = (resource, mip)
        if key not in self._views:
            tex = self.texture(resource)
            if mip is not None and not 0 <= mip < tex.mip_level_count:
                raise ShaderError(f"'{resource}' has {tex.mip_level_count} mip levels, no "
                                  f"mip {mip}")
            self._views[key] = tex.create_view(label=resource) if mip is None else \
                tex.create_view(base_mip_level=mip, mip_level_count=1, label=resource)
        return self._views[key]

    def format_of(self, value: Any) -> str | None:
        tex = getattr(value, "texture", None)
        return getattr(tex, "format", None) if tex is not None else None

    def _make_sampler(self, filter: str, address: str, compare: str | None) -> Any:
        return self.device.device.create_sampler(
            mag_filter=filter, min_filter=filter, mipmap_filter=filter,
            address_mode_u=address, address_mode_v=address, address_mode_w=address,
            compare=compare, label=f"rfw:sampler:{filter}:{address}")

    def uniform(self, owner: str, name: str, data: bytes) -> Any:
        """The uniform buffer of ``owner``'s binding ``name`` holding ``data``: written
        when the bytes differ from the ones it holds (a frame that changes no setting
        writes nothing)."""
        key = (owner, name)
        buf = self._uniforms.get(key)
        if buf is None or buf.size < len(data):
            buf = self._uniforms[key] = self.device.device.create_buffer(
                size=max(16, len(data)), usage=wgpu.BufferUsage.UNIFORM |
                wgpu.BufferUsage.COPY_DST, label=f"{owner}.{name}")
            self._written.pop(key, None)
        if self._written.get(key) != data:
            self.device.device.queue.write_buffer(buf, 0, data)
            self._written[key] = bytes(data)
        return buf

    def as_resource(self, value: Any, b: Binding, owner: Pass) -> Any:
        if isinstance(value, Settings):
            data = self._pack((owner.name, b.name), value)
            return {"buffer": self.uniform(owner.name, b.name, data)}
        if isinstance(value, np.ndarray | bytes):
            data = value.tobytes() if isinstance(value, np.ndarray) else value
            return {"buffer": self.uniform(owner.name, b.name, data)}
        if isinstance(value, wgpu.GPUBuffer):
            return {"buffer": value}
        return value

    def _pack(self, key: tuple[str, str], settings: Settings) -> bytes:
        # packing walks the type hints: the bytes are kept while the values read the same
        snap = (type(settings), repr(vars(settings)))
        hit = self._packs.get(key)
        if hit is None or hit[0] != snap:
            hit = self._packs[key] = (snap, settings.pack())
        return hit[1]

    def bind_group(self, layout: Any, resources: list[tuple[int, Any]], *,
                   label: str = "") -> Any:
        """The bind group of ``layout`` over ``resources`` [(binding, resource)], made once
        while the same objects are bound (a uniform's buffer stays while its size fits)."""
        key = (id(layout), *((k, _identity(r)) for k, r in resources))
        hit = self._bind_groups.get(key)
        if hit is None:
            entries = [{"binding": k, "resource": r} for k, r in resources]
            group = self.device.device.create_bind_group(layout=layout, entries=entries,
                                                         label=label)
            # holding what the key names keeps their ids from being reused
            hit = self._bind_groups[key] = [group, (layout, resources), self.frame_index]
        hit[2] = self.frame_index
        return hit[0]

    def bundle(self, slot: tuple[str, int], key: tuple, record: Any, *,
               color_formats: tuple[str, ...], depth_format: str | None,
               depth_read_only: bool) -> tuple[Any, int]:
        """The render bundle of ``slot`` (a pass and its n-th scene draw) and its draw
        count: ``record(encoder)`` fills a new one when ``key`` (pipeline, bind groups,
        scene, formats) differs from the last one's, else the last one is replayed."""
        hit = self._bundles.get(slot)
        if hit is not None and hit[0] == key:
            return hit[1], hit[2]
        enc = self.device.device.create_render_bundle_encoder(
            color_formats=list(color_formats), depth_stencil_format=depth_format,
            depth_read_only=depth_read_only, stencil_read_only=depth_read_only,
            label=f"{slot[0]}:scene")
        draws = record(enc)
        bundle = enc.finish(label=f"{slot[0]}:scene")
        self._bundles[slot] = (key, bundle, draws)
        self.bundles_recorded += 1
        return bundle, draws

    # frames -------------------------------------------------------------------------------
    def timestamp_writes(self, pass_name: str) -> dict | None:
        if not self._timestamp_enabled:
            return None
        k = self._next_query
        if k + 2 > self._query_set.count:
            return None
        self._next_query += 2
        self._query_owner.append(pass_name)
        return {"query_set": self._query_set, "beginning_of_pass_write_index": k,
                "end_of_pass_write_index": k + 1}

    def _slots_made(self, frames: int) -> None:
        # the frames' timestamps, read back in batches (Stamps): one place per frame
        if self.stamps is not None:
            self.stamps.destroy()
            self.stamps = None
        if self._timestamp_enabled:
            self.stamps = Stamps(self.device.device, 8 * self.in_flight.slots[0].query_set.count,
                                 max(STAMP_BATCH, frames))

    def _make_slot(self, k: int) -> FrameSlot:
        dev = self.device.device
        if not self._timestamp_enabled:
            return FrameSlot(None, None, None, self.calls)
        n = 2 * len(self.plan.order) * 4  # up to four GPU passes per rfw pass
        return FrameSlot(
            dev.create_query_set(type="timestamp", count=n, label=f"rfw:timestamps{k}"),
            dev.create_buffer(size=8 * n, usage=wgpu.BufferUsage.QUERY_RESOLVE |
                              wgpu.BufferUsage.COPY_SRC, label=f"rfw:timestamps{k}"),
            dev.create_buffer(size=8 * n, usage=wgpu.BufferUsage.MAP_READ |
                              wgpu.BufferUsage.COPY_DST, label=f"rfw:timestamps{k}:read"),
            self.calls)

    def _destroy_slot(self, slot: FrameSlot) -> None:
        slot.destroy()

    def _drained(self) -> None:
        if self.stamps is not None and self.stamps.unread:
            self.stamps.read()

    # the frame's primitives (rfw.exec.core) ----------------------------------------------
    def _open(self, slot: FrameSlot) -> None:
        """Host writes need no drain before a frame: WebGPU orders ``queue.write_buffer``
        before the next submit and keeps what a submitted frame uses alive."""
        self._query_set = slot.query_set
        self._encoder: Any = None
        self._next_query = 0
        self._query_owner: list[str] = []

    def _swap(self, a: str, b: str) -> None:
        # history: the textures behind two resources trade places, with their views
        if a in self.owner and b in self.owner:
            self.owner[a], self.owner[b] = self.owner[b], self.owner[a]
            views = {k: self._views.pop(k) for k in list(self._views) if k[0] in (a, b)}
            for (name, mip), v in views.items():
                self._views[(b if name == a else a, mip)] = v

    def _bridge(self, name: str) -> None:
        """A bridge's side of the plan (``rfw.frame``: the copy goes through the host
        between flushes, and WebGPU tracks the usage itself) records nothing."""
        if name not in self._bridges:
            raise KeyError(name)

    def _context(self, name: str, p: Pass) -> PassContext:
        """The pass's context over the frame's open command encoder (made on first use).
        No debug group around the pass: each compute and render pass it begins carries its
        name as label already, and a group costs two native calls per pass a frame."""
        if self._encoder is None:
            self._encoder = self.calls.encoder()
        return PassContext(self, p, self._encoder, self.slots[name])

    def _submit(self, slot: FrameSlot, *, last: bool) -> Any:
        """Submit the open encoder (``_send``) and return how to finish it: wait for it,
        then read its timestamps (a flush's from the slot's readback at once, the frame's
        last submit's from :class:`Stamps`, once its batch is read)."""
        owners = self._query_owner
        if not last:
            if not self._send(slot, last=False):
                return None
            return lambda append: self._finish_flush(slot, owners, append)
        frame = self.frame_index
        self._send(slot, last=True)
        # bind groups unused last frame and this one name objects no pass binds any more
        if len(self._bind_groups) > 64:
            self._bind_groups = {k: v for k, v in self._bind_groups.items()
                                 if v[2] >= self.frame_index - 1}
        return lambda append: self._finish(slot, frame, owners, append)

    def _finish_flush(self, slot: FrameSlot, owners: list[str], append: Any) -> None:
        slot.wait()
        if not owners:
            append(None)
            return
        slot.readback.map_sync("READ_NOSYNC")
        try:
            raw = np.frombuffer(slot.readback.read_mapped(0, 16 * len(owners)), np.uint64)
        finally:
            slot.readback.unmap()
        append(self._add_timestamps(raw, owners))

    def _send(self, slot: FrameSlot, *, last: bool) -> bool:
        """Submit the open encoder with its queries resolved and copied to where they are
        read (the frame's place in :class:`Stamps` for its ``last`` submit, else the
        slot's own readback, read at once): False if none is open."""
        encoder = self._encoder
        if encoder is None:
            return False
        self._encoder = None
        n = self._next_query
        if n:
            encoder.resolve_query_set(slot.query_set, 0, n, slot.resolve, 0)
            if last:
                buf, at = self.stamps.place(self.frame_index)
                encoder.copy_buffer_to_buffer(slot.resolve, 0, buf, at, 8 * n)
            else:
                encoder.copy_buffer_to_buffer(slot.resolve, 0, slot.readback, 0, 8 * n)
        slot.index = self.calls.submit(encoder)
        self._next_query = 0
        self._query_owner = []
        return True

    def _finish(self, slot: FrameSlot, frame: int, owners: list[str], append: Any) -> None:
        """Wait for a submitted frame, then hand its GPU ms per pass to ``append`` (once
        its timestamps are read, if its last submit had any)."""
        slot.wait()

        def times(raw: np.ndarray | None) -> None:
            append(self._add_timestamps(raw, owners) if owners else None)

        if self.stamps is not None:  # every frame: a batch is read after its last frame
            self.stamps.finished(frame, 16 * len(owners), times)
        else:
            times(None)

    def _add_timestamps(self, raw: np.ndarray, owners: list[str]) -> dict[str, float]:
        """GPU ms per pass: pass ``owners[k]``'s begin and end stamps are ``raw[2k]`` and
        ``raw[2k + 1]`` (a pass with several GPU passes adds them up)."""
        gpu: dict[str, float] = {}
        period = self.device.timestamp_period * 1e-6
        for k, name in enumerate(owners):
            begin, end = int(raw[2 * k]), int(raw[2 * k + 1])
            gpu[name] = gpu.get(name, 0.0) + max(0, end - begin) * period
        return gpu

    def upload(self, resource: str, array: np.ndarray) -> None:
        """Fill an external image from an (H, W, C) array of its texel type."""
        r = self.plan.resource(resource)
        data = np.ascontiguousarray(array)
        self.device.device.queue.write_texture(
            {"texture": self.texture(resource), "mip_level": 0},
            data, {"bytes_per_row": data.nbytes // r.height}, (r.width, r.height, 1))

    def read(self, resource: str) -> np.ndarray:
        """Read an image back as (H, W, C) numpy array in its own texel type, once every
        frame in flight is done."""
        self.drain()
        r = self.plan.resource(resource)
        info = format_info(r.format)
        tex = self.texture(resource)
        bpp = info.block_bytes
        data = self.device.device.queue.read_texture(
            {"texture": tex, "mip_level": 0, "origin": (0, 0, 0)},
            {"offset": 0, "bytes_per_row": r.width * bpp}, (r.width, r.height, 1))
        dtype = {"float": np.float16 if bpp // max(1, info.components) == 2 else np.float32,
                 "unorm": np.uint8 if bpp // max(1, info.components) == 1 else np.uint16,
                 "uint": np.uint32, "depth": np.float32}.get(info.kind, np.uint8)
        arr = np.frombuffer(data, dtype=dtype)
        return arr.reshape(r.height, r.width, -1)

    def _make_buffer(self, label: str, data: np.ndarray, usage: tuple[str, ...]) -> Any:
        """A buffer holding ``data`` (a pass's setup tables), destroyed with the executor."""
        buf = self.device.device.create_buffer_with_data(data=data.tobytes(),
                                                         usage=usage_flags(usage), label=label)
        self._made.append(buf)
        return buf

    def _release(self) -> None:
        """What the executor made, after every frame is finished (ExecutorCore.destroy)."""
        if self.stamps is not None:
            self.stamps.destroy()
            self.stamps = None
        self.calls.clear()
        for t in self._textures.values():
            t.destroy()
        self._textures.clear()
        for b in (*self._buffers.values(), *self._uniforms.values(), *self._made):
            b.destroy()
        self._buffers.clear()
        self._made.clear()
        self._views.clear()
        self._bundles.clear()
        self._bind_groups.clear()
        self._uniforms.clear()
        self._written.clear()
        self._packs.clear()
        self._query_set = None
