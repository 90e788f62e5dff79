"""A ``Scene`` on the GPU: vertex and index buffers, materials, instances, camera, lights.

Layouts follow ``shaders/common/scene.glsl`` (group 1) and ``mesh.glsl`` (groups 2 and 3).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import wgpu

from ..scene.model import Camera, Scene, is_mirrored
from ..units import align_up
from .scene_data import (
    SCENE_GROUPS,
    instance_blocks,
    lights_bytes,
    main_camera_bytes,
    material_bytes,
    mip_chain,
    mirrored_arrays,
    sun_camera_bytes,
)

# wgpu layout entries of rfw.spirv's descriptor kinds (the scene's groups use these three)
_ENTRIES: dict[str, tuple[str, dict[str, str]]] = {
    "uniform_buffer": ("buffer", {"type": "uniform"}),
    "sampled_image": ("texture", {"sample_type": "float", "view_dimension": "2d"}),
    "sampler": ("sampler", {"type": "filtering"}),
}


INSTANCE_BYTES = 128  # mesh.glsl's InstanceBlock: model and normal matrices
# the scene's bindings moved by a dynamic offset per draw: every instance in one buffer
DYNAMIC = {(3, 0)}


def scene_layout_entries(group: int) -> list[dict]:
    """Bind group layout entries of a scene group, visible to every stage that may read it
    (the instance block with a dynamic offset: one bind group serves every instance)."""
    stages = wgpu.ShaderStage.VERTEX | wgpu.ShaderStage.FRAGMENT | wgpu.ShaderStage.COMPUTE
    out = []
    for _, binding, kind in SCENE_GROUPS[group]:
        key, layout = _ENTRIES[kind]
        entry = dict(layout) | ({"has_dynamic_offset": True} if (group, binding) in DYNAMIC
                                else {})
        out.append({"binding": binding, "visibility": stages, key: entry})
    return out


class GpuScene:
    def __init__(self, device: Any, scene: Scene, camera: Camera | None = None):
        self.device = device
        self.scene = scene = scene.drawable()  # singular transforms: skipped, with a warning
        self.camera = camera or scene.default_camera()
        self._buffers: list[Any] = []
        self._textures: list[Any] = []
        self._upload_meshes()
        self._upload_textures()
        self.material_data = [material_bytes(m) for m in scene.materials]
        self.instance_stride = align_up(
            INSTANCE_BYTES, device.limits["min-uniform-buffer-offset-alignment"])
        self.instance_buffer = self._instances()
        self.camera_buffer = self._uniform(b"\0" * 352, "scene.camera")
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

    def _instances(self) -> Any:
        # one buffer, one aligned block per instance: written once, bound once per draw list
        rows = np.zeros((max(1, len(self.scene.instances)), self.instance_stride), np.uint8)
        if self.scene.instances:
            blocks = instance_blocks([i.transform for i in self.scene.instances])
            rows[:len(blocks), :INSTANCE_BYTES] = blocks.view(np.uint8)
        return self._buffer(rows, wgpu.BufferUsage.UNIFORM, "scene.instances")

    def _upload_meshes(self) -> None:
        v = wgpu.BufferUsage.VERTEX
        self.mirrored = [is_mirrored(i.transform) for i in self.scene.instances]
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

    def _texture(self, pixels: np.ndarray, srgb: bool, label: str) -> Any:
        levels = mip_chain(pixels)
        tex = self.device.create_texture(
            size=(pixels.shape[1], pixels.shape[0], 1), mip_level_count=len(levels),
            format="rgba8unorm-srgb" if srgb else "rgba8unorm",
            usage=wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST, label=label)
        for k, lv in enumerate(levels):
            h, w = lv.shape[:2]
            self.device.queue.write_texture({"texture": tex, "mip_level": k},
                                            np.ascontiguousarray(lv),
                                            {"bytes_per_row": 4 * w}, (w, h, 1))
        self._textures.append(tex)
        return tex.create_view()

    def _upload_textures(self) -> None:
        self.textures = [self._texture(t.pixels, t.srgb, t.name) for t in self.scene.textures]
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
        q = self.device.queue
        q.write_buffer(self.camera_buffer, 0, main_camera_bytes(self.camera, size))
        q.write_buffer(self.sun_camera_buffer, 0,
                       sun_camera_bytes(self.camera, self.sun_matrix, size))

    def bindings(self) -> dict[str, Any]:
        return {"camera": {"buffer": self.camera_buffer},
                "lights": {"buffer": self.lights_buffer}}

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
        """Instance ``k``'s block, or (``k`` None) the group of a dynamic-offset layout
        that every instance shares."""
        key = ("instance", id(layout), k)
        if key not in self._bind_cache:
            offset = 0 if k is None else k * self.instance_stride
            self._bind_cache[key] = self.device.create_bind_group(
                layout=layout, entries=[{"binding": 0, "resource": {
                    "buffer": self.instance_buffer, "offset": offset, "size": INSTANCE_BYTES}}],
                label="scene.instances" if k is None else f"instance{k}")
        return self._bind_cache[key]

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
             dynamic: bool = True) -> int:
        """Draw every instance whose material's alpha mode is in ``alpha`` (into a render
        pass or a render bundle); returns draws. ``dynamic``: the program's group 3 is the
        scene's layout (``scene_layout_entries``), whose instance block takes an offset;
        else (a WGSL program's own layout) each instance gets a bind group of its own."""
        rp.set_pipeline(pipeline)
        if group0 is not None:
            rp.set_bind_group(0, group0)
        rp.set_bind_group(1, self._scene_group(prog.layouts[1], camera))
        shared = self._instance_group(prog.layouts[3], None) if dynamic else None
        draws = 0
        for k, inst in enumerate(self.scene.instances):
            mesh = self.scene.meshes[inst.mesh]
            mat = self.scene.materials[mesh.material]
            if mat.alpha_mode not in alpha:
                continue
            # a mirrored instance draws its mesh with the winding (and tangent sign) reversed
            buffers, index, count = self.mirrored_meshes[inst.mesh] if self.mirrored[k] \
                else self.meshes[inst.mesh]
            rp.set_bind_group(2, self._material_group(prog.layouts[2], mesh.material))
            if shared is not None:
                rp.set_bind_group(3, shared, [k * self.instance_stride])
            else:
                rp.set_bind_group(3, self._instance_group(prog.layouts[3], k))
            for slot, buf in enumerate(buffers):
                rp.set_vertex_buffer(slot, buf)
            rp.set_index_buffer(index, "uint32")
            rp.draw_indexed(count)
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
