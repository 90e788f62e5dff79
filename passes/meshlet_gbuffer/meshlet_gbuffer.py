"""G-buffer through task and mesh shaders: the gbuffer pass's outputs from meshlets."""

from rfw.authoring import (
    GBUFFER,
    MESH_SHADER,
    Attachment,
    Buffer,
    DepthAttachment,
    RenderPass,
    Settings,
    SettingsError,
    Storage,
    Texture,
    register_pass,
)

PHASES = ("single", "early", "late")


@register_pass("meshlet_gbuffer")
class MeshletGBufferPass(RenderPass):
    """The ``gbuffer`` pass's attachments, rasterised from meshlets (64 vertices, 124
    triangles; ``vkext.meshlet``). GPU-driven: a ``meshlet_cull`` pass of the same phase
    culls whole instances and writes one indirect command per instance (``commands``); per
    material one ``vkCmdDrawMeshTasksIndirectEXT`` launches task shaders that cull 32
    meshlets per workgroup (normal cone, bounding sphere against the frustum, and in the
    late phase the depth pyramid; all conservative), adding to ``counters`` and recording
    ``visibility`` (both in place); a mesh shader emits the survivors (optionally culling
    back-facing triangles) and ``passes/gbuffer/gbuffer.frag.glsl`` shades them unchanged.
    Vulkan only (``VK_EXT_mesh_shader``); every buffer is a graph resource, so the compiler
    plans every barrier. Bindings are reflected from the shaders.

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
    type = "mesh"
    requires = (MESH_SHADER,)
    backend = "vk"
    replay = "auto"
    inputs = {
        "commands": Buffer(usage=("indirect",), desc="indirect commands (meshlet_cull)"),
        "counters": Storage(desc="the frame's culling counters (added to)"),
        "visibility": Storage(desc="visibility words: read (early), recorded (single, late)"),
    }
    outputs = dict(GBUFFER)

    class Params(Settings):
        cone: bool = True  # cull meshlets whose normal cone faces away from the camera
        frustum: bool = True  # cull meshlets outside the frustum
        phase: str = "single"  # single | early | late (two-phase occlusion culling)
        triangles: bool = False  # cull back-facing triangles in the mesh shader
        colors: bool = False  # debug view: a color per meshlet as the albedo
        freeze: bool = False  # debug: keep culling from the camera the freeze began with

    def declare(self):
        if self.params.phase not in PHASES:
            raise SettingsError(f"{self.name}: setting 'phase' must be one of "
                                f"{', '.join(PHASES)}, got {self.params.phase!r}")
        if self.params.phase != "late":
            return dict(self.inputs), dict(self.outputs)
        # the early phase's G-buffer, loaded and drawn over in place, and the pyramid
        ins = {k: Attachment(desc=f"{k} of the early phase") for k in self.outputs
               if k != "depth"}
        ins["depth"] = DepthAttachment(None, desc="depth of the early phase")
        ins["pyramid"] = Texture(stages=("TASK_SHADER_EXT",),
                                 desc="max-depth pyramid of the early depth (depth_pyramid)")
        return {**self.inputs, **ins}, {}

    def replay_key(self, ctx):
        # and the culling camera
        return ctx.meshlets.cull_camera(self.params.freeze)

    def record(self, ctx) -> None:
        p = self.params
        phase = p.phase
        if p.freeze and phase != "single":
            if phase == "late":
                return  # frozen: no occlusion culling (the pyramid is the view's)
            phase = "single"
        late = phase == "late"
        clear = None if late else (0.0, 0.0, 0.0, 0.0)
        color = [(k, clear) for k in ("albedo", "normal", "material", "emissive")]
        # the cone test is the perspective one (apex to camera position): back faces only
        flags = ctx.meshlets.flags(cone=p.cone, frustum=p.frustum, occlusion=late,
                         triangles=p.triangles, colors=p.colors)
        ctx.draw_meshlets(color=color, depth=("depth", None if late else 1.0), flags=flags,
                      phase=phase, freeze=p.freeze, depth_compare="less-equal", cull="back")
