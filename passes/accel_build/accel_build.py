"""Acceleration structures of the scene, for the passes that trace rays."""

from rfw.authoring import AccelStructure, Pass, Settings, register_pass


@register_pass("accel_build")
class AccelBuildPass(Pass):
    """The scene's BLAS (one per mesh) and TLAS (over its instances), for ray-traced passes.

    The BLAS are built once per scene, with ``prefer`` (``fast_trace``, ``fast_build`` or
    ``none``) and optionally ``compact``ed, and kept on the scene for every frame and graph
    that uses the same options. Each frame the pass rebuilds the TLAS from the instances'
    transforms or, with ``allow_update``, refits it in place, in a scratch buffer it keeps.
    Both are outputs, so the graph plans every barrier of the build: after the last frame's
    build (``scratch``, write after write) and traces (``tlas``, write after read), and
    before every pass that reads ``tlas``. ``timings.json`` reports the
    structures' counts, bytes (before and after compaction) and build times under ``accel``.
    Vulkan only (wgpu has no acceleration structures).
    """

    type = "compute"
    backend = "vk"
    requires = ("VK_KHR_acceleration_structure",)
    outputs = {"tlas": AccelStructure(desc="top-level acceleration structure of the scene"),
               "scratch": AccelStructure(desc="scratch memory of the TLAS builds, reused "
                                             "every frame (the scene's, like the structures)")}

    class Params(Settings):
        prefer: str = "fast_trace"  # fast_trace | fast_build | none
        allow_update: bool = False  # refit the TLAS each frame instead of rebuilding it
        compact: bool = False  # compact the BLAS after their build

    def setup(self, ctx) -> None:
        self.accel = None
        if ctx.scene is not None:
            self.accel = self._scene_accel(ctx.scene)

    def _scene_accel(self, scene):
        p = self.params
        prefer = None if p.prefer == "none" else p.prefer
        return scene.accel(prefer=prefer, allow_update=p.allow_update, compact=p.compact)

    def record(self, ctx) -> None:
        self.accel = self._scene_accel(ctx.scene)
        ctx.build_accel("tlas", self.accel, update=self.params.allow_update)
