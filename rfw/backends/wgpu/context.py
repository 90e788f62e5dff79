"""The per-pass recording context: what ``Pass.record`` sees on wgpu.

A frame costs no Python per draw: a pass's scene draws are recorded once into a render
bundle and replayed while its pipeline, bind groups, scene and formats stay the same; bind
groups are made once per set of bound objects, and settings reach the replayed draws through
their uniform buffers, written when their bytes change (``benchmarks/bench_record.py``).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ...context import check_topology, nothing_to_draw
from ...exec.context import ContextCore
from ...graph.formats import format_info
from ...passes import Pass, Settings
from ...settings_layout import check_bound_settings
from ...shaders import ShaderError, program_files
from ...spirv import check_bindings
from ..scene_data import SCENE_GROUPS
from .programs import RECHECK_S, Binding, Program, _stamps
from .scene import VERTEX_BUFFERS


def _defines_key(defines: dict[str, object] | None) -> tuple:
    return tuple(sorted(defines.items())) if defines else ()


def _same_call(hit: tuple | None, call: tuple, bindings: dict[str, Any]) -> tuple | None:
    """``hit`` when it was found for ``call`` with the same bindings: the same names and
    the very same objects (values given as data, settings or bytes, may differ: they are
    written each frame)."""
    if hit is None or hit[0] != call or hit[1] != tuple(bindings):
        return None
    for old, new in zip(hit[2], bindings.values(), strict=True):
        if old is not new and not isinstance(new, Settings | bytes | np.ndarray):
            return None
    return hit


class PassContext(ContextCore):
    """What ``Pass.record`` sees: its resources by slot name and ways to record work."""

    # executor: the .executor.Executor recording the frame (it imports this module)
    def __init__(self, executor: Any, pass_: Pass, encoder: Any, slots: dict[str, str]):
        super().__init__(executor, pass_, slots)
        self.encoder = encoder
        self.device = executor.device.device

    # resources ----------------------------------------------------------------------------
    def texture(self, slot: str) -> Any:
        return self.executor.texture(self.resource(slot))

    def view(self, slot: str, *, mip: int | None = None) -> Any:
        """The slot's texture view; ``mip``: a view of that one mip level only."""
        return self.executor.view(self.resource(slot), mip=mip)

    def sampled(self, slot: str) -> Any:
        return self.executor.view(self.resource(slot))

    storage = view

    _step = -1  # the declared step (Pass.steps) the pass is in
    _bundles = 0  # scene draws recorded by this pass so far in this frame

    def step(self, index: int) -> None:
        """Enter step ``index`` of the pass's declared steps: wgpu orders a pass's work
        itself, so nothing is recorded; the order is checked as on Vulkan."""
        self.executor.plan.barriers_before_step(self.pass_.name, index, self._step)
        self._step = index

    # recording ----------------------------------------------------------------------------
    def _timestamps(self) -> dict | None:
        return self.executor.timestamp_writes(self.pass_.name)

    def program(self, kind: str, *, shader: str | None = None,
                defines: dict[str, object] | None = None,
                formats: dict[str, str] | None = None) -> Program:
        """The pass's program (``kind``: compute | render) of ``shader`` (default: the
        pass's), its files found by ``rfw.shaders.program_files``."""
        name = self.shader_name(shader)
        defines, formats = defines or {}, formats or {}

        def make() -> Program:
            paths = program_files(self.pass_.folder(), name, owner=self.pass_.name)
            return self.executor.shaders.program(paths, defines, kind, formats,
                                                 owner=self.pass_.name)

        # keys are unique, so sorting never compares the values
        key = (type(self.pass_), self.pass_.name, name, kind, tuple(sorted(defines.items())),
               tuple(sorted(formats.items())))
        return self.executor.shaders.recent(key, make)

    def bind(self, prog: Program, values: dict[str, Any], *, groups: tuple[int, ...] = (0,),
             cache_key: Any = None) -> list[Any]:
        """Bind groups for ``groups``, matching binding names in the shader to ``values``."""
        out = []
        for g in groups:
            wanted = [b for b in prog.bindings.values() if b.group == g]
            if prog.layouts[g] is self.executor.shaders.scene_layouts.get(g):
                # the scene's layout: every binding of the scene's group, used or not
                wanted = [Binding(n, g, k, {}) for n, k, _ in SCENE_GROUPS[g]]
            check_bindings(self.pass_.name, prog.name, [b.name for b in wanted], values,
                           missing=True)
            for b in wanted:
                self._check_format(prog, b, values[b.name])
                check_bound_settings(prog, b.name, values[b.name], self.pass_.name)
            # a uniform's bytes are written here, every frame, into the same buffer
            resources = [(b.binding, self.executor.as_resource(values[b.name], b, self.pass_))
                         for b in wanted]
            out.append(self.executor.bind_group(prog.layouts[g], resources,
                                                label=f"{self.pass_.name}:g{g}"))
        return out

    def _check_format(self, prog: Program, b: Binding, value: Any) -> None:
        # up front: wgpu reports a mismatch late, as its own validation error
        have = self.executor.format_of(value)
        if have is None:
            return
        if b.storage_format is not None:
            if have == b.storage_format:
                return
            want = f"storage texture declared {b.storage_format}"
        elif b.depth and not format_info(have).depth:
            want = "depth texture (a depth format)"
        else:
            return
        name = getattr(value, "label", "") or "the texture"  # views are labelled by resource
        hint = " (depth made on another backend arrives as r32float)" if "@" in name else ""
        raise ShaderError(f"pass '{self.pass_.name}': binding '{b.name}' ({b.where}) is a "
                          f"{want}, but '{name}' is {have}{hint}")

    _dispatches = 0  # dispatches recorded by this pass so far in this frame

    def dispatch(self, *, threads: tuple[int, ...], shader: str | None = None,
                 entry: str = "main", defines: dict[str, object] | None = None,
                 **bindings: Any) -> None:
        """Run a compute shader over ``threads`` (rounded up to whole workgroups).

        Per call site (the pass's n-th dispatch) the program, pipeline and bind groups are
        kept with what they were found for: a frame that binds the same objects with the
        same shader, defines and threads looks none of them up again (uniform values are
        still written, where their bytes changed)."""
        site = (self.pass_.name, self._dispatches)
        self._dispatches += 1
        call = (shader, entry, _defines_key(defines), tuple(threads), self.scene)
        sites = self.executor.call_sites
        hit = self._site_hit(sites.get(site), call, bindings)
        if hit is not None:
            prog, pipe, bgs, groups = hit[3]
        else:
            prog, pipe, bgs, groups = self._dispatch_state(threads, shader, entry, defines,
                                                           bindings)
            sites[site] = (call, tuple(bindings), tuple(bindings.values()),
                           (prog, pipe, bgs, groups), self._uniform_slots(prog, bindings),
                           [time.monotonic()])
        self.executor.calls.dispatch(self.encoder, self.pass_.name, self._timestamps(), pipe,
                                     bgs, groups)

    def _uniform_slots(self, prog: Program, bindings: dict[str, Any]) -> list[tuple]:
        """The bindings given as data (settings, bytes) with the buffers they went into."""
        ex, out = self.executor, []
        for name, value in bindings.items():
            if isinstance(value, Settings | bytes | np.ndarray):
                b = prog.bindings[name]
                out.append((name, b, ex.as_resource(value, b, self.pass_)["buffer"]))
        return out

    def _site_hit(self, hit: tuple | None, call: tuple, bindings: dict[str, Any]
                  ) -> tuple | None:
        """``hit`` (a call site's last call and what it found) when it holds for this
        call: the same call and bound objects, its program still the cache's and looked up
        less than ``RECHECK_S`` ago (hot reload), and this frame's uniform values fit their
        buffers (they are written here)."""
        hit = _same_call(hit, call, bindings)
        if hit is None:
            return None
        prog = hit[3][0]
        if self.executor.shaders.programs.get(prog.key) is not prog:
            return None
        now = time.monotonic()
        if now - hit[5][0] >= RECHECK_S:
            # the sources are looked at again: unchanged, they keep the program (a stat per
            # file, not the program's whole lookup)
            stamps = getattr(prog, "stamps", None)
            if stamps is None or _stamps(p for p, _, _ in stamps) != stamps:
                return None
            hit[5][0] = now
        return hit if self._uniforms_fit(hit, bindings) else None

    def _uniforms_fit(self, hit: tuple, bindings: dict[str, Any]) -> bool:
        """Write this frame's uniform values; False where one needed a new buffer (its
        bind group is made again)."""
        ex = self.executor
        for name, b, buf in hit[4]:
            if ex.as_resource(bindings[name], b, self.pass_)["buffer"] is not buf:
                return False
        return True

    def _dispatch_state(self, threads: tuple[int, ...], shader: str | None, entry: str,
                        defines: dict[str, object] | None, bindings: dict[str, Any]
                        ) -> tuple[Program, Any, list[Any], tuple[int, ...]]:
        """The program, pipeline, bind groups and workgroups of a dispatch."""
        formats = {k: self.executor.format_of(v) for k, v in bindings.items()}
        prog = self.program("compute", shader=shader, defines=defines,
                            formats={k: v for k, v in formats.items() if v})
        check_bindings(self.pass_.name, prog.name, prog.bindings, bindings)
        values = {**self.executor.scene_bindings(), **bindings}
        groups = tuple(range(len(prog.layouts)))
        bgs = self.bind(prog, values, groups=groups)
        module, main = prog.stages["comp"]
        entry = main if entry == "main" else entry  # WGSL may name another entry point
        pipe = prog.pipelines.get(entry)
        if pipe is None:
            pipe = prog.pipelines[entry] = self.device.create_compute_pipeline(
                layout=prog.pipeline_layout, compute={"module": module, "entry_point": entry},
                label=f"{self.pass_.name}:{entry}")
        t = (*threads, 1, 1)[:3]
        return prog, pipe, bgs, tuple(max(1, math.ceil(t[i] / prog.workgroup[i]))
                                      for i in range(3))

    def draw_scene(self, *, color: list[tuple[str, Any]] = (), depth: tuple[str, Any] | None = None,
                   shader: str | None = None, defines: dict[str, object] | None = None,
                   depth_compare: str = "less", depth_write: bool = True,
                   cull: str = "back", camera: str = "main",
                   blend: dict | None = None, alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
                   topology: str = "triangle-list", **bindings: Any) -> int:
        """Draw the scene's instances into ``color`` targets (and ``depth``) with the pass's
        ``vs_main``/``fs_main``; group 0 takes ``bindings``. Returns the number of draws.
        ``topology`` point-list or line-list draws the scene's strokes instead (nothing at
        all, no pass begun, where it has none of that kind and nothing is cleared).

        The draws are recorded once into a render bundle and replayed; per call site (the
        pass's n-th scene draw) the program, pipeline and group 0 are kept with what they
        were found for, so a frame that draws as the last one did looks none of them up."""
        if self.scene is None:
            raise ShaderError(f"pass '{self.pass_.name}' draws the scene, but none is loaded")
        check_topology(self.pass_.name, topology)
        if nothing_to_draw(self.scene, topology, color, depth):
            return 0
        site = (self.pass_.name, "scene", self._bundles)
        call = (tuple(color), depth, shader, _defines_key(defines), depth_compare,
                depth_write, cull, camera, repr(blend), tuple(alpha), topology, self.scene)
        sites = self.executor.call_sites
        hit = self._site_hit(sites.get(site), call, bindings)
        if hit is not None:
            prog, pipe, group0, targets, dfmt = hit[3]
        else:
            prog, pipe, group0, targets, dfmt = self._scene_state(
                color, depth, shader, defines, depth_compare, depth_write, cull, blend, bindings,
                topology)
            sites[site] = (call, tuple(bindings), tuple(bindings.values()),
                           (prog, pipe, group0, targets, dfmt),
                           self._uniform_slots(prog, bindings), [time.monotonic()])
        read_only = depth is not None and not depth_write
        # the draws are recorded once into a bundle and replayed while nothing they name
        # changes: per-frame data (camera, lights, settings) reaches them through buffers
        key = (pipe, group0, self.scene, camera, tuple(alpha), targets, dfmt, read_only)
        bundle, n = self.executor.bundle(
            (self.pass_.name, self._bundles), key, lambda enc: self.scene.draw(
                enc, prog, pipe, camera=camera, group0=group0, alpha=alpha,
                dynamic=prog.layouts[3] is self.executor.shaders.scene_layouts.get(3),
                topology=topology),
            color_formats=targets, depth_format=dfmt, depth_read_only=read_only)
        self._bundles += 1
        self.executor.calls.bundles(self.encoder, self.pass_.name,
                                    *self._attachments(color, depth, read_only),
                                    self._timestamps(), (bundle,))
        return n

    def _scene_state(self, color: list[tuple[str, Any]], depth: tuple[str, Any] | None,
                     shader: str | None, defines: dict[str, object] | None,
                     depth_compare: str, depth_write: bool, cull: str, blend: dict | None,
                     bindings: dict[str, Any], topology: str = "triangle-list") -> tuple:
        """The program, pipeline, group 0 and target formats of a scene draw."""
        formats = {k: self.executor.format_of(v) for k, v in bindings.items()}
        prog = self.program("render", shader=shader, defines=defines,
                            formats={k: v for k, v in formats.items() if v})
        check_bindings(self.pass_.name, prog.name, [*prog.bindings, "camera", "lights"],
                       bindings)
        if len(prog.layouts) != 4:  # wgpu-native aborts on a bundle that leaves one unset
            raise ShaderError(f"pass '{self.pass_.name}': {prog.name} declares groups 0-"
                              f"{len(prog.layouts) - 1}: a scene draw binds groups 0 (the "
                              "pass's) to 3 (the scene's), each declared")
        targets = tuple(self.format(slot) for slot, _ in color)
        dfmt = self.format(depth[0]) if depth is not None else None
        key = ("scene", targets, dfmt, depth_compare, depth_write, cull, str(blend), topology)
        pipe = prog.pipelines.get(key)
        if pipe is None:
            frag = None
            if targets and "frag" not in prog.stages:
                raise ShaderError(f"pass '{self.pass_.name}': {prog.name} has no fragment "
                                  f"shader to write {', '.join(s for s, _ in color)}")
            if "frag" in prog.stages and (targets or prog.paths[0].suffix != ".wgsl"):
                module, main = prog.stages["frag"]
                frag = {"module": module, "entry_point": main,
                        "targets": [{"format": f, **({"blend": blend} if blend else {})}
                                    for f in targets]}
            ds = None
            if dfmt is not None:
                ds = {"format": dfmt, "depth_write_enabled": depth_write,
                      "depth_compare": depth_compare}
            pipe = prog.pipelines[key] = self.device.create_render_pipeline(
                layout=prog.pipeline_layout,
                vertex={"module": prog.stages["vert"][0], "entry_point":
                        prog.stages["vert"][1], "buffers": VERTEX_BUFFERS},
                # points and lines have no faces to cull
                primitive={"topology": topology, "front_face": "ccw", "cull_mode":
                           cull if topology == "triangle-list" else "none"},
                depth_stencil=ds, fragment=frag, label=f"{self.pass_.name}:scene")
        group0 = self.bind(prog, bindings, groups=(0,))[0]
        return prog, pipe, group0, targets, dfmt

    def render_pass(self, *, color: list[tuple[str, Any]] = (), depth: tuple[str, Any] | None
                    = None, depth_read_only: bool = False) -> Any:
        """Begin a render pass; ``color`` is [(slot, clear color or None to load)]."""
        attachments, ds = self._attachments(color, depth, depth_read_only)
        return self.executor.calls.render_pass(self.encoder, self.pass_.name, attachments, ds,
                                               self._timestamps())

    def _attachments(self, color: list[tuple[str, Any]], depth: tuple[str, Any] | None,
                     depth_read_only: bool) -> tuple[list[dict], dict | None]:
        attachments = [{"view": self.view(slot), "load_op": "load" if clear is None else "clear",
                        "store_op": "store", "clear_value": clear or (0, 0, 0, 0)}
                       for slot, clear in color]
        ds = None
        if depth is not None:
            slot, clear = depth
            ds = {"view": self.view(slot), "depth_read_only": depth_read_only}
            if not depth_read_only:
                ds |= {"depth_load_op": "load" if clear is None else "clear",
                       "depth_store_op": "store", "depth_clear_value": clear or 0.0}
        return attachments, ds
