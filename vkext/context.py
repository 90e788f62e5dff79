"""The per-pass recording context on Vulkan: what ``Pass.record`` sees (slots by name,
dispatch, draw_scene, trace_rays); image descriptors are written in the layout the plan puts
the image in for the pass."""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rfw.authoring import MESH_SHADER
from rfw.context import check_topology, nothing_to_draw
from rfw.exec.context import ContextCore
from rfw.graph.formats import format_info
from rfw.passes import Pass, Settings
from rfw.settings_layout import check_bound_settings
from rfw.shaders import ShaderError, program_files
from rfw.spirv import DescriptorInfo, check_bindings

from .commands import image_layout, record_barriers
from .consts import const, ffi, lib, new
from .memory import Buffer, Image, ImageView
from .objects import BufferRange, Sampler, update_descriptors
from .programs import Program
from .render_pass import VkRenderPass, _record_op, _target_formats, _viewport

_COLOR_ATTACHMENT_LAYOUTS = {"COLOR_ATTACHMENT_OPTIMAL", "GENERAL", "ATTACHMENT_OPTIMAL"}
# a pass's program is looked up from memory between looks at its sources (hot reload):
# a replayed frame neither stats nor hashes shader files
RECHECK_S = 0.25
# per executor: what records look up each frame and that does not change between frames
# (programs by call, a step's planned barriers); dropped with the executor
_MEMOS: weakref.WeakKeyDictionary[Any, dict[tuple, Any]] = weakref.WeakKeyDictionary()


def _memo(executor: Any) -> dict[tuple, Any]:
    memo = _MEMOS.get(executor)
    if memo is None:
        memo = _MEMOS[executor] = {}
    return memo


@dataclass(frozen=True)
class ImageBinding:
    """An image slot bound to a descriptor: written in the layout the plan gives the image
    in the recording pass (sampled, storage and attachment alike)."""

    resource: str
    image: Image
    view: ImageView


def _check_storage_format(what: str, d: DescriptorInfo, view: ImageView, resource: str) -> None:
    """A storage image's declared format (``layout(rgba8)``) must be the view's: Vulkan
    leaves a mismatch undefined and no validation message reports it."""
    have = format_info(view.format)
    if d.format is None or have.vk is None or have.vk == d.format:
        return
    declared = format_info(d.format)
    raise ShaderError(f"{what} declared {declared.wgpu or declared.name} ({d.format}), but "
                      f"'{resource}' is {have.wgpu or have.name} ({have.vk})")


class VkPassContext(ContextCore):
    """What ``Pass.record`` sees on Vulkan: ``rfw.context.PassContext`` and
    ``RayTracingContext``, plus mesh programs (``program("mesh")``, ``render_pass``)."""

    # executor: the vkext.executor.VkExecutor recording the frame (it imports this module)
    def __init__(self, executor: Any, pass_: Pass, cmd: Any, slots: dict[str, str]):
        super().__init__(executor, pass_, slots)
        self._cmd = cmd  # None: the frame is replayed whole (vkext.executor) until used
        self.executed: Any = None  # the pass bundle executed, if that is all it recorded
        self.direct = False  # whether it recorded into the frame's command buffer itself
        self.device = executor.device
        self._rendering: VkRenderPass | None = None
        self._bound: list[Any] = []  # cached sets bound by this record (bundles keep them)
        self._memo = _memo(executor)
        self._pass_bundle: Any = None  # the bundle this record's commands go into (replay)
        self._primary: Any = None  # the pass's command buffer while they do
        self._used: list[Any] = []  # every cached set bound by this record

    _step = -1  # the declared step (Pass.steps) the pass is in

    @property
    def cmd(self) -> Any:
        """The command buffer the pass records into."""
        if self._pass_bundle is None:  # the frame's own: recorded (again) from here on
            self.direct = True
            self._primary_cmd()
        return self._cmd

    @cmd.setter
    def cmd(self, value: Any) -> None:
        self._cmd = value

    def step(self, index: int) -> None:
        """Enter step ``index`` of the pass's declared steps: record the barriers the plan
        puts before it, which order it after the earlier steps (the work inside one step is
        unordered: no barrier is recorded between its dispatches)."""
        key = ("step", self.pass_.name, index, self._step)
        barriers = self._memo.get(key)
        if barriers is None:
            barriers = self.executor.plan.barriers_before_step(self.pass_.name, index,
                                                               self._step)
            queues = self.executor.queues
            if queues is not None:  # as the pass's queue can record them
                barriers = queues.barriers_for(self.pass_.name, barriers)
            self._memo[key] = barriers
        record_barriers(self.cmd, barriers, self.executor.resources)
        self._step = index

    def can_replay(self) -> bool:
        """Whether this pass's commands may go into a bundle kept for a later frame
        (``rfw.exec.replay``: the executor asks before ``record``). Not without bundles
        (``RunOptions.bundles``) or under synchronization validation: the layer does not
        report hazards between two bundles (a broken plan's went unreported:
        test_schedule_fuzz), so there every pass records its commands into the frame. Nor
        for a pass on a compute-only queue family (async compute): bundles are the graphics
        family's."""
        ex = self.executor
        if ex.bundles is None or self.device.sync_validation:
            return False
        return ex.queues is None or self.pass_.name not in ex.queues.elsewhere

    def replayed(self, full: tuple) -> bool:
        """Execute again the bundle recorded for ``full`` (the pass's replay key, built
        before ``record``) and say so (True: ``record`` is not called). False: ``record``
        goes on, its commands recorded into a bundle kept under ``full``."""
        ex = self.executor
        slot = (self.pass_.name, -1)
        bundle = ex.bundles.find(slot, full)
        if bundle is not None and bundle.usable():
            for entry, data in bundle.writes:
                entry.write(data)
            if self._cmd is None and ex.replays(bundle):
                self.executed = bundle  # in the slot's command buffer already
                return True
            lib.vkCmdExecuteCommands(self._primary_cmd(), 1, bundle.handles)
            self.executed = bundle
            return True
        primary = self._primary_cmd()
        self._pass_bundle = ex.bundles.begin(slot, full)
        self._primary, self._cmd = primary, self._pass_bundle.cmd
        return False

    def _primary_cmd(self) -> Any:
        # the frame's command buffer for executing a bundle (not a direct use)
        if self._cmd is None:
            self._cmd = self.executor.catch_up()
            if self.executed is not None:  # replayed, then recorded more: executed here
                lib.vkCmdExecuteCommands(self._cmd, 1, self.executed.handles)
        return self._cmd

    # mesh shaders: a capability of passes that declare MESH_SHADER (rfw.authoring) ---------
    @property
    def meshlets(self) -> Any:
        """The scene's meshlets (``vkext.meshlet.MeshletScene``), for a pass that declares
        ``requires = (MESH_SHADER, ...)``."""
        from .meshlet import scene_of

        self._check_mesh_shader()
        return scene_of(self)

    def _check_mesh_shader(self) -> None:
        if MESH_SHADER not in self.pass_.requires:
            raise ShaderError(f"pass '{self.pass_.name}' draws meshlets but does not declare "
                              f"requires = ({MESH_SHADER!r},)")

    def draw_meshlets(self, *, color: Sequence[tuple[str, Any]],
                      depth: tuple[str, Any] | None, flags: int, phase: str,
                      freeze: bool = False, depth_compare: str = "less-equal",
                      cull: str = "back") -> int:
        """``vkext.meshlet.draw_meshlets`` into this pass's slots."""
        from .meshlet import draw_meshlets

        self._check_mesh_shader()
        return draw_meshlets(self, color=color, depth=depth, flags=flags, phase=phase,
                             freeze=freeze, depth_compare=depth_compare, cull=cull)

    def slot_objects(self) -> list[Any]:
        """The objects behind the pass's slots (history images swap between frames)."""
        ex = self.executor
        out = []
        for r in self.slots.values():
            obj = ex.images.get(r)
            out.append(obj if obj is not None else ex.buffers.get(r, ex.accels.get(r)))
        return out

    def _end_pass_bundle(self) -> None:
        """Close the bundle of this record's commands and execute it in the pass."""
        bundle, self._pass_bundle = self._pass_bundle, None
        self._cmd, self._primary = self._primary, None
        bundle.sets = list(dict.fromkeys(self._used))
        bundle.writes = [(e, list(e.data)) for e in bundle.sets]
        self.executor.bundles.end((self.pass_.name, -1), bundle)
        lib.vkCmdExecuteCommands(self._cmd, 1, bundle.handles)
        self.executed = bundle

    # resources ----------------------------------------------------------------------------
    def texture(self, slot: str) -> Image:
        return self.executor.image(self.resource(slot))

    def view(self, slot: str, *, mip: int | None = None) -> ImageBinding:
        """The slot's image view; ``mip``: a view of that one mip level only."""
        name = self.resource(slot)
        return ImageBinding(name, self.executor.image(name), self.executor.view(name, mip=mip))

    def sampled(self, slot: str) -> ImageBinding:
        name = self.resource(slot)
        return ImageBinding(name, self.executor.image(name),
                            self.executor.view(name, sampled=True))

    storage = view

    def accel(self, slot: str) -> Any:
        """The acceleration structures behind an ``AccelStructure`` slot (the
        ``vkext.accel.SceneAccel`` its builder published), to bind or to read mesh data of."""
        name = self.resource(slot)
        acc = self.executor.accels.get(name)
        if acc is None:
            raise ShaderError(f"pass '{self.pass_.name}': '{name}' has no acceleration "
                              "structure yet (its builder publishes one with set_accel)")
        return acc

    def set_accel(self, slot: str, accel: Any) -> None:
        """Publish the structures this pass builds for its ``AccelStructure`` output."""
        self.executor.accels[self.resource(slot)] = accel

    def build_accel(self, slot: str, accel: Any, *, update: bool = False) -> None:
        """Record the top-level build (``update``: a refit) of ``accel`` (a
        ``vkext.accel.SceneAccel``) in this pass and publish it for ``slot``; the plan's
        barriers order it against the frame's other builds and traces."""
        self.set_accel(slot, accel)
        accel.record_tlas(self.cmd, update=update)

    # recording ----------------------------------------------------------------------------
    def program(self, kind: str, *, shader: str | None = None,
                defines: dict[str, object] | None = None,
                stages: Sequence[str | Path] = ()) -> Program:
        """The pass's program of ``kind`` (compute | render | mesh | ray_tracing) from
        ``shader`` (default: the pass's) and the files of its other ``stages`` (names beside
        the pass, or paths; a name names files as ``rfw.shaders.program_files`` does): a
        mesh program is its mesh shader plus, in ``stages``, an optional task and fragment
        shader. Looked up from memory between looks at the sources (``RECHECK_S``)."""
        try:
            key = ("program", type(self.pass_), self.pass_.name, kind, shader,
                   tuple(sorted(defines.items())) if defines else (), tuple(stages))
            hit = self._memo.get(key)
        except TypeError:  # an unhashable define or stage: look it up every time
            return self._program(kind, shader, defines, stages)
        now = time.monotonic()
        if hit is not None and now - hit[1] < RECHECK_S:
            return hit[0]
        prog = self._program(kind, shader, defines, stages)
        self._memo[key] = (prog, now)
        return prog

    def _program(self, kind: str, shader: str | None, defines: dict[str, object] | None,
                 stages: Sequence[str | Path]) -> Program:
        if kind in ("compute", "render") and not stages:
            paths = self.executor.shader_paths(self.pass_, shader)
        else:
            paths = [p for n in (shader or self.pass_.shader, *stages)
                     for p in self._stage_paths(n)]
        return self.executor.programs.get(self.pass_, paths, defines or {}, kind)

    def _stage_paths(self, name: str | Path | None) -> list[Path]:
        name = self.shader_name(name)
        if isinstance(name, Path):
            if not name.is_file():
                raise ShaderError(f"pass '{self.pass_.name}': shader {name} not found")
            return [name]
        return program_files(self.pass_.folder(), name, owner=self.pass_.name)

    def _check_extra(self, prog: Program, values: dict[str, Any]) -> None:
        if not prog.descriptors.keys() >= values.keys():
            check_bindings(self.pass_.name, prog.name, prog.descriptors, values)

    def bind(self, prog: Program, values: dict[str, Any], point: int,
             sets: Sequence[int] | None = None) -> None:
        """Bind ``sets`` (default: every set of ``prog``), matching binding names to
        ``values``; the scene's own sets are bound as they are."""
        for s in prog.sets() if sets is None else sets:
            handle = self._set(prog, s, values)
            if handle is not None:
                lib.vkCmdBindDescriptorSets(self.cmd, point, prog.pipeline_layout.handle, s,
                                            1, handle, 0, ffi.NULL)

    _set_calls = 0  # own sets bound so far in this record: one SetCache call site each

    def _set(self, prog: Program, s: int, values: dict[str, Any]) -> Any:
        """``VkDescriptorSet[1]`` binding set ``s`` of ``prog`` to ``values`` (None: the set
        declares nothing): the scene's where it is one of them, else one written once and
        kept (``vkext.bundles.SetCache``), or without that cache one for this frame."""
        ex = self.executor
        wanted = prog.set_descriptors(s)
        if not wanted:
            return None
        if not all(d.name in values for d in wanted):
            check_bindings(self.pass_.name, prog.name, [d.name for d in wanted], values,
                           missing=True)
        for d in wanted:  # a Settings value's block: checked once per program and type
            check_bound_settings(prog, d.name, values[d.name], self.pass_.name)
        handle = self._scene_set(prog, s, values, wanted)
        if handle is not None:
            return handle
        if ex.sets is not None:
            slot = (self.pass_.name, self._set_calls)
            self._set_calls += 1
            entry = ex.sets.get(slot, prog.set_layouts[s], wanted, values,
                                lambda d, v: self._payload(prog, d, v), _owners)
            self._bound.append(entry)
            self._used.append(entry)
            return entry.handle
        entries = [(d.binding, d.kind, max(1, d.count)) for d in wanted]
        arr = ex.descriptors.allocate(prog.set_layouts[s], entries)
        update_descriptors(ex.device, [
            (arr[0], d.binding, d.kind, self._payload(prog, d, values[d.name]))
            for d in wanted])
        return arr

    def _scene_set(self, prog: Program, s: int, values: dict[str, Any],
                   wanted: list[DescriptorInfo]) -> Any:
        scene = self.scene
        if scene is None or s != 1 or s not in prog.scene_sets:
            return None
        lights = values.get("lights")
        for cam in ("main", "sun"):
            if values.get("camera") == scene.camera_range(cam) and \
                    lights in (None, scene.lights_range):
                return scene.camera_sets[cam]
        return None

    def _payload(self, prog: Program, d: DescriptorInfo, value: Any) -> tuple | list:
        ex, kind = self.executor, d.kind
        what = f"pass '{self.pass_.name}': binding '{d.name}' of {prog.name} is a {kind}"
        if isinstance(value, list):
            # an array binding: one payload per element, the last repeated to fill it
            if not value:
                raise ShaderError(f"{what} array, but the pass gives no element")
            items = [self._payload(prog, replace(d, count=1), v) for v in value]
            return (items + items[-1:] * d.count)[:d.count]
        if kind == "acceleration_structure":
            handle = getattr(getattr(value, "tlas", value), "handle", None)
            if handle is None:
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__} (give "
                                  "ctx.accel(slot), a SceneAccel or its tlas)")
            return (handle,)
        if kind in ("uniform_buffer", "storage_buffer"):
            if kind == "uniform_buffer" and isinstance(value, Settings):
                r = ex.ring.push(value.pack())
            elif kind == "uniform_buffer" and isinstance(value, bytes | bytearray | np.ndarray):
                data = value.tobytes() if isinstance(value, np.ndarray) else bytes(value)
                r = ex.ring.push(data)
            elif isinstance(value, BufferRange):
                r = value
            elif isinstance(value, Buffer):
                r = BufferRange(value.handle, 0, value.bytes)
            else:
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
            return (r.buffer, r.offset, r.size)
        if kind == "sampler":
            if not isinstance(value, Sampler):
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
            return (value.handle,)
        sampler = None
        if kind == "combined_image_sampler":
            if not (isinstance(value, tuple) and len(value) == 2
                    and isinstance(value[1], Sampler)):
                raise ShaderError(f"{what}: give (image, sampler), not "
                                  f"{type(value).__name__}")
            value, sampler = value
        if isinstance(value, ImageBinding):
            state = ex.state_in(self.pass_.name, value.resource)
            if state is None or state.layout is None:
                raise ShaderError(f"{what}, but '{value.resource}' is not a resource of "
                                  "this pass in the plan")
            layout = state.layout
            if kind == "storage_image" and layout != "GENERAL":
                raise ShaderError(f"{what}, but the plan has '{value.resource}' in {layout} "
                                  "in this pass (declare the slot as a storage output)")
            view, resource = value.view, value.resource
        elif isinstance(value, ImageView):
            layout = "GENERAL" if kind == "storage_image" else "SHADER_READ_ONLY_OPTIMAL"
            view, resource = value, value.image.label
        else:
            raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
        if kind == "storage_image":
            _check_storage_format(what, d, view, resource)
        payload = (view.handle, image_layout(layout))
        return (*payload, sampler.handle) if sampler is not None else payload

    def dispatch(self, *, threads: tuple[int, ...], shader: str | None = None,
                 entry: str = "main", defines: dict[str, object] | None = None,
                 push_constants: bytes | None = None, **bindings: Any) -> None:
        """Run a compute shader over ``threads`` (rounded up to whole workgroups)."""
        prog = self.program("compute", shader=shader, defines=defines)
        self._check_extra(prog, bindings)
        values = {**self.executor.scene_bindings(), **bindings}
        pipe = self.executor.programs.compute_pipeline(prog)
        point = const("VK_PIPELINE_BIND_POINT_COMPUTE")
        lib.vkCmdBindPipeline(self.cmd, point, pipe.handle)
        self.bind(prog, values, point)
        self._push(prog, push_constants)
        # no barrier here: dispatches of one step are unordered (rfw.passes), and a pass
        # whose dispatches depend on each other declares steps
        t = (*threads, 1, 1)[:3]
        lib.vkCmdDispatch(self.cmd, *(max(1, math.ceil(t[i] / prog.local_size[i]))
                                     for i in range(3)))

    def trace_rays(self, *, size: tuple[int, ...], shader: str | None = None,
                   miss: str | None = None, closest_hit: str | None = None,
                   any_hit: str | None = None, defines: dict[str, object] | None = None,
                   max_recursion: int = 1, push_constants: bytes | None = None,
                   **bindings: Any) -> None:
        """``vkCmdTraceRaysKHR`` over ``size`` launches: ``shader`` (default: the pass's) is
        the raygen shader, ``miss``/``closest_hit``/``any_hit`` the files of the other
        stages beside it; bindings as for ``dispatch`` (scene camera and lights by name)."""
        raygen = shader or self.pass_.shader
        names = [raygen, *(n for n in (miss, closest_hit, any_hit) if n)]
        paths = [self.executor.shader_paths(self.pass_, n)[0] for n in names]
        prog = self.executor.programs.get(self.pass_, paths, defines or {}, "ray_tracing")
        self._check_extra(prog, bindings)
        values = {**self.executor.scene_bindings(), **bindings}
        pipe = self.executor.programs.ray_pipeline(prog, max_recursion=max_recursion)
        point = const("VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR")
        lib.vkCmdBindPipeline(self.cmd, point, pipe.handle)
        self.bind(prog, values, point)
        self._push(prog, push_constants)
        pipe.sbt.trace(self.cmd, *(*size, 1, 1)[:3])

    def _push(self, prog: Program, data: bytes | None) -> None:
        if data is None:
            return
        self._check_push(prog, data)
        buf = ffi.new("char[]", bytes(data))
        lib.vkCmdPushConstants(self.cmd, prog.pipeline_layout.handle, prog.stage_flags, 0,
                               len(data), buf)

    def _check_push(self, prog: Program, data: bytes) -> None:
        if len(data) > prog.push_size:
            raise ShaderError(f"pass '{self.pass_.name}': {len(data)} bytes of push constants, "
                              f"{prog.name} declares {prog.push_size}")

    def draw_scene(self, *, color: Sequence[tuple[str, Any]] = (),
                   depth: tuple[str, Any] | None = None, shader: str | None = None,
                   defines: dict[str, object] | None = None, depth_compare: str = "less",
                   depth_write: bool = True, cull: str = "back", camera: str = "main",
                   blend: dict | None = None, alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
                   topology: str = "triangle-list", push_constants: bytes | None = None,
                   **bindings: Any) -> int:
        """Draw the scene's instances into ``color`` targets (and ``depth``) with dynamic
        rendering; set 0 takes ``bindings``, sets 1-3 are the scene's. Returns the draws.
        ``topology`` point-list or line-list draws the scene's strokes (nothing at all
        where it has none of that kind and nothing is cleared).

        The draws are recorded once into a bundle (``vkext.bundles``) and replayed while
        nothing they bake in changes; uniform values are rewritten each frame."""
        if self.scene is None:
            raise ShaderError(f"pass '{self.pass_.name}' draws the scene, but none is loaded")
        check_topology(self.pass_.name, topology)
        if nothing_to_draw(self.scene, topology, color, depth):
            return 0
        prog = self.program("render", shader=shader, defines=defines)
        self._check_extra(prog, {**bindings, "camera": 0, "lights": 0})
        if self.executor.bundles is None or self._pass_bundle is not None:  # inline
            with self.render_pass(color=color, depth=depth,
                                  depth_read_only=not depth_write) as rp:
                rp.use(prog, depth_compare=depth_compare, cull=cull, blend=blend,
                       topology=topology)
                rp.bind(**bindings)
                if push_constants is not None:
                    rp.push(push_constants)
                return self.scene.draw(self.cmd, prog.pipeline_layout.handle, camera=camera,
                                       alpha=alpha, topology=topology)
        colors, targets, dimage = self._targets(color, depth)
        first = (targets or [dimage])[0]
        pipe = self.executor.programs.graphics_pipeline(
            prog, **_target_formats(targets, dimage), samples=first.samples,
            depth_write=depth_write, depth_compare=depth_compare, cull=cull, blend=blend,
            topology=topology)
        if push_constants is not None:
            self._check_push(prog, push_constants)
        # the pass's own sets first: cached, with this frame's uniform values written
        self._bound = []
        own = [(s, h) for s in prog.sets() if s not in prog.scene_sets
               for h in [self._set(prog, s, bindings)] if h is not None]
        sets, self._bound = self._bound, []
        key = (pipe.handle, (first.width, first.height), camera, tuple(alpha),
               None if push_constants is None else bytes(push_constants),
               tuple((s, h[0]) for s, h in own), tuple(id(e) for e in sets), self.scene)
        slot = (self.pass_.name, self._draw_calls)
        self._draw_calls += 1
        bundle = self.executor.bundles.find(slot, key)
        if bundle is None:
            formats = _target_formats(targets, dimage)
            layout = prog.pipeline_layout.handle

            def fill(cmd: Any) -> int:
                _viewport(cmd, first.width, first.height)
                point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
                lib.vkCmdBindPipeline(cmd, point, pipe.handle)
                for s, handle in own:
                    lib.vkCmdBindDescriptorSets(cmd, point, layout, s, 1, handle, 0, ffi.NULL)
                if push_constants is not None:
                    buf = ffi.new("char[]", bytes(push_constants))
                    lib.vkCmdPushConstants(cmd, layout, prog.stage_flags, 0,
                                           len(push_constants), buf)
                return self.scene.draw(cmd, layout, camera=camera, alpha=alpha,
                                       topology=topology)

            bundle = self.executor.bundles.record(
                slot, key, colors=formats["colors"], depth=formats["depth"] or 0,
                stencil=formats["depth"] if formats["stencil"] else 0,
                samples=first.samples, fill=fill)
            bundle.sets = sets
        self._begin_rendering(colors, depth, depth_write, (first.width, first.height),
                              secondary=True)
        lib.vkCmdExecuteCommands(self.cmd, 1, bundle.handles)
        lib.vkCmdEndRendering(self.cmd)
        return bundle.draws

    _draw_calls = 0  # draw_scene and render_pass calls so far: one bundle call site each

    def render_pass(self, *, color: Sequence[tuple[str, Any]] = (),
                    depth: tuple[str, Any] | None = None,
                    depth_read_only: bool = False) -> VkRenderPass:
        """Begin dynamic rendering into ``color`` targets ([(slot, clear color or None to
        load)]) and ``depth`` ((slot, clear depth or None)); record into the returned
        :class:`VkRenderPass` and ``end()`` it (or use it as a ``with`` block)."""
        colors, targets, dimage = self._targets(color, depth)
        # begun at end(), around a bundle (inside a pass's bundle: recorded as it comes)
        if self.executor.bundles is not None and self._pass_bundle is None:
            self._rendering = VkRenderPass(self, targets, dimage, not depth_read_only,
                                           begin=(colors, depth))
            return self._rendering
        first = (targets or [dimage])[0]
        self._begin_rendering(colors, depth, not depth_read_only, (first.width, first.height))
        self._rendering = VkRenderPass(self, targets, dimage, not depth_read_only)
        return self._rendering

    def _execute(self, rp: VkRenderPass) -> None:
        """Begin the rendering of ``rp`` and execute the bundle of its commands: the one
        this call site recorded for the same commands, targets and scene, or a new one."""
        formats = _target_formats(rp.targets, rp.depth)
        key = ("render_pass", tuple(rp.ops), rp.extent, rp.samples, tuple(formats["colors"]),
               formats["depth"], formats["stencil"], tuple(id(e) for e in rp.sets), self.scene)
        slot = (self.pass_.name, self._draw_calls)
        self._draw_calls += 1
        bundle = self.executor.bundles.find(slot, key)
        if bundle is None:
            ops, device = rp.ops, self.device

            def fill(cmd: Any) -> int:
                _viewport(cmd, *rp.extent)
                for op in ops:
                    _record_op(cmd, op, device)
                return rp.draws

            bundle = self.executor.bundles.record(
                slot, key, colors=formats["colors"], depth=formats["depth"] or 0,
                stencil=formats["depth"] if formats["stencil"] else 0, samples=rp.samples,
                fill=fill)
            bundle.sets = rp.sets
        colors, depth = rp.begin
        self._begin_rendering(colors, depth, rp.depth_write, rp.extent, secondary=True)
        lib.vkCmdExecuteCommands(self.cmd, 1, bundle.handles)
        lib.vkCmdEndRendering(self.cmd)

    def _targets(self, color: Sequence[tuple[str, Any]], depth: tuple[str, Any] | None
                 ) -> tuple[list[tuple[str, Any]], list[Image], Image | None]:
        """The color targets as (resource, clear), their images and the depth image."""
        ex = self.executor
        colors = [(self.resource(slot), clear) for slot, clear in color]
        targets = [ex.image(r) for r, _ in colors]
        dimage = ex.image(self.resource(depth[0])) if depth is not None else None
        if not targets and dimage is None:
            raise ShaderError(f"pass '{self.pass_.name}': render_pass needs a color or depth "
                              "target")
        if self._rendering is not None and self._rendering.open:
            raise ShaderError(f"pass '{self.pass_.name}': render_pass while another is open "
                              "(end() it first)")
        return colors, targets, dimage

    def finish(self) -> None:
        """After ``record``: a render pass left open is ended, and named as an error."""
        left_open = self._rendering is not None and self._rendering.open
        if left_open:
            self._rendering.end()
        if self._pass_bundle is not None:
            self._end_pass_bundle()
        if left_open:
            raise ShaderError(f"pass '{self.pass_.name}' left a render pass open (end() it, "
                              "or begin it in a with block)")

    def _begin_rendering(self, colors: list[tuple[str, Any]], depth: tuple[str, Any] | None,
                         depth_write: bool, extent: tuple[int, int], *,
                         secondary: bool = False) -> None:
        """``vkCmdBeginRendering``; ``secondary``: its contents are a bundle's. The info is
        built once per pass, targets (their images: history ones swap) and clears."""
        ex = self.executor
        dname = None if depth is None else self.resource(depth[0])
        key = (self.pass_.name, tuple((n, _frozen(c), id(ex.images.get(n))) for n, c in colors),
               None if depth is None else (dname, _frozen(depth[1]), id(ex.images.get(dname))),
               depth_write, extent, secondary)
        made = ex.rendering_infos.get(key)
        if made is None:
            made = ex.rendering_infos[key] = self._rendering_info(colors, depth, depth_write,
                                                                  extent, secondary)
        lib.vkCmdBeginRendering(self.cmd, made[0])

    def _rendering_info(self, colors: list[tuple[str, Any]], depth: tuple[str, Any] | None,
                        depth_write: bool, extent: tuple[int, int], secondary: bool
                        ) -> tuple[Any, list[Any]]:
        """A ``VkRenderingInfo`` and the structs it points to (kept alive with it)."""
        ex = self.executor
        atts = new("VkRenderingAttachmentInfo", len(colors))
        for i, (name, clear) in enumerate(colors):
            layout = self._attachment_layout(name)
            if layout not in _COLOR_ATTACHMENT_LAYOUTS:
                raise ShaderError(f"pass '{self.pass_.name}': '{name}' is a color target, but "
                                  f"the plan has it in {layout} (declare an Attachment slot)")
            a = atts[i]
            a.imageView = ex.view(name).handle
            a.imageLayout = image_layout(layout)
            a.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD" if clear is None
                             else "VK_ATTACHMENT_LOAD_OP_CLEAR")
            a.storeOp = const("VK_ATTACHMENT_STORE_OP_STORE")
            if clear is not None:
                kind = format_info(ex.plan.resource(name).format).kind
                values = (*tuple(clear), 0, 0, 0, 0)[:4]
                for k in range(4):
                    if kind == "uint":
                        a.clearValue.color.uint32[k] = int(values[k])
                    elif kind == "sint":
                        a.clearValue.color.int32[k] = int(values[k])
                    else:
                        a.clearValue.color.float32[k] = float(values[k])
        info = new("VkRenderingInfo", layerCount=1, colorAttachmentCount=len(colors),
                   pColorAttachments=atts)
        if secondary:
            info.flags = const("VK_RENDERING_CONTENTS_SECONDARY_COMMAND_BUFFERS_BIT")
        info.renderArea.extent.width, info.renderArea.extent.height = extent
        keep = [atts]
        if depth is not None:
            name, clear = self.resource(depth[0]), depth[1]
            layout = self._attachment_layout(name)
            read_only = "READ_ONLY" in layout
            d = new("VkRenderingAttachmentInfo", imageView=ex.view(name).handle,
                    imageLayout=image_layout(layout))
            if read_only or (not depth_write and clear is None):
                d.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD")
                d.storeOp = const("VK_ATTACHMENT_STORE_OP_NONE" if read_only
                                  else "VK_ATTACHMENT_STORE_OP_STORE")
            else:
                d.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD" if clear is None
                                 else "VK_ATTACHMENT_LOAD_OP_CLEAR")
                d.storeOp = const("VK_ATTACHMENT_STORE_OP_STORE")
                d.clearValue.depthStencil.depth = float(clear or 0.0)
            info.pDepthAttachment = d
            if format_info(ex.plan.resource(name).format).stencil:
                info.pStencilAttachment = d
            keep.append(d)
        return info, keep

    def _attachment_layout(self, name: str) -> str:
        state = self.executor.state_in(self.pass_.name, name)
        if state is None or state.layout is None:
            raise ShaderError(f"pass '{self.pass_.name}': '{name}' is not a resource of this "
                              "pass in the plan")
        return state.layout


def _frozen(clear: Any) -> Any:
    """A clear value as a key: None, a number or a tuple of numbers."""
    return tuple(clear) if isinstance(clear, list | tuple) else clear


def _owners(value: Any) -> list[Any]:
    """The objects that keep a bound value's handles alive (``SetCache`` keys on them): an
    image binding's view, a sampler, a buffer, an acceleration structure and its TLAS; a
    ``BufferRange`` has none (its handle and range are the key)."""
    if isinstance(value, list | tuple):
        return [o for v in value for o in _owners(v)]
    if isinstance(value, BufferRange):
        return []
    if isinstance(value, ImageBinding):
        return [value.view]
    tlas = getattr(value, "tlas", None)
    return [value] if tlas is None else [value, tlas]
