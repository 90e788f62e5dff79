"""``VkScene``: a :class:`rfw.scene.Scene` on a :class:`VkDevice`, the twin of ``GpuScene``.

Vertex and index buffers, mipmapped textures (with 1x1 white and flat-normal defaults), one
sampler per texture, and the descriptor sets the GLSL twins declare: set 1 camera + lights
(one set for the main camera, one for the sun), set 2 per material (uniform, five texture
views, sampler), set 3 one for the whole scene (every instance's matrices in one storage
buffer, which a draw indexes through its ``firstInstance``; built in one batched numpy step).
Bytes come from :mod:`rfw.backends.scene_data`, so both backends upload the same scene.
Persistent memory comes from a :class:`BlockAllocator`.

The Vulkan object wrappers it makes (samplers, descriptor set layouts and pools, descriptor
writes) come from :mod:`.objects`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rfw.authoring import INSTANCE_DTYPE as TABLE_DTYPE
from rfw.backends.scene_data import (
    INSTANCE_BYTES,
    MOTION_BYTES,
    SCENE_GROUPS,
    CameraFrames,
    InstanceFrames,
    check_instance_limits,
    instance_blocks,
    lights_bytes,
    material_bytes,
    mip_levels,
    mirrored_arrays,
    mirrored_mask,
    sun_camera_bytes,
    texture_views,
)
from rfw.graph.sync import State
from rfw.scene.model import Camera, Scene
from rfw.scene.sides import with_back_faces
from rfw.units import MiB, align_up

from .accel import SceneAccel
from .commands import (
    copy_into_buffers,
    copy_into_uniforms,
    one_time,
    record_image_bands,
    record_upload,
)
from .consts import (
    const,
    ffi,
    lib,
)
from .device import VkDevice
from .memory import BlockAllocator, Buffer, Image, ImageView, image_view, staging_buffer
from .objects import (
    BufferRange,
    DescriptorPool,
    DescriptorSetLayout,
    make_sampler,
    update_descriptors,
)

CAMERA_BYTES = 304  # CameraBlock
LIGHTS_BYTES = 1120  # LightsBlock

# stage flags of scene set layouts: one layout serves raster and compute pipelines alike
SHADER_STAGES = ("VK_SHADER_STAGE_VERTEX_BIT", "VK_SHADER_STAGE_FRAGMENT_BIT",
                 "VK_SHADER_STAGE_COMPUTE_BIT")

# who reads the scene's buffers and textures: the upload makes its copies visible to them
_SCENE_READ = State(None, frozenset({"VERTEX_ATTRIBUTE_INPUT", "INDEX_INPUT", "VERTEX_SHADER",
                                     "FRAGMENT_SHADER", "COMPUTE_SHADER"}),
                    frozenset({"VERTEX_ATTRIBUTE_READ", "INDEX_READ", "UNIFORM_READ",
                               "SHADER_STORAGE_READ"}))
# the cameras' uniforms: read by any stage of any pass (written by a frame's copy_camera)
CAMERA_READ = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"UNIFORM_READ"}))
# the instance rows animations move: read as storage by any stage (written by copy_pose),
# and before a frame's copy, also the last write (the upload's, or last frame's copy)
POSE_READ = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"SHADER_STORAGE_READ"}))
POSE_BEFORE = State(None, frozenset({"ALL_COMMANDS"}),
                    frozenset({"SHADER_STORAGE_READ", "TRANSFER_WRITE"}))
MESHLET_ROW_BYTES = 144  # meshlet.glsl's MInstance
_SAMPLED = State("SHADER_READ_ONLY_OPTIMAL", frozenset({"FRAGMENT_SHADER", "COMPUTE_SHADER"}),
                 frozenset({"SHADER_SAMPLED_READ"}))


def _flags(names: Iterable[str]) -> int:
    out = 0
    for n in names:
        out |= const(n)
    return out


def scene_set_layout(device: VkDevice, index: int) -> DescriptorSetLayout:
    return DescriptorSetLayout(device, [(b, kind, 1) for _, b, kind in SCENE_GROUPS[index]],
                               _flags(SHADER_STAGES), label=f"scene:set{index}")


# ---------------------------------------------------------------------------------------------
# the scene


# what one storage descriptor of the instance rows must reach
# (rfw.backends.scene_data.check_instance_limits)
INSTANCE_LIMIT_KEYS = ("maxStorageBufferRange",)


def meshlet_rows(transforms: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """meshlet.glsl's MInstance of each instance (``vkext.meshlet``'s rows, all at once):
    its ``instance_blocks`` row (``rows``: model and normal matrices), then its largest
    column scale (sphere radii), 1 where the scale is uniform, -1 where it mirrors."""
    m = np.asarray(transforms, np.float64).reshape(-1, 4, 4)
    cols = np.linalg.norm(m[:, :3, :3], axis=1)
    scale = cols.max(axis=1)
    uniform = np.all(np.isclose(cols, scale[:, None], rtol=1e-4), axis=1)
    out = np.zeros((len(m), MESHLET_ROW_BYTES // 4), np.float32)
    out[:, :INSTANCE_BYTES // 4] = rows
    out[:, 32] = scale
    out[:, 33] = uniform
    out[:, 34] = np.where(np.linalg.det(m[:, :3, :3]) < 0.0, -1.0, 1.0)
    return out


class _SameSet:
    """A read-only sequence of ``count`` copies of one descriptor set pointer."""

    def __init__(self, handle: Any, count: int):
        self.handle, self.count = handle, count

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, k: int) -> Any:
        if not -self.count <= k < self.count:
            raise IndexError(k)
        return self.handle


class _Upload:
    """The scene's buffers, through one staging buffer and one submit (textures go through
    ``_TextureUpload``)."""

    def __init__(self) -> None:
        self.parts: list[np.ndarray] = []
        self.size = 0
        self.buffers: list[tuple[Buffer, int, int]] = []  # (dst, staging offset, bytes)

    def _add(self, data: np.ndarray) -> int:
        raw = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
        pad = -self.size % 16
        if pad:
            self.parts.append(np.zeros(pad, np.uint8))
        offset = self.size + pad
        self.parts.append(raw)
        self.size = offset + raw.size
        return offset

    def buffer(self, dst: Buffer, data: np.ndarray) -> None:
        self.buffers.append((dst, self._add(data), int(np.asarray(data).nbytes)))

    def submit(self, device: VkDevice) -> None:
        if not self.size:
            return
        staging = staging_buffer(device, self.size, label="scene:upload")
        try:
            offset = 0
            for part in self.parts:  # in place: no joined copy of every byte uploaded
                staging.write(part, offset)
                offset += part.size
            with one_time(device, label="scene upload") as cmd:
                record_upload(cmd, staging, buffers=self.buffers, buffers_to=_SCENE_READ)
        finally:
            staging.destroy()


# staging bytes per texture copy: the host holds at most this much of the texels uploaded
TEXTURE_CHUNK = 32 * MiB


class _TextureUpload:
    """Textures streamed through one bounded staging buffer, a submit per ``TEXTURE_CHUNK``
    of rows, one mip level built while the last one is copied: the host holds one image's
    pixels, two of its levels and one chunk, not every texture's chain twice over."""

    def __init__(self, device: VkDevice) -> None:
        self.device = device
        self.staging: Buffer | None = None

    def image(self, dst: Image, levels: Iterable[np.ndarray]) -> None:
        need = min(TEXTURE_CHUNK, align_up(dst.width * dst.height * 4 * 4 // 3 + 4096, 16))
        if self.staging is None or self.staging.bytes < need:
            self.close()
            self.staging = staging_buffer(self.device, need, label="scene:textures")
        pending: list[tuple[int, int, int, int, int]] = []  # (offset, mip, y, width, rows)
        used, first = 0, True
        for mip, level in enumerate(levels):
            h, w = level.shape[:2]
            step = max(1, self.staging.bytes // (4 * w))
            for y in range(0, h, step):
                band = level[y:y + step]
                if used + band.nbytes > self.staging.bytes:
                    self._copy(dst, pending, first=first, last=False)
                    pending, used, first = [], 0, False
                self.staging.write(band, used)
                pending.append((used, mip, y, w, band.shape[0]))
                used = align_up(used + band.nbytes, 16)
        self._copy(dst, pending, first=first, last=True)

    def _copy(self, dst: Image, regions: list[tuple[int, int, int, int, int]], *,
              first: bool, last: bool) -> None:
        assert self.staging is not None
        with one_time(self.device, label=f"upload {dst.label}") as cmd:
            record_image_bands(cmd, self.staging, dst, regions, first=first, last=last,
                               to=_SAMPLED)

    def close(self) -> None:
        if self.staging is not None:
            self.staging.destroy()
            self.staging = None


@dataclass(frozen=True)
class BufferPart:
    """One mesh's part of a packed stream: where shaders find it by device address."""

    buffer: Buffer
    offset: int  # bytes
    bytes: int

    @property
    def handle(self) -> Any:
        return self.buffer.handle

    @property
    def address(self) -> int:
        return self.buffer.address + self.offset


@dataclass
class _MeshBuffers:
    vertex: Any  # VkBuffer[4]
    offsets: Any  # VkDeviceSize[4]
    index: Any  # VkBuffer
    count: int
    index_offset: int = 0  # bytes


class VkScene:
    """The scene's buffers, textures, samplers and descriptor sets on a device.

    ``shadow_sampler`` (comparison, less-or-equal) and ``linear_sampler`` are what passes
    bind by name; ``draw()`` records every instance with sets 1 to 3 bound.
    """

    # a camera set between frames is the next frame's alone (set_viewport, copy_camera):
    # frames in flight keep theirs, nothing drains them (rfw.camera_path.set_frame_camera)
    camera_per_frame = True

    def __init__(self, device: VkDevice, scene: Scene, camera: Camera | None = None, *,
                 block_size: int = 32 * MiB):
        self.device = device
        # singular transforms: skipped, with a warning; double-sided materials: back faces
        self.scene = scene = with_back_faces(scene.drawable())
        self.camera = camera or scene.default_camera()
        self.size = (1, 1)
        self.frames = CameraFrames()
        # the instances' rows as each frame sees them, where animations move them
        self.poses = InstanceFrames(scene)
        self.pose_blob = b""  # what the frame begun last copies into the moving rows
        self.pose_span = 0
        self._pose_copies: list[tuple[Buffer, Any]] = []
        self._sun = b""
        self._objects: list[Any] = []
        self.meshlets: Any = None  # vkext.meshlet.MeshletScene, made by the first meshlet pass
        self.allocator = BlockAllocator(device, block_size=block_size, label="scene")
        try:
            self._build()
        except BaseException:
            self.destroy()
            raise

    # building ------------------------------------------------------------------------------
    def _own(self, obj: Any) -> Any:
        self._objects.append(obj)
        return obj

    def _build(self) -> None:
        dev, scene = self.device, self.scene
        align = max(16, int(dev.limits["minUniformBufferOffsetAlignment"]))
        up = _Upload()
        self.meshes: list[_MeshBuffers] = []
        # each stream of every mesh in one buffer (five allocations however many meshes: the
        # city has 2,367), every mesh's part at a 16-byte aligned offset
        per_mesh = [(m.positions, m.normals, m.uvs, m.tangents) for m in scene.meshes]
        vertex = [self._pack(up, [np.ascontiguousarray(a[k], np.float32) for a in per_mesh],
                             "vertex", f"scene:{name}")
                  for k, name in enumerate(("pos", "nor", "uv", "tan"))]
        index = self._pack(up, [np.ascontiguousarray(m.indices, np.uint32)
                                for m in scene.meshes], "index", "scene:indices")
        self.streams = {"pos": vertex[0][0], "nor": vertex[1][0], "uv": vertex[2][0],
                        "tan": vertex[3][0], "indices": index[0]}
        # per mesh (positions, normals, uvs, tangents, indices) as parts of those buffers:
        # shaders that read them through device addresses (buffer references) take theirs
        self.mesh_buffers: list[tuple[BufferPart, ...]] = [
            tuple(BufferPart(b, offs[j], a.nbytes) for (b, offs), a in
                  zip((*vertex, index), (m.positions, m.normals, m.uvs, m.tangents, m.indices),
                      strict=True))
            for j, m in enumerate(scene.meshes)]
        for j, m in enumerate(scene.meshes):
            vb = ffi.new("VkBuffer[4]", [b.handle for b, _ in vertex])
            offsets = ffi.new("VkDeviceSize[4]", [offs[j] for _, offs in vertex])
            self.meshes.append(_MeshBuffers(vb, offsets, index[0].handle, len(m.indices),
                                            index[1][j]))
        # every instance's transform, stacked once for the batched maths below
        self._transforms = np.asarray([i.transform for i in scene.instances],
                                      np.float64).reshape(-1, 4, 4)
        self._mirrored_meshes(up)
        self._strokes(up)

        # static uniforms: the materials, each at an aligned offset
        blob = bytearray()
        self._material_ranges = []
        for data in (material_bytes(m) for m in scene.materials):
            blob += b"\0" * (-len(blob) % align)
            self._material_ranges.append((len(blob), len(data)))
            blob += data
        self.static_uniforms = self.allocator.create_buffer(
            max(16, len(blob)), ("uniform", "transfer_dst"), label="scene:uniforms")
        if blob:
            up.buffer(self.static_uniforms, np.frombuffer(bytes(blob), np.uint8))
        self._instances(up)

        # camera (main, sun, the main one's motion block) and lights: the lights written here,
        # once; the cameras copied in by each frame from its own slot's bytes (copy_camera),
        # so frames in flight keep theirs
        lights, self.sun_matrix, self.default_light = lights_bytes(scene)
        self._cam_offsets = (0, align_up(CAMERA_BYTES, align))
        self._motion_offset = align_up(self._cam_offsets[1] + CAMERA_BYTES, align)
        self.camera_span = self._motion_offset + MOTION_BYTES  # the cameras' bytes
        self._lights_offset = align_up(self.camera_span, align)
        self.camera_blob = bytes(self.camera_span)  # what set_viewport made last
        self.dynamic_uniforms = self.allocator.create_buffer(
            self._lights_offset + LIGHTS_BYTES, ("uniform", "transfer_dst"),
            host_visible=True, label="scene:camera+lights")
        self.dynamic_uniforms.write(np.frombuffer(lights, np.uint8), self._lights_offset)
        self.dynamic_uniforms.write(np.zeros(self._lights_offset, np.uint8), 0)
        self._camera_region = ffi.new("VkBufferCopy*", {"srcOffset": 0, "dstOffset": 0,
                                                        "size": self.camera_span})

        # textures, their samplers and the defaults
        key = "maxImageDimension2D"
        tex = _TextureUpload(dev)
        try:
            self.textures = texture_views(scene, dev.limits.get(key), key,
                                          lambda t: self._texture(tex, t.pixels, t.srgb, t.name))
            one = np.full((1, 1, 4), 255, np.uint8)
            flat = np.array([[[128, 128, 255, 255]]], np.uint8)
            self.white = self._texture(tex, one, False, "white")
            self.white_srgb = self._texture(tex, one, True, "white_srgb")
            self.flat_normal = self._texture(tex, flat, False, "flat_normal")
        finally:
            tex.close()
        self.samplers = [self._own(make_sampler(
            dev, mag=t.mag_filter, min=t.min_filter, mip=t.mipmap_filter, address_u=t.address_u,
            address_v=t.address_v, label=f"{t.name}:sampler")) for t in scene.textures]
        up.submit(dev)

        self.default_sampler = self._own(make_sampler(
            dev, mag="linear", min="linear", mip="linear", address_u="repeat",
            address_v="repeat", label="scene.default"))
        self.linear_sampler = self._own(make_sampler(
            dev, mag="linear", min="linear", mip="linear", label="scene.linear"))
        self.shadow_sampler = self._own(make_sampler(
            dev, mag="linear", min="linear", compare="less-equal", label="scene.shadow"))

        self._descriptor_sets()

    def _instances(self, up: _Upload) -> None:
        # every instance's row (scene_data.instance_blocks) in one storage buffer
        self.instances_size = check_instance_limits(self.scene, self.device.limits,
                                                    INSTANCE_LIMIT_KEYS)
        self.instance_buffer = self.allocator.create_buffer(
            self.instances_size, ("storage", "transfer_dst"), label="scene:instances")
        placed = [*self._transforms, *(i.transform for i in self.scene.stroke_instances)]
        if placed:
            up.buffer(self.instance_buffer, instance_blocks(placed))
        self.prev_instance_buffer = self.instance_buffer
        self.instance_table = self.meshlet_instances = None
        if self.poses.moves:
            self._pose_buffers(up)

    def _pose_buffers(self, up: _Upload) -> None:
        """Where animations move instances: last frame's rows (``prev_instances``), and
        the rows the scene tables and the meshlets read (``instance_table``,
        ``meshlet_instances``: their own copies on a still scene), each written by every
        frame from its slot's bytes (``copy_pose``), as the cameras are."""
        n = len(self.scene.instances)
        rest = self.poses.rows(self.poses.rest)
        self.prev_instance_buffer = self.allocator.create_buffer(
            self.instances_size, ("storage", "transfer_dst"), label="scene:prev_instances")
        self.instance_table = self.allocator.create_buffer(
            max(1, n) * TABLE_DTYPE.itemsize, ("storage", "transfer_dst"),
            label="scene:instance_table")
        self.meshlet_instances = self.allocator.create_buffer(
            max(1, n) * MESHLET_ROW_BYTES, ("storage", "transfer_dst"),
            label="scene:meshlet_instances")
        parts = self._pose_parts(self.poses.rest, rest, rest)
        offset = 0
        for (dst, _), data in zip(self._pose_targets(), parts, strict=True):
            if dst is not self.instance_buffer:  # uploaded already (_instances)
                up.buffer(dst, data)
            region = ffi.new("VkBufferCopy*", {"srcOffset": offset, "dstOffset": 0,
                                               "size": data.nbytes})
            self._pose_copies.append((dst, region))
            offset = align_up(offset + data.nbytes, 16)
        self.pose_span = offset

    def _pose_targets(self) -> list[tuple[Buffer, str]]:
        return [(self.instance_buffer, "rows"), (self.prev_instance_buffer, "prev"),
                (self.instance_table, "table"), (self.meshlet_instances, "meshlets")]

    def _pose_parts(self, transforms: np.ndarray, rows: np.ndarray,
                    prev: np.ndarray) -> list[np.ndarray]:
        """The bytes of each pose target (``_pose_targets``) for a frame."""
        n = len(self.scene.instances)
        table = np.zeros(max(1, n), TABLE_DTYPE)
        meshlet = np.zeros((max(1, n), MESHLET_ROW_BYTES // 4), np.float32)
        if n:
            table["matrices"] = rows[:n]
            table["mesh"][:, 0] = [i.mesh for i in self.scene.instances]
            table["mesh"][:, 1] = self.mirrored
            meshlet[:] = meshlet_rows(transforms[:n], rows[:n])
        return [rows, prev, table, meshlet]

    def _strokes(self, up: _Upload) -> None:
        # points and lines (GpuScene's twin): their fourth stream is COLOR_0 (mesh.glsl);
        # a scene without any makes no buffer
        self.strokes: list[_MeshBuffers] = []
        strokes = self.scene.strokes
        if not strokes:
            return
        streams = [self._pack(up, [np.ascontiguousarray(getattr(m, name), np.float32)
                                   for m in strokes], "vertex", f"scene:strokes:{name}")
                   for name in ("positions", "normals", "uvs", "colors")]
        idx, idx_offs = self._pack(up, [np.ascontiguousarray(m.indices, np.uint32)
                                        for m in strokes], "index", "scene:strokes:indices")
        for j, m in enumerate(strokes):
            vb = ffi.new("VkBuffer[4]", [b.handle for b, _ in streams])
            offsets = ffi.new("VkDeviceSize[4]", [offs[j] for _, offs in streams])
            self.strokes.append(_MeshBuffers(vb, offsets, idx.handle, len(m.indices),
                                             idx_offs[j]))

    def _mirrored_meshes(self, up: _Upload) -> None:
        # a mirrored instance draws with two corners swapped and the tangent sign flipped
        # (scene_data.mirrored_arrays): counter-clockwise front faces again, same pipelines
        scene = self.scene
        self.mirrored = mirrored_mask(self._transforms).tolist()
        self.mirrored_meshes: dict[int, _MeshBuffers] = {}
        ks = sorted({i.mesh for i, m in zip(scene.instances, self.mirrored, strict=True) if m})
        if not ks:
            return
        flipped = [mirrored_arrays(scene.meshes[k]) for k in ks]  # (indices, tangents)
        tan, tan_offs = self._pack(up, [t for _, t in flipped], "vertex", "scene:tan:mirrored")
        idx, idx_offs = self._pack(up, [i for i, _ in flipped], "index",
                                   "scene:indices:mirrored")
        self.streams.update({"tan:mirrored": tan, "indices:mirrored": idx})
        for n, k in enumerate(ks):
            plain = self.meshes[k]
            vb = ffi.new("VkBuffer[4]", [*plain.vertex[0:3], tan.handle])
            offsets = ffi.new("VkDeviceSize[4]", [*plain.offsets[0:3], tan_offs[n]])
            self.mirrored_meshes[k] = _MeshBuffers(vb, offsets, idx.handle,
                                                   len(flipped[n][0]), idx_offs[n])

    def _pack(self, up: _Upload, arrays: list[np.ndarray], usage: str,
              label: str) -> tuple[Buffer, list[int]]:
        """One buffer holding ``arrays`` back to back at 16-byte aligned offsets (a vertex
        attribute's and an index's alignment, and the staging copy's), and the offsets."""
        offsets, end = [], 0
        for a in arrays:
            offsets.append(end)
            end = align_up(end + a.nbytes, 16)
        buf = self.allocator.create_buffer(max(16, end), (usage, "transfer_dst"), label=label)
        if end:
            blob = np.zeros(end, np.uint8)
            for o, a in zip(offsets, arrays, strict=True):
                blob[o:o + a.nbytes] = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
            up.buffer(buf, blob)
        return buf, offsets

    def _texture(self, up: _TextureUpload, pixels: np.ndarray, srgb: bool,
                 label: str) -> ImageView:
        h, w = pixels.shape[:2]
        img = self.allocator.create_image(w, h, "rgba8unorm-srgb" if srgb else "rgba8unorm",
                                          ("sampled", "transfer_dst"),
                                          mips=max(w, h).bit_length(), label=label)
        up.image(img, mip_levels(np.ascontiguousarray(pixels, np.uint8), srgb=srgb))
        return image_view(img, label=f"{label}:view")

    def _descriptor_sets(self) -> None:
        dev, scene = self.device, self.scene
        self.layouts = {i: self._own(scene_set_layout(dev, i)) for i in SCENE_GROUPS}
        n_mat = len(scene.materials)
        self.pool = self._own(DescriptorPool(
            dev, 3 + n_mat, {"uniform_buffer": 4 + n_mat, "storage_buffer": 1,
                             "sampled_image": 5 * n_mat, "sampler": n_mat},
            label="scene:descriptors"))
        layouts = [self.layouts[1].handle] * 2 + [self.layouts[2].handle] * n_mat + \
            [self.layouts[3].handle]
        self._sets = self.pool.allocate(layouts)  # keeps the VkDescriptorSet[] alive
        self.camera_sets = {"main": ffi.addressof(self._sets, 0),
                            "sun": ffi.addressof(self._sets, 1)}
        self.material_sets = [ffi.addressof(self._sets, 2 + k) for k in range(n_mat)]
        self.instance_set = ffi.addressof(self._sets, 2 + n_mat)

        dyn, static = self.dynamic_uniforms.handle, self.static_uniforms.handle
        writes: list[tuple[Any, int, str, tuple]] = []
        for name, k in (("main", 0), ("sun", 1)):
            s = self.camera_sets[name][0]
            writes.append((s, 0, "uniform_buffer", (dyn, self._cam_offsets[k], CAMERA_BYTES)))
            writes.append((s, 1, "uniform_buffer", (dyn, self._lights_offset, LIGHTS_BYTES)))
        read_only = const("VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL")
        for k, m in enumerate(scene.materials):
            s = self.material_sets[k][0]

            def tex(index: int | None, fallback: ImageView) -> Any:
                return (self.textures[index] if index is not None else fallback).handle

            sampler = self.samplers[m.base_color_texture] if m.base_color_texture is not None \
                else self.default_sampler
            off, n = self._material_ranges[k]
            writes += [
                (s, 0, "uniform_buffer", (static, off, n)),
                (s, 1, "sampled_image", (tex(m.base_color_texture, self.white_srgb), read_only)),
                (s, 2, "sampled_image", (tex(m.metallic_roughness_texture, self.white),
                                         read_only)),
                (s, 3, "sampled_image", (tex(m.normal_texture, self.flat_normal), read_only)),
                (s, 4, "sampled_image", (tex(m.occlusion_texture, self.white), read_only)),
                (s, 5, "sampled_image", (tex(m.emissive_texture, self.white_srgb), read_only)),
                (s, 6, "sampler", (sampler.handle,)),
            ]
        writes.append((self.instance_set[0], 0, "storage_buffer",
                       (self.instance_buffer.handle, 0, self.instances_size)))
        update_descriptors(dev, writes)

    # per frame -----------------------------------------------------------------------------
    def set_viewport(self, size: tuple[int, int]) -> None:
        """Make both cameras' bytes for an output ``size`` (``camera_blob``): no GPU memory
        is written here, so frames in flight are not disturbed. Each executor frame copies
        the bytes it began with into the cameras' buffer (:meth:`copy_camera`)."""
        self.size = (int(size[0]), int(size[1]))
        self._sun = sun_camera_bytes(self.camera, self.sun_matrix, self.size)
        self._blob(*self.frames.still(self.camera, self.size))

    def begin_frame(self, index: int) -> None:
        """Frame ``index`` begins: the main camera as it sees it (jittered where a pass asks
        for jitter, ``frames.jitter``) and last frame's matrices (``CameraFrames``), into
        ``camera_blob``, which the frame copies in as it begins."""
        frame = self.frames.begin(self.camera, self.size, index)
        if frame is not None:
            self._blob(*frame)
        pose = self.poses.begin(index)  # None: nothing moves, or the frame has begun
        if pose is not None:
            blob = np.zeros(self.pose_span, np.uint8)
            for (_, region), data in zip(self._pose_copies, self._pose_parts(*pose),
                                         strict=True):
                raw = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
                blob[region.srcOffset:region.srcOffset + raw.size] = raw
            self.pose_blob = blob.tobytes()
            for acc in self.__dict__.get("_accels", {}).values():
                acc.move(pose[0][:len(self.scene.instances)])

    def _blob(self, main: bytes, motion: bytes) -> None:
        blob = bytearray(self.camera_span)
        blob[0:len(main)] = main
        off = self._cam_offsets[1]
        blob[off:off + len(self._sun)] = self._sun
        blob[self._motion_offset:self._motion_offset + len(motion)] = motion
        self.camera_blob = bytes(blob)

    def copy_camera(self, cmd: Any, source: Buffer) -> None:
        """Record the copy of a frame's cameras (``camera_blob`` as the frame wrote it into
        ``source``, host-visible and its own until it is finished) into the buffer the
        camera sets bind: after every read of the frames before it (on this queue, or
        ordered before it), before every read after it."""
        copy_into_uniforms(cmd, source, self.dynamic_uniforms, self._camera_region,
                           CAMERA_READ)

    def copy_pose(self, cmd: Any, source: Buffer) -> None:
        """Record the copies of a frame's instance rows (``pose_blob`` as the frame wrote
        it into ``source``, its slot's own) into the buffers passes bind, as
        :meth:`copy_camera` copies the cameras: after every read of the frames before it,
        before every read after it. Nothing where no animation moves an instance."""
        if not self._pose_copies:
            return
        copy_into_buffers(cmd, source, self._pose_copies, before=POSE_BEFORE, after=POSE_READ)

    def camera_range(self, camera: str = "main") -> BufferRange:
        k = 1 if camera == "sun" else 0
        return BufferRange(self.dynamic_uniforms.handle, self._cam_offsets[k], CAMERA_BYTES)

    @property
    def lights_range(self) -> BufferRange:
        return BufferRange(self.dynamic_uniforms.handle, self._lights_offset, LIGHTS_BYTES)

    @property
    def instances_range(self) -> BufferRange:
        """Every instance's row (``mesh.glsl``'s ``scene_instances``), as set 3 binds it."""
        return BufferRange(self.instance_buffer.handle, 0, self.instances_size)

    @property
    def instance_sets(self) -> _SameSet:
        """Set 3 by instance, for callers that bind one per draw: every instance shares the
        scene's one set (the draw's ``firstInstance`` picks the row)."""
        return _SameSet(self.instance_set, len(self.scene.instances))

    def accel(self, **options: Any) -> Any:
        """The scene's :class:`vkext.accel.SceneAccel` built with ``options`` (``prefer``,
        ``allow_update``, ``compact``): made on first use, kept and destroyed with the
        scene, so every executor and frame on this scene shares its BLAS and TLAS."""
        cache = self.__dict__.setdefault("_accels", {})
        key = tuple(sorted(options.items()))
        if key not in cache:
            acc = SceneAccel(self.device, self.scene, label="scene.accel",
                             moves=self.poses.moves, **options)
            cache[key] = self._own(acc)
            moved = self.poses.last_transforms  # made mid-run: the frame begun last's
            if moved is not None:
                acc.move(moved[:len(self.scene.instances)])
        return cache[key]

    def bindings(self) -> dict[str, Any]:
        """Set 1 by name, as ``GpuScene.bindings()``: the main camera and the lights; and
        what a pass may bind in its own set: ``motion`` (motion.glsl's block, copied in with
        the cameras) and ``prev_instances``, last frame's instance rows (the same rows
        where no animation moves them)."""
        return {"camera": self.camera_range("main"), "lights": self.lights_range,
                "motion": BufferRange(self.dynamic_uniforms.handle, self._motion_offset,
                                      MOTION_BYTES),
                "prev_instances": BufferRange(self.prev_instance_buffer.handle, 0,
                                              self.instances_size)}

    def draw(self, cmd: Any, layout: Any, *, camera: str = "main",
             alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
             topology: str = "triangle-list") -> int:
        """Record every instance whose material's alpha mode is in ``alpha`` with a bound
        graphics pipeline whose layout (``layout``) uses the scene's sets 1 to 3; each
        draw's ``firstInstance`` is the instance's index (its row in set 3). ``topology``
        point-list or line-list: the stroke instances of that kind instead (their rows
        follow the instances')."""
        point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
        lib.vkCmdBindDescriptorSets(cmd, point, layout, 1, 1, self.camera_sets[camera], 0,
                                    ffi.NULL)
        lib.vkCmdBindDescriptorSets(cmd, point, layout, 3, 1, self.instance_set, 0, ffi.NULL)
        index_type = const("VK_INDEX_TYPE_UINT32")
        if topology != "triangle-list":
            return self._draw_strokes(cmd, layout, topology, alpha)
        draws = 0
        last_mesh = last_material = None
        for k, inst in enumerate(self.scene.instances):
            mesh = self.scene.meshes[inst.mesh]
            if self.scene.materials[mesh.material].alpha_mode not in alpha:
                continue
            mirrored = self.mirrored[k]
            buffers = self.mirrored_meshes[inst.mesh] if mirrored else self.meshes[inst.mesh]
            if buffers.count == 0:
                continue
            if mesh.material != last_material:
                lib.vkCmdBindDescriptorSets(cmd, point, layout, 2, 1,
                                            self.material_sets[mesh.material], 0, ffi.NULL)
                last_material = mesh.material
            if (inst.mesh, mirrored) != last_mesh:
                lib.vkCmdBindVertexBuffers(cmd, 0, 4, buffers.vertex, buffers.offsets)
                lib.vkCmdBindIndexBuffer(cmd, buffers.index, buffers.index_offset, index_type)
                last_mesh = (inst.mesh, mirrored)
            lib.vkCmdDrawIndexed(cmd, buffers.count, 1, 0, 0, k)
            draws += 1
        return draws

    def _draw_strokes(self, cmd: Any, layout: Any, topology: str,
                      alpha: tuple[str, ...]) -> int:
        point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
        draws, base = 0, len(self.scene.instances)
        last_material = None
        for k, inst in enumerate(self.scene.stroke_instances):
            mesh = self.scene.strokes[inst.mesh]
            buffers = self.strokes[inst.mesh]
            if mesh.topology != topology or buffers.count == 0 or \
                    self.scene.materials[mesh.material].alpha_mode not in alpha:
                continue
            if mesh.material != last_material:
                lib.vkCmdBindDescriptorSets(cmd, point, layout, 2, 1,
                                            self.material_sets[mesh.material], 0, ffi.NULL)
                last_material = mesh.material
            lib.vkCmdBindVertexBuffers(cmd, 0, 4, buffers.vertex, buffers.offsets)
            lib.vkCmdBindIndexBuffer(cmd, buffers.index, buffers.index_offset,
                                     const("VK_INDEX_TYPE_UINT32"))
            lib.vkCmdDrawIndexed(cmd, buffers.count, 1, 0, 0, base + k)
            draws += 1
        return draws

    def destroy(self) -> None:
        """Destroy every object of the scene (safe to call twice)."""
        for obj in reversed(self._objects):
            obj.destroy()
        self._objects.clear()
        if self.allocator is not None:
            self.allocator.destroy()  # buffers, images (and their views), blocks
            self.allocator = None
