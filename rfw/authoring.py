"""Everything a pass may import: the pass-authoring API, in one module.

A pass in ``passes/<id>/<id>.py`` imports from here (and the standard library and numpy)
and from nowhere else: not a backend module, not vkext, not another pass. So a pass is
written once for every backend, and what it may rely on is listed here:

* the pass classes and settings (:mod:`rfw.passes`) and ``register_pass``;
* the slot and step types of the graph (:mod:`rfw.graph`) and format facts;
* what ``record(ctx)`` and ``setup(ctx)`` see, as protocols: :class:`PassContext` (every
  backend), :class:`RayTracingContext` and :class:`MeshShaderContext` (capabilities a pass
  declares in ``requires``), :class:`SetupContext`, and the typed scene views
  :class:`SceneView` / :class:`VkSceneView`;
* the scene tables passes that read the scene from a shader build (instance matrices,
  material factors, the tables of ``scene_tables``/``texture_lists`` that reach any
  triangle and its material, the visibility buffer's id split) and the G-buffer's layout, which
  several passes share.

Replay is declared, not called: a pass whose commands depend on nothing but its settings,
the resources behind its slots and the scene says ``replay = "auto"``; a ``replay_key(ctx)``
adds whatever else they depend on (meshlet culling's camera). The executor checks the key
before ``record`` and, where it can, executes again what the pass recorded for it
(:mod:`rfw.exec.replay`).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from .backends.scene_data import instance_blocks, material_bytes
from .context import TOPOLOGIES, PassContext, RayTracingContext
from .graph import (
    AccelStructure,
    Attachment,
    Buffer,
    DepthAttachment,
    History,
    Part,
    SizeRule,
    Slot,
    Step,
    Storage,
    Texture,
)
from .graph.errors import did_you_mean
from .graph.formats import format_info
from .passes import (
    ComputePass,
    DepthPrepassMixin,
    Pass,
    Range,
    RayTracedPass,
    RenderPass,
    Settings,
    SettingsError,
    Tex2D,
    storage_format,
)
from .registry import register_pass
from .scene.model import Scene, SceneError

__all__ = [
    "GBUFFER", "MESH_SHADER", "TOPOLOGIES", "AccelStructure", "Attachment", "Buffer",
    "ComputePass", "DepthAttachment", "DepthPrepassMixin", "History", "MeshShaderContext",
    "MeshletSceneView", "Part", "Pass", "PassContext", "Range", "RayTracedPass",
    "RayTracingContext", "RenderPass", "SceneError", "SceneView", "Settings",
    "SettingsError", "SetupContext", "SizeRule", "Slot", "Step", "Storage", "Tex2D",
    "Texture", "VkSceneView", "did_you_mean", "format_info", "instance_blocks",
    "material_bytes", "register_pass", "scene_table_bindings", "scene_tables", "storage_format", "texture_lists",
    "triangle_bits",
]

# what a pass that draws meshlets declares in ``requires`` (MeshShaderContext)
MESH_SHADER = "VK_EXT_mesh_shader"

# the G-buffer's attachments: what gbuffer and meshlet_gbuffer write (vis_resolve writes
# the same four colour outputs as storage images)
GBUFFER: dict[str, Slot] = {
    "albedo": Attachment("rgba8unorm-srgb", desc="base color (alpha: coverage)"),
    "normal": Attachment("rgba16float", desc="world-space normal"),
    "material": Attachment("rgba8unorm", desc="occlusion, roughness, metallic"),
    "emissive": Attachment("rgba16float", desc="emitted radiance"),
    "depth": DepthAttachment("depth32float", desc="0 near, 1 far"),
}


def triangle_bits(scene: Scene) -> int:
    """How many low bits of a visibility-buffer id hold the triangle: what the instances'
    index leaves of 32 bits. A scene whose instances and largest mesh do not fit raises a
    SceneError."""
    instance_bits = max(1, (len(scene.instances) - 1).bit_length())
    bits = 32 - instance_bits
    triangles = max((len(m.indices) // 3 for m in scene.meshes), default=0)
    if triangles > 1 << bits:
        raise SceneError(f"{len(scene.instances):,} instances and a mesh of {triangles:,} "
                         "triangles do not fit the visibility buffer's 32-bit ids "
                         f"({instance_bits} bits for the instance leave {bits} for the "
                         "triangle): use the raster G-buffer (geometry=raster)",
                         element="visbuffer")
    return bits


@runtime_checkable
class SceneView(Protocol):
    """The uploaded scene as a pass sees it (``ctx.scene``; None without a scene)."""

    scene: Scene  # the model: meshes, materials, instances, lights, cameras
    size: tuple[int, int]  # the viewport
    shadow_sampler: Any  # comparison sampler for shadow maps
    linear_sampler: Any
    default_sampler: Any
    textures: list[Any]  # the scene's images, in the model's texture order
    samplers: list[Any]
    white: Any  # the default textures a material without one binds
    white_srgb: Any
    flat_normal: Any
    mirrored: Any  # per instance: whether its transform mirrors (winding flips)

    def bindings(self) -> dict[str, Any]:
        """The scene's own bindings by name: camera and lights (group 1), and for a pass's
        own group ``motion`` (``shaders/common/motion.glsl``: last frame's camera) and
        ``prev_instances`` (last frame's instance rows)."""


@runtime_checkable
class VkSceneView(SceneView, Protocol):
    """What raw-Vulkan passes (``backend = "vk"``) also see: device addresses of the mesh
    streams and the acceleration structures."""

    mesh_buffers: list[Any]  # per mesh: positions, normals, uvs, tangents, indices
    camera_blob: bytes  # the cameras' bytes of the frame being recorded (camera paths move it)
    # the instances' rows of each frame where animations move them (the scene tables'
    # ``instances``), else None; ``poses.pose`` changes with the frame's transforms
    instance_table: Any
    poses: Any

    def accel(self, *, prefer: str | None = None, allow_update: bool = False,
              compact: bool = False) -> Any:
        """The scene's acceleration structures (built once, kept by the scene)."""


@runtime_checkable
class SetupContext(Protocol):
    """What ``Pass.setup(ctx)`` sees, once per executor: the scene and a way to make
    persistent buffers. Not the executor: a pass never reaches a backend's objects."""

    scene: SceneView | None
    caps: frozenset[str]  # the device's capabilities (Pass.requires names)

    def buffer(self, label: str, data: np.ndarray, *,
               usage: tuple[str, ...] = ("storage",)) -> Any:
        """A buffer holding ``data``, kept until the executor is destroyed."""


@runtime_checkable
class MeshletSceneView(Protocol):
    """The scene's meshlets (``ctx.meshlets``) for a pass that declares ``MESH_SHADER``."""

    draw_count: int  # drawn instances: one indirect command each
    instance_meshlet_count: int  # (instance, meshlet) pairs: one visibility word each

    def cull_camera(self, freeze: bool) -> Any:
        """The culling camera's buffer: the view's, or the one a freeze began with."""

    def bindings(self) -> dict[str, Any]:
        """The meshlet tables by binding name."""

    def push(self, flags: int, phase: str, *, draw_base: int = 0, count: int | None = None,
             viewport: tuple[int, int] = (0, 0)) -> bytes:
        """meshlet.glsl's push constants."""

    def flags(self, *, cone: bool = False, frustum: bool = False, occlusion: bool = False,
              triangles: bool = False, colors: bool = False) -> int:
        """meshlet.glsl's culling flags."""

    def check_capacity(self, ctx: Any) -> None:
        """A ShaderError naming the setting when the pass's buffers cannot hold the
        scene's commands or visibility words."""


@runtime_checkable
class MeshShaderContext(PassContext, Protocol):
    """A context on a device with task and mesh shaders, for a pass that declares
    ``requires = (MESH_SHADER, ...)``."""

    meshlets: MeshletSceneView

    def draw_meshlets(self, *, color: Any, depth: Any, flags: int, phase: str,
                      freeze: bool = False, depth_compare: str = "less-equal",
                      cull: str = "back") -> int:
        """Draw the scene's opaque and masked instances through the task and mesh
        shaders; returns the indirect draws recorded."""


# the std430 rows of the scene tables a shader reads any triangle's data and material from
# (shaders/common/scene_tables.glsl: SceneMesh, SceneInstance, SceneMaterial)
MESH_DTYPE = np.dtype([("addresses", "<u8", 5), ("material", "<u4"), ("pad", "<u4")])
INSTANCE_DTYPE = np.dtype([("matrices", "<f4", 32), ("mesh", "<u4", 4)])
MATERIAL_DTYPE = np.dtype([("factors", "u1", 64), ("textures", "<i4", 8)])


def texture_lists(scene: Any) -> tuple[list, list]:
    """The textures (the scene's, then its white, white sRGB and flat-normal defaults) and
    samplers (the scene's, then its default) that the material table indexes."""
    return ([*scene.textures, scene.white, scene.white_srgb, scene.flat_normal],
            [*scene.samplers, scene.default_sampler])


def scene_tables(vk_scene: Any) -> dict[str, np.ndarray]:
    """Per mesh its streams' device addresses and material; per instance its matrices, mesh
    and mirroring; per material its factors and texture and sampler slots (the ones the
    G-buffer binds: a missing texture is the default that ``VkScene`` binds in its place)."""
    scene = vk_scene.scene
    meshes = np.zeros(max(1, len(scene.meshes)), MESH_DTYPE)
    for k, m in enumerate(scene.meshes):
        meshes[k] = ([p.address for p in vk_scene.mesh_buffers[k]], m.material, 0)
    instances = np.zeros(max(1, len(scene.instances)), INSTANCE_DTYPE)
    if scene.instances:
        instances["matrices"] = instance_blocks([i.transform for i in scene.instances])
        instances["mesh"][:, 0] = [i.mesh for i in scene.instances]
        instances["mesh"][:, 1] = vk_scene.mirrored
    # texture_lists' order: the scene's textures, then white, white sRGB, flat normal; the
    # scene's samplers (one per texture), then the default
    n = len(scene.textures)
    white, white_srgb, flat, default_sampler = n, n + 1, n + 2, n
    materials = np.zeros(max(1, len(scene.materials)), MATERIAL_DTYPE)
    for k, m in enumerate(scene.materials):
        slots = [_or(m.base_color_texture, white_srgb), _or(m.metallic_roughness_texture, white),
                 _or(m.normal_texture, flat), _or(m.occlusion_texture, white),
                 _or(m.emissive_texture, white_srgb),
                 _or(m.base_color_texture, default_sampler), 0, 0]
        materials[k] = (np.frombuffer(material_bytes(m), np.uint8), slots)
    return {"meshes": meshes, "instances": instances, "materials": materials}


def scene_table_bindings(ctx: Any, label: str) -> tuple[dict[str, Any], dict[str, int]]:
    """What a shader that reaches any triangle binds (``scene_tables`` uploaded as storage
    buffers labelled ``label:<table>``, ``textures`` and ``samplers``), and the array sizes
    it is compiled with (``MAX_TEXTURES``, ``MAX_SAMPLERS``): for ``setup(ctx)``."""
    textures, samplers = texture_lists(ctx.scene)
    bindings = {name: ctx.buffer(f"{label}:{name}", data)
                for name, data in scene_tables(ctx.scene).items()}
    moving = getattr(ctx.scene, "instance_table", None)
    if moving is not None:  # animations move instances: the scene's rows of each frame
        bindings["instances"] = moving
    return ({**bindings, "textures": textures, "samplers": samplers},
            {"MAX_TEXTURES": len(textures), "MAX_SAMPLERS": len(samplers)})


def _or(index: int | None, fallback: int) -> int:
    return fallback if index is None else index

