"""The geometry input of BLAS builds: a scene's triangles in device buffers.

All meshes' positions go in one buffer, all indices in another (texture coordinates in a
third, for shaders that shade what they hit). Builds read positions and indices through
device addresses; both stay after the build, readable by shaders (storage usage), with each
mesh's ranges in ``mesh_ranges``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.scene.model import Scene

from ..blocks import BlockAllocator
from ..commands import upload_buffer
from ..consts import const, new
from ..device import VkDevice

# builds read their geometry inputs as shader reads of the build stage (the spec's rule for
# vkCmdBuildAccelerationStructuresKHR): uploads leave the buffers visible to that
INPUT_READ = State(None, frozenset({"ACCELERATION_STRUCTURE_BUILD_KHR"}),
                   frozenset({"SHADER_READ"}))


class SceneGeometry:
    """Positions, indices and uvs of every mesh of ``scene``, uploaded once.

    ``mesh_ranges[m]`` is mesh ``m``'s (first vertex, vertex count, first index, index
    count); :meth:`geometry` describes its triangles to a build.
    """

    def __init__(self, device: VkDevice, scene: Scene, allocator: BlockAllocator, label: str):
        self.scene = scene
        self.mesh_ranges: list[tuple[int, int, int, int]] = []
        pos_parts, idx_parts, uv_parts = [], [], []
        v0 = i0 = 0
        for k, m in enumerate(scene.meshes):
            pos = np.ascontiguousarray(m.positions, np.float32).reshape(-1, 3)
            idx = np.ascontiguousarray(m.indices).reshape(-1)
            _check_indices(k, m.name, idx, len(pos))
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
        uvs = np.concatenate(uv_parts) if uv_parts else np.zeros((0, 2), np.float32)
        self.positions = allocator.create_buffer(max(16, positions.nbytes), usage,
                                                 label=f"{label}.positions")
        self.indices = allocator.create_buffer(max(16, indices.nbytes), usage,
                                               label=f"{label}.indices")
        # never built from: no acceleration_structure_input usage
        self.uvs = allocator.create_buffer(max(16, uvs.nbytes), ("storage", "transfer_dst"),
                                           label=f"{label}.uvs")
        for buf, data in ((self.positions, positions), (self.indices, indices),
                          (self.uvs, uvs)):
            if data.nbytes:
                upload_buffer(device, buf, data, INPUT_READ)

    def triangles(self, m: int) -> int:
        return self.mesh_ranges[m][3] // 3

    def geometry(self, m: int) -> Any:
        """Mesh ``m``'s triangles as a ``VkAccelerationStructureGeometryKHR``: opaque for
        OPAQUE materials (any-hit shaders never run), else one any-hit call per triangle."""
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


def _check_indices(k: int, name: str, idx: np.ndarray, vertices: int) -> None:
    if len(idx) % 3:
        raise ValueError(f"mesh {k} ('{name}'): {len(idx)} indices is not a multiple of 3")
    if len(idx) and (int(idx.min()) < 0 or int(idx.max()) >= vertices):
        raise ValueError(f"mesh {k} ('{name}'): indices outside its {vertices} vertices (a "
                         "build would read past the vertex buffer)")
