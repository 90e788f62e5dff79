"""A ``Scene`` on the GPU: vertex and index buffers, materials, instances, camera, lights.

Layouts follow ``shaders/common/scene.glsl`` (group 1) and ``mesh.glsl`` (groups 2 and 3).
Every instance's matrices sit in one read-only storage buffer (group 3), which a draw
indexes through its first instance: one bind group for the whole scene, nothing bound per
instance, and the buffer's size checked against the device's limits before it is made.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import wgpu

from ...scene.model import Camera, Scene
from ...scene.sides import with_back_faces
from ...units import align_up
from ..scene_data import (
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
from .calls import wait_idle

# wgpu layout entries of rfw.spirv's descriptor kinds (the scene's groups use these four;
# storage is read-only, the only kind a vertex shader may bind)
_ENTRIES: dict[str, tuple[str, dict[str, str]]] = {
    "uniform_buffer": ("buffer", {"type": "uniform"}),
    "storage_buffer": ("buffer", {"type": "read-only-storage"}),
    "sampled_image": ("texture", {"sample_type": "float", "view_dimension": "2d"}),
    "sampler": ("sampler", {"type": "filtering"}),
}


# bytes of texels written to the queue between two waits: wgpu-native holds more than the
# chunk per write until the wait (peak RSS of 16 4096x4096 textures on lavapipe, forward at
# 64x64: 1,739 MB at 4 MiB, 2,172 at 32, 2,926 at 128; benchmarks/bench_texture_memory.py)
TEXTURE_CHUNK = 4 << 20


def scene_layout_entries(group: int) -> list[dict]:
    """Bind group layout entries of a scene group, visible to every stage that may read it."""
    stages = wgpu.ShaderStage.VERTEX | wgpu.ShaderStage.FRAGMENT | wgpu.ShaderStage.COMPUTE
    out = []
    for _, binding, kind in SCENE_GROUPS[group]:
        key, layout = _ENTRIES[kind]
        out.append({"binding": binding, "visibility": stages, key: dict(layout)})
    return out


# what one storage binding of the instance rows must fit (scene_data.check_instance_limits)
INSTANCE_LIMIT_KEYS = ("max-storage-buffer-binding-size", "max-buffer-size")


class GpuScene:
    # a camera set between frames is the next frame's alone: queue.write_buffer lands after
    # every frame submitted before it (rfw.camera_path.set_frame_camera needs no drain)
    camera_per_frame = True

    def __init__(self, device: Any, scene: Scene, camera: Camera | None = None):
        self.device = device
        # singular transforms: skipped, with a warning; double-sided materials: back faces
        self.scene = scene = with_back_faces(scene.drawable())
        self.camera = camera or scene.default_camera()
        self._buffers: list[Any] = []
        self._textures: list[Any] = []
        self._upload_meshes()
        self._upload_textures()
        self.material_data = [material_bytes(m) for m in scene.materials]
        # the instances' rows as each frame sees them, where animations move them
        self.poses = InstanceFrames(scene)
        self.instance_buffer = self._instances()
        # last frame's rows (prev_instances): the same buffer while nothing moves
        self.prev_instance_buffer = self._instances(prev=True) if self.poses.moves \
            else self.instance_buffer
        self._instance_uniforms: Any = None  # made for a WGSL program's own group 3 only
        self.camera_buffer = self._uniform(b"\0" * 352, "scene.camera")
        # last frame's camera beside this one's, for the passes that bind it (motion.glsl)
        self.motion_buffer = self._uniform(b"\0" * MOTION_BYTES, "scene.motion")
        self.frames = CameraFrames()
        self._camera_bytes: tuple[bytes, bytes] | None = None
        self.sun_camera_buffer = self._uniform(b"\0" * 352, "scene.sun_camera")
        self.lights_buffer = self._uniform(self._lights_bytes(), "scene.lights")
        self.linear_sampler = device.create_sampler(
            mag_filter="linear", min_filter="linear", mipmap_filter="linear",
            address_mode_u="clamp-to-edge", address_mode_v="clamp-to-edge",
            label="scene.linear")
        self.shadow_sampler = device.create_sampler(
            mag_filter="linear", min_filter="linear", compare="less-equal",
            address_mode_u="clamp-to-edge", address_mode_v="clamp-to-edge",
            label="scene.shadow")
        self._bind_cache: dict[Any, Any] = {}
        self.size = (1, 1)

    # uploads ------------------------------------------------------------------------------
    def _buffer(self, data: np.ndarray, usage: int, label: str) -> Any:
        buf = self.device.create_buffer_with_data(data=np.ascontiguousarray(data), usage=usage,
                                                  label=label)
        self._buffers.append(buf)
        return buf

    def _uniform(self, data: bytes, label: str) -> Any:
        buf = self.device.create_buffer(size=len(data), usage=wgpu.BufferUsage.UNIFORM |
                                        wgpu.BufferUsage.COPY_DST, label=label)
        self.device.queue.write_buffer(buf, 0, data)
        self._buffers.append(buf)
        return buf

    def _instances(self, *, prev: bool = False) -> Any:
        # one storage buffer, one 128-byte row per instance: bound once, written once (or,
        # where animations move instances, as each frame begins: begin_frame)
        check_instance_limits(self.scene, self.device.limits, INSTANCE_LIMIT_KEYS)
        placed = [*self.scene.instances, *self.scene.stroke_instances]
        rows = np.zeros((max(1, len(placed)), INSTANCE_BYTES // 4), np.float32)
        if placed:
            rows[:] = instance_blocks([i.transform for i in placed])
        usage = wgpu.BufferUsage.STORAGE
        if self.poses.moves:
            usage |= wgpu.BufferUsage.COPY_DST
        return self._buffer(rows, usage, "scene.prev_instances" if prev else "scene.instances")

    def _upload_meshes(self) -> None:
        v = wgpu.BufferUsage.VERTEX
        self.mirrored = mirrored_mask([i.transform for i in self.scene.instances]).tolist()
        used_mirrored = {i.mesh for i, m in zip(self.scene.instances, self.mirrored, strict=True)
                         if m}
        self.meshes = []
        self.mirrored_meshes: dict[int, tuple[list[Any], Any, int]] = {}
        for k, m in enumerate(self.scene.meshes):
            positions = self._buffer(m.positions.astype(np.float32), v, f"{m.name}.positions")
            normals = self._buffer(m.normals.astype(np.float32), v, f"{m.name}.normals")
            uvs = self._buffer(m.uvs.astype(np.float32), v, f"{m.name}.uvs")
            self.meshes.append((
                [positions, normals, uvs,
                 self._buffer(m.tangents.astype(np.float32), v, f"{m.name}.tangents")],
                self._buffer(m.indices.astype(np.uint32), wgpu.BufferUsage.INDEX,
                             f"{m.name}.indices"),
                len(m.indices)))
            if k in used_mirrored:
                indices, tangents = mirrored_arrays(m)
                self.mirrored_meshes[k] = (
                    [positions, normals, uvs,
                     self._buffer(tangents, v, f"{m.name}.tangents:mirrored")],
                    self._buffer(indices, wgpu.BufferUsage.INDEX, f"{m.name}.indices:mirrored"),
                    len(m.indices))

        # points and lines: the fourth stream is their COLOR_0 (mesh.glsl); nothing is made
        # for a scene without any
        self.strokes = [(
            [self._buffer(m.positions.astype(np.float32), v, f"{m.name}.positions"),
             self._buffer(m.normals.astype(np.float32), v, f"{m.name}.normals"),
             self._buffer(m.uvs.astype(np.float32), v, f"{m.name}.uvs"),
             self._buffer(m.colors.astype(np.float32), v, f"{m.name}.colors")],
            self._buffer(m.indices.astype(np.uint32), wgpu.BufferUsage.INDEX,
                         f"{m.name}.indices"),
            len(m.indices)) for m in self.scene.strokes]

    def _texture(self, pixels: np.ndarray, srgb: bool, label: str) -> Any:
        h, w = pixels.shape[:2]
        tex = self.device.create_texture(
            size=(w, h, 1), mip_level_count=max(w, h).bit_length(),
            format="rgba8unorm-srgb" if srgb else "rgba8unorm",
            usage=wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST, label=label)
        # in bands of rows, one level at a time, the queue flushed every TEXTURE_CHUNK:
        # write_texture stages its own copy until a submit, so unflushed writes of every
        # texture would all be held at once
        written = 0
        for k, lv in enumerate(mip_levels(pixels, srgb=srgb)):
            lh, lw = lv.shape[:2]
            step = max(1, TEXTURE_CHUNK // (4 * lw))
            for y in range(0, lh, step):
                band = np.ascontiguousarray(lv[y:y + step])
                self.device.queue.write_texture(
                    {"texture": tex, "mip_level": k, "origin": (0, y, 0)}, band,
                    {"bytes_per_row": 4 * lw, "rows_per_image": band.shape[0]},
                    (lw, band.shape[0], 1))
                written += band.nbytes
                if written >= TEXTURE_CHUNK:
                    wait_idle(self.device)
                    written = 0
        self._textures.append(tex)
        return tex.create_view()

    def _upload_textures(self) -> None:
        key = "max-texture-dimension-2d"
        self.textures = texture_views(self.scene, self.device.limits.get(key), key,
                                      lambda t: self._texture(t.pixels, t.srgb, t.name))
        self.samplers = [self.device.create_sampler(
            mag_filter=t.mag_filter, min_filter=t.min_filter,
            mipmap_filter=t.mipmap_filter, address_mode_u=t.address_u,
            address_mode_v=t.address_v, max_anisotropy=1) for t in self.scene.textures]
        self.default_sampler = self.device.create_sampler(
            mag_filter="linear", min_filter="linear", mipmap_filter="linear",
            address_mode_u="repeat", address_mode_v="repeat")
        one = np.full((1, 1, 4), 255, np.uint8)
        flat = np.array([[[128, 128, 255, 255]]], np.uint8)
        self.white = self._texture(one, False, "white")
        self.white_srgb = self._texture(one, True, "white_srgb")
        self.flat_normal = self._texture(flat, False, "flat_normal")

    def _lights_bytes(self) -> bytes:
        data, self.sun_matrix, self.default_light = lights_bytes(self.scene)
        return data

    # per frame ----------------------------------------------------------------------------
    def set_viewport(self, size: tuple[int, int]) -> None:
        self.size = size
        self._write_camera(*self.frames.still(self.camera, size))
        self.device.queue.write_buffer(self.sun_camera_buffer, 0,
                                       sun_camera_bytes(self.camera, self.sun_matrix, size))

    def begin_frame(self, index: int) -> None:
        """Frame ``index`` begins: the main camera as it sees it (jittered where a pass asks
        for jitter, ``frames.jitter``) and last frame's matrices (``CameraFrames``). Written
        through the queue, so frames submitted before keep theirs."""
        frame = self.frames.begin(self.camera, self.size, index)
        if frame is not None:
            self._write_camera(*frame)
        pose = self.poses.begin(index)  # None: nothing moves, or the frame has begun
        if pose is not None:
            self._write_rows(pose[1], pose[2])

    def _write_rows(self, rows: np.ndarray, prev: np.ndarray) -> None:
        """This frame's instance rows and last frame's, through the queue (frames submitted
        before keep theirs); the uniform copy of the rows too where one was made."""
        queue = self.device.queue
        queue.write_buffer(self.instance_buffer, 0, rows)
        queue.write_buffer(self.prev_instance_buffer, 0, prev)
        if self._instance_uniforms is not None:
            stride = self._uniform_rows()
            data = np.zeros((len(rows), stride), np.uint8)
            data[:, :INSTANCE_BYTES] = rows.view(np.uint8).reshape(len(rows), -1)
            queue.write_buffer(self._instance_uniforms, 0, data)

    def _write_camera(self, main: bytes, motion: bytes) -> None:
        last = self._camera_bytes
        if last is None or last[0] != main:
            self.device.queue.write_buffer(self.camera_buffer, 0, main)
        if last is None or last[1] != motion:
            self.device.queue.write_buffer(self.motion_buffer, 0, motion)
        self._camera_bytes = (main, motion)

    def bindings(self) -> dict[str, Any]:
        """The camera and lights (group 1) by name, and what a pass may bind in its own
        group: ``motion`` (motion.glsl's block) and ``prev_instances``, last frame's
        instance rows (the same rows where no animation moves them)."""
        return {"camera": {"buffer": self.camera_buffer},
                "lights": {"buffer": self.lights_buffer},
                "motion": {"buffer": self.motion_buffer},
                "prev_instances": {"buffer": self.prev_instance_buffer}}

    def _material_group(self, layout: Any, k: int) -> Any:
        key = ("material", id(layout), k)
        if key not in self._bind_cache:
            m = self.scene.materials[k]

            def tex(index: int | None, fallback: Any) -> Any:
                return self.textures[index] if index is not None else fallback

            sampler = self.samplers[m.base_color_texture] if m.base_color_texture is not None \
                else self.default_sampler
            ubuf = self._uniform(self.material_data[k], f"material{k}")
            entries = [{"binding": 0, "resource": {"buffer": ubuf}},
                       {"binding": 1, "resource": tex(m.base_color_texture, self.white_srgb)},
                       {"binding": 2, "resource": tex(m.metallic_roughness_texture, self.white)},
                       {"binding": 3, "resource": tex(m.normal_texture, self.flat_normal)},
                       {"binding": 4, "resource": tex(m.occlusion_texture, self.white)},
                       {"binding": 5, "resource": tex(m.emissive_texture, self.white_srgb)},
                       {"binding": 6, "resource": sampler}]
            self._bind_cache[key] = self.device.create_bind_group(layout=layout, entries=entries)
        return self._bind_cache[key]

    def _instance_group(self, layout: Any, k: int | None) -> Any:
        """(``k`` None) the group over every instance's row, or instance ``k``'s block as
        a uniform of its own (a WGSL program that declares one: a copy of the rows at the
        device's uniform offset alignment, made on first use)."""
        key = ("instance", id(layout), k)
        if key not in self._bind_cache:
            if k is None:
                resource = {"buffer": self.instance_buffer}
            else:
                stride = self._uniform_rows()
                resource = {"buffer": self._instance_uniforms, "offset": k * stride,
                            "size": INSTANCE_BYTES}
            self._bind_cache[key] = self.device.create_bind_group(
                layout=layout, entries=[{"binding": 0, "resource": resource}],
                label="scene.instances" if k is None else f"instance{k}")
        return self._bind_cache[key]

    def _uniform_rows(self) -> int:
        stride = align_up(INSTANCE_BYTES, self.device.limits["min-uniform-buffer-offset-alignment"])
        if self._instance_uniforms is None:
            placed = [*self.scene.instances, *self.scene.stroke_instances]
            rows = np.zeros((max(1, len(placed)), stride), np.uint8)
            if placed:
                blocks = self.poses.last_rows
                if blocks is None:
                    blocks = instance_blocks([i.transform for i in placed])
                rows[:, :INSTANCE_BYTES] = blocks.view(np.uint8)
            usage = wgpu.BufferUsage.UNIFORM
            if self.poses.moves:
                usage |= wgpu.BufferUsage.COPY_DST
            self._instance_uniforms = self._buffer(rows, usage, "scene.instances:uniform")
        return stride

    def _scene_group(self, layout: Any, camera: str) -> Any:
        key = ("scene", id(layout), camera)
        if key not in self._bind_cache:
            cam = self.sun_camera_buffer if camera == "sun" else self.camera_buffer
            self._bind_cache[key] = self.device.create_bind_group(
                layout=layout, entries=[{"binding": 0, "resource": {"buffer": cam}},
                                        {"binding": 1, "resource": {"buffer":
                                                                    self.lights_buffer}}])
        return self._bind_cache[key]

    def draw(self, rp: Any, prog: Any, pipeline: Any, *, camera: str = "main",
             group0: Any = None, alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
             dynamic: bool = True, topology: str = "triangle-list") -> int:
        """Draw every instance whose material's alpha mode is in ``alpha`` (into a render
        pass or a render bundle); returns draws. Each draw's first instance is the
        instance's index, which the shader reads its row by (``gl_InstanceIndex``).
        ``dynamic``: the program's group 3 is the scene's layout (``scene_layout_entries``);
        else (a WGSL program's own layout) a uniform instance block gets a group per
        instance, a storage one the shared group."""
        rp.set_pipeline(pipeline)
        if group0 is not None:
            rp.set_bind_group(0, group0)
        rp.set_bind_group(1, self._scene_group(prog.layouts[1], camera))
        shared = dynamic or _binds_storage(prog, 3)
        if shared:
            rp.set_bind_group(3, self._instance_group(prog.layouts[3], None))
        if topology != "triangle-list":
            return self._draw_strokes(rp, prog, topology, alpha, shared)
        draws = 0
        last_material = last_mesh = None
        for k, inst in enumerate(self.scene.instances):
            mesh = self.scene.meshes[inst.mesh]
            mat = self.scene.materials[mesh.material]
            if mat.alpha_mode not in alpha:
                continue
            # a mirrored instance draws its mesh with the winding (and tangent sign) reversed
            mirrored = self.mirrored[k]
            buffers, index, count = self.mirrored_meshes[inst.mesh] if mirrored \
                else self.meshes[inst.mesh]
            if mesh.material != last_material:
                rp.set_bind_group(2, self._material_group(prog.layouts[2], mesh.material))
                last_material = mesh.material
            if not shared:
                rp.set_bind_group(3, self._instance_group(prog.layouts[3], k))
            if (inst.mesh, mirrored) != last_mesh:
                for slot, buf in enumerate(buffers):
                    rp.set_vertex_buffer(slot, buf)
                rp.set_index_buffer(index, "uint32")
                last_mesh = (inst.mesh, mirrored)
            rp.draw_indexed(count, 1, 0, 0, k)
            draws += 1
        return draws

    def _draw_strokes(self, rp: Any, prog: Any, topology: str, alpha: tuple[str, ...],
                      shared: bool) -> int:
        """The stroke instances of ``topology`` (point-list or line-list); their rows
        follow the instances' in the instance buffer."""
        draws, base = 0, len(self.scene.instances)
        last_material = None
        for k, inst in enumerate(self.scene.stroke_instances):
            mesh = self.scene.strokes[inst.mesh]
            if mesh.topology != topology or \
                    self.scene.materials[mesh.material].alpha_mode not in alpha:
                continue
            buffers, index, count = self.strokes[inst.mesh]
            if mesh.material != last_material:
                rp.set_bind_group(2, self._material_group(prog.layouts[2], mesh.material))
                last_material = mesh.material
            if not shared:
                rp.set_bind_group(3, self._instance_group(prog.layouts[3], base + k))
            for slot, buf in enumerate(buffers):
                rp.set_vertex_buffer(slot, buf)
            rp.set_index_buffer(index, "uint32")
            rp.draw_indexed(count, 1, 0, 0, base + k)
            draws += 1
        return draws

    def destroy(self) -> None:
        for b in self._buffers:
            b.destroy()
        for t in self._textures:
            t.destroy()
        self._buffers.clear()
        self._textures.clear()
        self._bind_cache.clear()


def _binds_storage(prog: Any, group: int) -> bool:
    # a program's own layout: is its binding 0 of ``group`` a storage buffer?
    return any(b.group == group and b.binding == 0 and
               b.entry.get("buffer", {}).get("type", "uniform") != "uniform"
               for b in prog.bindings.values())


VERTEX_BUFFERS = [
    {"array_stride": 12, "attributes": [{"format": "float32x3", "offset": 0,
                                         "shader_location": 0}]},
    {"array_stride": 12, "attributes": [{"format": "float32x3", "offset": 0,
                                         "shader_location": 1}]},
    {"array_stride": 8, "attributes": [{"format": "float32x2", "offset": 0,
                                        "shader_location": 2}]},
    {"array_stride": 16, "attributes": [{"format": "float32x4", "offset": 0,
                                         "shader_location": 3}]},
]
