"""``ctx.render_pass``'s dynamic rendering on Vulkan: :class:`VkRenderPass` collects a
pass's draws (a render or mesh program, its sets, push constants, draws), recorded into
the pass's command buffer or a bundle by :meth:`vkext.context.VkPassContext._execute`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rfw.shaders import ShaderError

from .consts import const, ffi, lib
from .memory import Buffer, Image
from .objects import BufferRange
from .programs import Program


def _target_formats(targets: list[Image], depth: Image | None) -> dict[str, Any]:
    """The formats a graphics pipeline (and a bundle continuing its rendering) is made for."""
    return {"colors": [t.vk_format for t in targets],
            "depth": depth.vk_format if depth is not None else None,
            "stencil": bool(depth is not None and depth.info.stencil)}


def _viewport(cmd: Any, width: int, height: int) -> None:
    """Viewport and scissor over the whole target."""
    vp = ffi.new("VkViewport*")
    # negative height: clip space is WebGPU's (y up) on both backends (scene.glsl)
    vp.y, vp.height = float(height), -float(height)
    vp.width, vp.maxDepth = float(width), 1.0
    sc = ffi.new("VkRect2D*")
    sc.extent.width, sc.extent.height = width, height
    lib.vkCmdSetViewport(cmd, 0, 1, vp)
    lib.vkCmdSetScissor(cmd, 0, 1, sc)


class VkRenderPass:
    """Dynamic rendering begun by ``ctx.render_pass``: ``use`` a render or mesh program
    (its pipeline for these targets), ``bind`` its own sets by binding name and the scene's
    with ``bind_scene``, ``push`` constants, draw; ``end`` ends the rendering.

    With the executor's bundles (the default), the commands are collected rather than
    recorded: ``end`` looks them up among the call site's bundles (``vkext.bundles``) and
    executes the one recorded for the same commands, recording it on a miss, so a frame
    that draws what the last one drew records no command per draw. Without them
    (``RFW_VK_BUNDLES=0``) every command goes straight into the pass's command buffer."""

    def __init__(self, ctx: Any, targets: list[Image], depth: Image | None,
                 depth_write: bool, *, begin: tuple | None = None):
        self.ctx, self.cmd = ctx, ctx.cmd
        self.targets, self.depth, self.depth_write = targets, depth, depth_write
        self.prog: Program | None = None
        self.point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
        self.open = True
        first = (targets or [depth])[0]
        self.extent = (first.width, first.height)
        self.samples = first.samples
        # begin: the (colors, depth) the rendering begins with at end(), around a bundle;
        # None: begun already, and every command is recorded as it comes
        self.begin = begin
        self.ops: list[tuple] | None = None if begin is None else []
        self.sets: list[Any] = []  # the cached sets the commands bind (a bundle keeps them)
        self.draws = 0
        if begin is None:
            _viewport(self.cmd, *self.extent)

    def __enter__(self) -> VkRenderPass:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.end()

    def _emit(self, op: tuple) -> None:
        if self.ops is None:
            _record_op(self.cmd, op, self.ctx.device)
        else:
            self.ops.append(op)

    def use(self, prog: Program, *, depth_compare: str = "less", cull: str = "back",
            blend: dict | None = None, topology: str = "triangle-list") -> None:
        """Bind ``prog``'s pipeline for this pass's targets (made once per state)."""
        if prog.kind not in ("render", "mesh"):
            raise ShaderError(f"pass '{self.ctx.pass_.name}': {prog.name} is a {prog.kind} "
                              "program; a render pass draws render or mesh programs")
        pipe = self.ctx.executor.programs.graphics_pipeline(
            prog, **_target_formats(self.targets, self.depth), samples=self.samples,
            depth_compare=depth_compare, depth_write=self.depth_write, cull=cull, blend=blend,
            topology=topology)
        self._emit(("pipeline", pipe.handle))
        self.prog = prog

    def _program(self) -> Program:
        if self.prog is None:
            raise ShaderError(f"pass '{self.ctx.pass_.name}': bind a program with use() first")
        return self.prog

    def bind(self, *, sets: Sequence[int] | None = None, **values: Any) -> None:
        """Bind the program's own sets (default: every set that is not the scene's),
        matching its binding names to ``values``."""
        prog, ctx = self._program(), self.ctx
        ctx._check_extra(prog, values)
        own = [s for s in prog.sets() if s not in prog.scene_sets] if sets is None else sets
        layout = prog.pipeline_layout.handle
        for s in own:
            start = len(ctx._bound)
            handle = ctx._set(prog, s, values)
            self.sets += ctx._bound[start:]
            if handle is not None:
                self._emit(("set", layout, s, handle))

    def bind_scene(self, *, camera: str = "main", material: int | None = None,
                   instance: int | None = None) -> None:
        """Bind the scene's camera set (1) and, where given, a material's (2) and an
        instance's (3)."""
        prog, scene = self._program(), self.ctx.scene
        if scene is None:
            raise ShaderError(f"pass '{self.ctx.pass_.name}' binds the scene, but none is "
                              "loaded")
        layout = prog.pipeline_layout.handle
        self._emit(("set", layout, 1, scene.camera_sets[camera]))
        if material is not None:
            self._emit(("set", layout, 2, scene.material_sets[material]))
        if instance is not None:
            self._emit(("set", layout, 3, scene.instance_sets[instance]))

    def push(self, data: bytes) -> None:
        """Push constants to every stage of the program."""
        prog = self._program()
        self.ctx._check_push(prog, data)
        self._emit(("push", prog.pipeline_layout.handle, prog.stage_flags, bytes(data)))

    def draw_mesh_tasks(self, x: int, y: int = 1, z: int = 1) -> None:
        """``vkCmdDrawMeshTasksEXT``: x * y * z task (or mesh) workgroups."""
        self._program()
        self.draws += 1
        self._emit(("tasks", int(x), int(y), int(z)))

    def draw_mesh_tasks_indirect(self, buffer: Buffer | BufferRange, *, offset: int = 0,
                                 count: int = 1, stride: int = 12) -> None:
        """``vkCmdDrawMeshTasksIndirectEXT`` of ``count`` commands (x, y, z: three uints
        each) ``stride`` bytes apart from ``offset`` in ``buffer`` (a buffer slot's)."""
        self._program()
        handle = buffer.buffer if isinstance(buffer, BufferRange) else buffer.handle
        base = buffer.offset if isinstance(buffer, BufferRange) else 0
        self.draws += 1
        self._emit(("tasks_indirect", handle, base + offset, int(count), int(stride)))

    def end(self) -> None:
        if not self.open:
            return
        self.open = False
        if self.ops is None:
            lib.vkCmdEndRendering(self.cmd)
        else:
            self.ctx._execute(self)


def _record_op(cmd: Any, op: tuple, device: Any) -> None:
    """Record one command a :class:`VkRenderPass` collected."""
    kind = op[0]
    point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
    if kind == "pipeline":
        lib.vkCmdBindPipeline(cmd, point, op[1])
    elif kind == "set":
        lib.vkCmdBindDescriptorSets(cmd, point, op[1], op[2], 1, op[3], 0, ffi.NULL)
    elif kind == "push":
        lib.vkCmdPushConstants(cmd, op[1], op[2], 0, len(op[3]), ffi.new("char[]", op[3]))
    elif kind == "tasks":
        device.fn.vkCmdDrawMeshTasksEXT(cmd, *op[1:])
    elif kind == "tasks_indirect":
        device.fn.vkCmdDrawMeshTasksIndirectEXT(cmd, *op[1:])
    else:  # a command kind added above without its recording
        raise ShaderError(f"render pass command '{kind}' has no recording")
