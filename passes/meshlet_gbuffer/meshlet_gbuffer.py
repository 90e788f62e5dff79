"""G-buffer through task and mesh shaders: the gbuffer pass's outputs from meshlets."""

from passes.gbuffer.gbuffer import GBufferPass
from rfw import RenderPass, Settings, register_pass
from rfw.graph import Attachment, DepthAttachment, Texture
from rfw.passes import SettingsError

PHASES = ("single", "early", "late")


@register_pass("meshlet_gbuffer")
class MeshletGBufferPass(RenderPass):
    """The ``gbuffer`` pass's attachments, rasterised from meshlets (64 vertices, 124
    triangles; ``vkext.meshlet``). GPU-driven: a compute pass culls whole instances against
    the frustum and writes one indirect command per instance; per material one
    ``vkCmdDrawMeshTasksIndirectEXT`` launches task shaders that cull 32 meshlets per
    workgroup (normal cone, bounding sphere against the frustum, and in the late phase the
    depth pyramid; all conservative); a mesh shader emits the survivors (optionally culling
    back-facing triangles) and ``passes/gbuffer/gbuffer.frag.glsl`` shades them unchanged.
    Vulkan only (``VK_EXT_mesh_shader``). The counters are read through ``self.meshlets`` (a
    ``vkext.meshlet.MeshletScene``): ``counters()`` while the scene lives, ``last`` after.

    ``phase``: ``single`` (cone and frustum culling in one pass) or two-phase occlusion
    culling as two instances of this pass with a ``depth_pyramid`` between them:
    ``early`` draws what was visible at the end of the last frame (and declares the
    G-buffer, cleared), ``late`` takes the G-buffer as in-place inputs plus this frame's
    ``pyramid`` of the early depth, tests every meshlet against it, draws the newly visible
    and records visibility for the next frame (``configs/meshlet.toml``). The first frame's
    early phase draws nothing; the late phase then draws everything in view.

    Debug: ``colors`` writes a color per meshlet as the albedo; ``freeze`` keeps culling
    from the camera of the frame the freeze began while the view moves (then the late phase
    draws nothing and the early phase culls as ``single``: the pyramid is the view's)."""

    shader = "meshlet_gbuffer.mesh.glsl"
    requires = ("VK_EXT_mesh_shader",)
    backend = "vk"
    outputs = dict(GBufferPass.outputs)

    class Params(Settings):
        cone: bool = True  # cull meshlets whose normal cone faces away from the camera
        frustum: bool = True  # cull instances and meshlets outside the frustum
        phase: str = "single"  # single | early | late (two-phase occlusion culling)
        triangles: bool = False  # cull back-facing triangles in the mesh shader
        colors: bool = False  # debug view: a color per meshlet as the albedo
        freeze: bool = False  # debug: keep culling from the camera the freeze began with

    def declare(self):
        if self.params.phase not in PHASES:
            raise SettingsError(f"{self.name}: setting 'phase' must be one of "
                                f"{', '.join(PHASES)}, got {self.params.phase!r}")
        if self.params.phase != "late":
            return {}, dict(self.outputs)
        # the early phase's G-buffer, loaded and drawn over in place, and the pyramid
        ins = {k: Attachment(desc=f"{k} of the early phase") for k in self.outputs
               if k != "depth"}
        ins["depth"] = DepthAttachment(None, desc="depth of the early phase")
        ins["pyramid"] = Texture(stages=("TASK_SHADER_EXT",),
                                 desc="max-depth pyramid of the early depth (depth_pyramid)")
        return ins, {}

    def record(self, ctx) -> None:
        from vkext.executor import ImageBinding
        from vkext.meshlet import draw_meshlets, meshlet_scene

        self.meshlets = meshlet_scene(ctx.scene) if ctx.scene is not None else None
        p = self.params
        late = p.phase == "late"
        clear = None if late else (0.0, 0.0, 0.0, 0.0)
        color = [(k, clear) for k in ("albedo", "normal", "material", "emissive")]
        pyramid = None
        if late:
            name = ctx.resource("pyramid")
            pyramid = ImageBinding(name, ctx.executor.image(name), ctx.executor.view(name))
        draw_meshlets(ctx, color=color, depth=("depth", None if late else 1.0), cone=p.cone,
                      frustum=p.frustum, phase=p.phase, pyramid=pyramid,
                      triangles=p.triangles, colors=p.colors, freeze=p.freeze,
                      depth_compare="less-equal")
