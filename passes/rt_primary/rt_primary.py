"""Primary rays: barycentrics and albedo of what each pixel sees, as in the talk's example."""

import numpy as np

from rfw.authoring import AccelStructure, RayTracedPass, Tex2D, register_pass

# the std430 twins of rt_primary.glsl's GpuMesh and GpuMaterial
MESH_DTYPE = np.dtype([("positions", "<u8"), ("uvs", "<u8"), ("indices", "<u8"),
                       ("material", "<u4"), ("pad", "<u4")])
MATERIAL_DTYPE = np.dtype([("base_color", "<f4", 4), ("texture", "<i4"), ("pad", "<i4", 3)])


@register_pass("rt_primary")
class RTPrimaryPass(RayTracedPass):
    """One camera ray per pixel: the barycentrics of the closest hit and its albedo.

    The talk's example. A closest-hit shader (or the ray query's committed intersection)
    reports the instance, the triangle, its barycentrics and object-to-world transform; the
    raygen shader then reads the triangle's indices, positions and uvs through buffer
    references (device addresses of the scene's own index and vertex buffers, in a mesh
    table reached from an instance -> mesh table) and samples the material's base color
    texture at the LOD of the talk: half the log2 of the ratio of the triangle's texel area
    to its screen area. ``barycentrics`` holds (b, c, 1 - b - c, 1) on a hit, zero on a
    miss; ``albedo`` the linear base color (alpha 1 on a hit).
    """

    shaders = {"ray_query": "rt_primary.comp.glsl", "ray_pipeline": "rt_primary.rgen.glsl"}
    miss = "rt_primary.rmiss.glsl"
    closest_hit = "rt_primary.rchit.glsl"
    inputs = {"tlas": AccelStructure(desc="the scene's acceleration structure")}
    outputs = {
        "barycentrics": Tex2D("rgba16float", desc="b, c, a of the closest hit; 0: a miss"),
        "albedo": Tex2D("rgba16float", desc="linear base color of the closest hit"),
    }

    def setup(self, ctx) -> None:
        """The scene's mesh, instance and material tables (host-visible storage buffers)."""
        scene = ctx.scene
        self.tables = None
        if scene is None:
            return
        meshes = np.zeros(max(1, len(scene.scene.meshes)), MESH_DTYPE)
        for k, m in enumerate(scene.scene.meshes):
            pos, _nor, uv, _tan, idx = scene.mesh_buffers[k]
            meshes[k] = (pos.address, uv.address, idx.address, m.material, 0)
        instances = np.array([i.mesh for i in scene.scene.instances] or [0], np.uint32)
        materials = np.zeros(max(1, len(scene.scene.materials)), MATERIAL_DTYPE)
        for k, m in enumerate(scene.scene.materials):
            tex = -1 if m.base_color_texture is None else m.base_color_texture
            materials[k] = (m.base_color, tex, (0, 0, 0))
        self.tables = {}
        for name, data in (("meshes", meshes), ("instances", instances),
                           ("materials", materials)):
            self.tables[name] = ctx.buffer(f"{self.name}:{name}", data)

    def record(self, ctx) -> None:
        scene = ctx.scene
        textures = list(scene.textures) or [scene.white_srgb]
        self.trace(ctx, ctx.extent("albedo"), defines={"MAX_TEXTURES": len(textures)}, tlas=ctx.accel("tlas"),
                   textures=textures, s_texture=scene.default_sampler,
                   o_barycentrics=ctx.storage("barycentrics"), o_albedo=ctx.storage("albedo"),
                   **self.tables)
