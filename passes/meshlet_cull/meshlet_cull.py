"""Meshlet instance culling: the indirect draws, counters and visibility of a meshlet
G-buffer pass, as graph buffers."""

from rfw.authoring import (
    MESH_SHADER,
    Buffer,
    ComputePass,
    Settings,
    SettingsError,
    Step,
    Storage,
    register_pass,
)

PHASES = ("single", "early", "late")
COUNTER_BYTES = 4 * 13  # shaders/common/meshlet.glsl's C_COUNT words
COMMAND_BYTES = 16  # one VkDrawMeshTasksIndirectEXT command, padded to a uvec4
# the blocks meshlet_cull.comp.glsl declares (its own and shaders/common/meshlet.glsl's)
_BLOCKS = ("commands", "counters", "visibility", "cull_camera", "instances", "draws")


@register_pass("meshlet_cull")
class MeshletCullPass(ComputePass):
    """Culls whole mesh instances against the frustum (their mesh's bounding sphere) and
    writes one ``VkDrawMeshTasksIndirectEXT`` command per instance into ``commands``, which
    a ``meshlet_gbuffer`` pass of the same phase draws from (``vkext.meshlet``). Every
    buffer is a graph resource, so the compiler plans each barrier: the indirect-command
    read, the task shaders' counter and visibility accesses, the next frame's clear.

    ``phase`` ``single`` or ``early`` (the first culling pass of a frame) also makes the
    frame's ``counters`` (cleared, then added to by every meshlet pass; read back by the
    executor into ``timings.json``'s ``culling``) and ``visibility``, one word per
    (instance, meshlet) that two-phase culling carries to the next frame: both persistent,
    never aliased, cleared on an executor's first frame. ``late`` takes both as in-place
    inputs. The single and late phases count the instances they cull and clear their
    visibility words; the early phase draws only what was visible last frame and counts
    nothing here.

    ``max_draws`` and ``max_meshlets`` size the buffers (a scene with more fails with the
    setting to raise); ``freeze`` keeps culling from the camera the freeze began with."""

    shader = "meshlet_cull.comp.glsl"
    requires = (MESH_SHADER,)
    backend = "vk"
    counts_meshlets = True  # vkext.meshlet finds the counters by this
    replay = "auto"

    class Params(Settings):
        frustum: bool = True  # cull instances outside the frustum
        phase: str = "single"  # single | early | late (two-phase occlusion culling)
        freeze: bool = False  # debug: keep culling from the camera the freeze began with
        max_draws: int = 65536  # instances drawn at most (16 bytes of commands each)
        max_meshlets: int = 1 << 20  # meshlets of all instances at most (4 bytes each)

    def declare(self):
        p = self.params
        if p.phase not in PHASES:
            raise SettingsError(f"{self.name}: setting 'phase' must be one of "
                                f"{', '.join(PHASES)}, got {p.phase!r}")
        for key in ("max_draws", "max_meshlets"):
            if not 1 <= getattr(p, key) <= 1 << 26:
                raise SettingsError(f"{self.name}: setting '{key}' must be in 1..{1 << 26}, "
                                    f"got {getattr(p, key)}")
        outs = {"commands": Buffer(COMMAND_BYTES * p.max_draws, usage=("storage",),
                                   desc="one indirect mesh-tasks command per instance")}
        if p.phase == "late":
            return {"counters": Storage(desc="the frame's culling counters (added to)"),
                    "visibility": Storage(desc="visibility words (culled instances cleared)")}, \
                outs
        outs["counters"] = Buffer(COUNTER_BYTES, usage=("storage",), external=True,
                                  desc="the frame's culling counters, read back after it")
        # load: the previous frame's visibility is read (the early phase draws by it)
        outs["visibility"] = Buffer(4 * p.max_meshlets, usage=("storage",), external=True,
                                    load="load", desc="one word per (instance, meshlet): "
                                    "visible at the end of the last frame")
        return {}, outs

    def steps(self) -> tuple[Step, ...]:
        if self.params.phase == "late":
            return ()
        # the clear, then the culling dispatch that counts and writes the commands: the
        # compiler plans the barrier between them
        return (Step("clear", writes=("counters", "visibility")),
                Step("cull", reads="counters", writes=("commands", "counters", "visibility")))

    def replay_key(self, ctx):
        # and the culling camera; the first frame's first phase also clears the visibility
        return (ctx.meshlets.cull_camera(self.params.freeze),
                ctx.frame == 0 and self.params.phase != "late")

    def record(self, ctx) -> None:
        ms = ctx.meshlets
        ms.check_capacity(ctx)
        p = self.params
        if p.freeze and p.phase == "late":
            return  # frozen: the late phase draws nothing (the pyramid is the view's)
        phase = "single" if p.freeze else p.phase
        camera = ms.cull_camera(p.freeze)
        bindings = {"commands": ctx.buffer("commands"), "counters": ctx.buffer("counters"),
                    "visibility": ctx.buffer("visibility"), "cull_camera": camera,
                    **ms.bindings()}
        bindings = {k: v for k, v in bindings.items() if k in _BLOCKS}
        if p.phase != "late":
            # nothing was visible before an executor's first frame
            words = ms.instance_meshlet_count if ctx.frame == 0 else 0
            ctx.step(0)
            ctx.dispatch(threads=(max(13, words),), defines={"CLEAR": 1},
                         push_constants=ms.push(0, phase, count=words), **bindings)
            ctx.step(1)
        ctx.dispatch(threads=(ms.draw_count,), push_constants=ms.push(
            ms.flags(frustum=p.frustum), phase), **bindings)
