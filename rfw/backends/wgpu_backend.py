"""Run a compiled frame graph on wgpu: textures from the plan, passes with timestamps, readback.

WebGPU cannot alias memory, so transient resources with identical descriptions and disjoint
lifetimes share one texture instead; everything else follows the compiled plan.

A frame costs no Python per draw: a pass's scene draws are recorded once into a render
bundle and replayed while its pipeline, bind groups, scene and formats stay the same; bind
groups are made once per set of bound objects, and settings reach the replayed draws through
their uniform buffers, written when their bytes change (``benchmarks/bench_record.py``).
"""

from __future__ import annotations

import math
import re
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import wgpu

from ..backend import gpu_choice, pick_gpu
from ..context import check_topology, nothing_to_draw
from ..errors import naming
from ..exec.samplers import Samplers
from ..exec.timing import pass_timings
from ..frame import InFlight, frames_in_flight, run_frames
from ..graph import CompiledGraph
from ..graph.compile import IMPLIED_CAPS, ResourcePlan
from ..graph.formats import format_info
from ..passes import Pass, Settings
from ..shaders import BindingInfo, ShaderError, Source, explain, preprocess, program_files
from ..shaders import reflect as reflect_wgsl
from ..spirv import (
    DescriptorInfo,
    ShaderCompileError,
    Spirv,
    check_bindings,
    compile_glsl,
    readonly_blocks_marked,
    reflect,
)
from ..units import align_up
from .base import FrameExecutor, SlotContext
from .gpu_scene import VERTEX_BUFFERS, scene_layout_entries
from .scene_data import SCENE_GROUPS
from .wgpu_calls import FrameCalls

# seconds between looks at a pass's shader sources while frames replay its program
RECHECK_S = 0.25
# wgpu features rfw asks for when the adapter has them
WANTED_FEATURES = ("timestamp-query", "float32-filterable", "rg11b10ufloat-renderable",
                   "bgra8unorm-storage", "texture-adapter-specific-format-features")


class Device:
    """A wgpu adapter and device with what rfw needs to know about them."""

    def __init__(self, *, power_preference: str = "high-performance"):
        index = gpu_choice()
        if index is None:
            self.adapter = wgpu.gpu.request_adapter_sync(power_preference=power_preference)
        else:  # RFW_GPU: that GPU among the Vulkan adapters, in the driver's order
            adapters = [a for a in wgpu.gpu.enumerate_adapters_sync()
                        if a.info.get("backend_type") == "Vulkan"]
            self.adapter = pick_gpu(
                [("cpu" if a.info.get("adapter_type") == "CPU" else "gpu", a) for a in adapters],
                index, ", ".join(a.info.get("device", "?") for a in adapters) or "none")
        if self.adapter is None:
            raise RuntimeError("no wgpu adapter found (is a Vulkan driver installed?)")
        self.features = tuple(f for f in WANTED_FEATURES if f in self.adapter.features)
        self.device = self.adapter.request_device_sync(required_features=list(self.features),
                                                       label="rfw")
        info = self.adapter.info
        self.name = info.get("device", "?")
        self.driver = info.get("description", "") or info.get("driver", "")
        self.backend = info.get("backend_type", "")
        self.timestamp_period = _timestamp_period(self.device)
        self.caps = frozenset(self.features) | frozenset(self.adapter.features)

    def describe(self) -> dict[str, str]:
        return {"device": self.name, "driver": self.driver, "api": self.backend,
                "backend": "wgpu"}


def _timestamp_period(device: Any) -> float:
    # wgpu-native resolves raw ticks; the period converts them to nanoseconds
    try:
        from wgpu.backends.wgpu_native._ffi import lib

        return float(lib.wgpuQueueGetTimestampPeriod(device.queue._internal)) or 1.0
    except Exception:
        return 1.0


# ---------------------------------------------------------------------------------------------
# textures from the plan


_USAGE = {"sampled": wgpu.TextureUsage.TEXTURE_BINDING,
          "storage": wgpu.TextureUsage.STORAGE_BINDING,
          "color": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "depth": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "depth_read": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "shading_rate": wgpu.TextureUsage.TEXTURE_BINDING,
          "transfer_src": wgpu.TextureUsage.COPY_SRC,
          "transfer_dst": wgpu.TextureUsage.COPY_DST}


def wgpu_format(name: str) -> str:
    info = format_info(name)
    if info.wgpu is None:
        raise ShaderError(f"format {name} has no WebGPU equivalent")
    return info.wgpu


_BUFFER_USAGE = {"storage": wgpu.BufferUsage.STORAGE, "uniform": wgpu.BufferUsage.UNIFORM,
                 "indirect": wgpu.BufferUsage.INDIRECT, "vertex": wgpu.BufferUsage.VERTEX,
                 "index": wgpu.BufferUsage.INDEX, "transfer_src": wgpu.BufferUsage.COPY_SRC,
                 "transfer_dst": wgpu.BufferUsage.COPY_DST}


def buffer_usage(r: ResourcePlan) -> int:
    # copies both ways so buffers can be cleared, filled and read back
    usage = wgpu.BufferUsage.COPY_SRC | wgpu.BufferUsage.COPY_DST
    for u in r.usages:
        usage |= _BUFFER_USAGE.get(u, 0)
    return usage


def texture_usage(r: ResourcePlan, readback: bool) -> int:
    usage = 0
    for u in r.usages:
        usage |= _USAGE.get(u, 0)
    return usage | (wgpu.TextureUsage.COPY_SRC if readback else 0)


def share_textures(plans: list[ResourcePlan], readback: set[str],
                   spans: dict[str, tuple[int, int]]) -> dict[str, str]:
    """Map each transient to the resource whose texture it reuses (itself if none).

    Same format, size, mips, layers, samples and usage, and lifetimes that do not overlap.
    """
    owner: dict[str, str] = {}
    busy: dict[tuple, list[tuple[str, int]]] = defaultdict(list)  # key -> [(owner, last)]
    for r in sorted(plans, key=lambda r: spans[r.name][0]):
        if not r.transient or r.name in readback:
            owner[r.name] = r.name
            continue
        key = (r.format, r.width, r.height, r.mips, r.layers, r.samples,
               texture_usage(r, False))
        first, last = spans[r.name]
        for k, (o, end) in enumerate(busy[key]):
            if end < first:
                owner[r.name] = o
                busy[key][k] = (o, last)
                break
        else:
            owner[r.name] = r.name
            busy[key].append((r.name, last))
    return owner


# ---------------------------------------------------------------------------------------------
# programs: GLSL through SPIR-V (every built-in pass), WGSL for wgpu-only plugins


_WG_SIZE = re.compile(r"@workgroup_size\(\s*(\d+)\s*(?:,\s*(\d+)\s*)?(?:,\s*(\d+)\s*)?\)")
_UNFILTERABLE = {"r32float", "rg32float", "rgba32float"}
_VISIBLE = {"comp": wgpu.ShaderStage.COMPUTE, "vert": wgpu.ShaderStage.VERTEX,
            "frag": wgpu.ShaderStage.FRAGMENT}
_ALL_STAGES = wgpu.ShaderStage.VERTEX | wgpu.ShaderStage.FRAGMENT | wgpu.ShaderStage.COMPUTE


@dataclass(frozen=True)
class Binding:
    """One reflected binding as the bind group needs it."""

    name: str
    group: int
    binding: int
    entry: dict  # the bind group layout entry
    storage_format: str | None = None  # the texel format a storage texture declares
    depth: bool = False  # declared a depth texture (sampled with a depth reference)
    where: str = "?"  # where it is declared: a file, or file:line for WGSL


@dataclass
class Program:
    paths: tuple[Path, ...]
    stages: dict[str, tuple[Any, str]]  # comp | vert | frag -> (module, entry point)
    bindings: dict[str, Binding]
    layouts: list[Any]
    pipeline_layout: Any
    workgroup: tuple[int, int, int] = (1, 1, 1)
    pipelines: dict[Any, Any] = field(default_factory=dict)
    key: tuple = ()  # its key in ShaderCache.programs

    @property
    def name(self) -> str:
        return " + ".join(str(p) for p in self.paths)


class ShaderCache:
    """Programs keyed by their SPIR-V (or preprocessed WGSL) and the bound formats; bind
    group layouts shared between programs with the same entries (the scene's groups)."""

    def __init__(self, device: Device):
        self.device = device
        self.programs: dict[tuple, Program] = {}
        self.layouts: dict[str, Any] = {}
        self.scene_layouts: dict[int, Any] = {}
        # (files, defines) -> their SPIR-V and the stamps of every source they read: a
        # dispatch looks its program up without hashing sources or asking glslang
        self.compiled: dict[tuple, tuple[list[Spirv], tuple]] = {}
        # a pass's (class, name, shader, kind, defines, formats) -> (program, when checked)
        self.memo: dict[tuple, tuple[Program, float]] = {}

    def program(self, paths: list[Path], defines: dict[str, object], kind: str,
                formats: dict[str, str], *, owner: str = "") -> Program:
        """The program of ``paths`` (``rfw.shaders.program_files``) for ``kind``
        (compute | render), with the layouts the bound ``formats`` need."""
        if paths[0].suffix == ".wgsl":
            return self._wgsl(paths[0], defines, kind, formats)
        spirvs = self._spirv(paths, defines, owner)
        key = (kind, *(s.key for s in spirvs), tuple(sorted(formats.items())))
        if key not in self.programs:
            self.programs[key] = self._glsl(paths, spirvs, kind, formats, owner)
            self.programs[key].key = key
            # what a call site compares to keep the program past RECHECK_S (hot reload)
            self.programs[key].stamps = _stamps(s for spv in spirvs for s in spv.sources)
        return self.programs[key]

    def recent(self, key: tuple, make: Any) -> Program:
        """``make()``'s program, made again only when ``RECHECK_S`` has passed since it
        last was (a pass's sources are looked at that often, for hot reload) or the cache
        was cleared (``rfw view``'s R): a frame records without touching the files."""
        hit = self.memo.get(key)
        now = time.monotonic()
        if hit is not None and now - hit[1] < RECHECK_S and \
                self.programs.get(hit[0].key) is hit[0]:
            return hit[0]
        prog = make()
        self.memo[key] = (prog, now)
        return prog

    def _spirv(self, paths: list[Path], defines: dict[str, object], owner: str) -> list[Spirv]:
        memo = (tuple(paths), tuple(sorted((k, str(v)) for k, v in defines.items())))
        hit = self.compiled.get(memo)
        if hit is not None and hit[1] == _stamps(s for spv in hit[0] for s in spv.sources):
            return hit[0]
        try:
            spirvs = [compile_glsl(p, defines) for p in paths]
        except ShaderCompileError as e:
            raise e.about(f"pass '{owner}'") if owner else e from None
        self.compiled[memo] = (spirvs, _stamps(s for spv in spirvs for s in spv.sources))
        return spirvs

    def layout(self, entries: list[dict], label: str) -> Any:
        key = repr(sorted(entries, key=lambda e: e["binding"]))
        if key not in self.layouts:
            self.layouts[key] = self.device.device.create_bind_group_layout(entries=entries,
                                                                            label=label)
        return self.layouts[key]

    def _module(self, path: Path, code: bytes | str, explain_error: Any = None) -> Any:
        try:
            return self.device.device.create_shader_module(code=code, label=path.name)
        except Exception as e:  # wgpu raises its own error types for shader problems
            msg = " ".join(str(e).split())
            raise ShaderError(explain_error(msg) if explain_error else
                              f"{path}: wgpu does not take its SPIR-V: {msg}") from None

    def _glsl(self, paths: list[Path], spirvs: list[Spirv], kind: str,
              formats: dict[str, str], owner: str) -> Program:
        where = " + ".join(str(p) for p in paths)
        who = f"pass '{owner}': " if owner else ""
        stages, found, workgroup = self._stages(paths, spirvs, who, where)
        if (kind == "compute") != ("comp" in stages) or (kind == "render" and
                                                         "vert" not in stages):
            need = "a comp shader" if kind == "compute" else "a vert shader (and a frag one)"
            raise ShaderError(f"{who}{where}: a {kind} pass needs {need}")
        bindings = {name: self._binding(d, vis, formats.get(name), path, who)
                    for name, (d, vis, path) in found.items()}
        layouts = self._group_layouts(kind, bindings, f"{who}{where}", paths[0].name)
        dev = self.device.device
        return Program(tuple(paths), stages, bindings, layouts,
                       dev.create_pipeline_layout(bind_group_layouts=layouts,
                                                  label=paths[0].name), workgroup)

    def _stages(self, paths: list[Path], spirvs: list[Spirv], who: str, where: str
                ) -> tuple[dict[str, tuple[Any, str]], dict[str, tuple[DescriptorInfo, int, Path]],
                           tuple[int, int, int]]:
        """A module per stage, and every binding with the stages that see it (a name is
        one binding in every stage that declares it)."""
        stages: dict[str, tuple[Any, str]] = {}
        found: dict[str, tuple[DescriptorInfo, int, Path]] = {}
        workgroup = (1, 1, 1)
        for path, spv in zip(paths, spirvs, strict=True):
            if spv.stage not in _VISIBLE:
                raise ShaderError(f"{who}{path} is a {spv.stage} shader: the wgpu backend runs "
                                  "comp, vert and frag shaders (this pass needs --backend vk)")
            if spv.stage in stages:
                raise ShaderError(f"{who}{where} has two {spv.stage} shaders")
            refl = reflect(spv.code)
            for d in refl.descriptors.values():  # before naga gives its own, vaguer error
                _check_portable(d, path, who)
            stages[spv.stage] = (self._module(path, readonly_blocks_marked(spv.code)),
                                 refl.entry)
            if spv.stage == "comp":
                workgroup = refl.local_size
            for d in refl.descriptors.values():
                prior = found.get(d.name)
                if prior is not None and (prior[0].set, prior[0].binding, prior[0].kind) != (
                        d.set, d.binding, d.kind):
                    raise ShaderError(f"{who}'{d.name}' is group {prior[0].set} binding "
                                      f"{prior[0].binding} in {prior[2]} and group {d.set} "
                                      f"binding {d.binding} in {path}")
                vis = _VISIBLE[spv.stage] | (prior[1] if prior else 0)
                found[d.name] = (d, vis, prior[2] if prior else path)
        return stages, found, workgroup

    def _group_layouts(self, kind: str, bindings: dict[str, Binding], where: str,
                       label: str) -> list[Any]:
        """One bind group layout per group index; the scene's groups (all of them in a
        render program) take the scene's shared layout."""
        groups: dict[int, list[Binding]] = defaultdict(list)
        for b in bindings.values():
            groups[b.group].append(b)
        top = max(groups, default=-1)
        if kind == "render":
            top = max(top, max(SCENE_GROUPS))
        layouts = []
        for g in range(top + 1):
            mine = groups.get(g, [])
            scene = [(n, b) for n, b, _ in SCENE_GROUPS.get(g, ())] or None
            if scene is not None and (kind == "render" or mine) and all(
                    (b.name, b.binding) in scene for b in mine):
                # the scene's own groups: one layout, so its bind groups serve every pass
                if g not in self.scene_layouts:
                    self.scene_layouts[g] = self.device.device.create_bind_group_layout(
                        entries=scene_layout_entries(g), label=f"scene:group{g}")
                layouts.append(self.scene_layouts[g])
                continue
            if kind == "render" and scene is not None:
                odd = [b.name for b in mine if (b.name, b.binding) not in scene]
                raise ShaderError(f"{where} declares {', '.join(odd)} in group {g}, which the "
                                  f"scene owns ({', '.join(n for n, _ in scene)})")
            layouts.append(self.layout([b.entry for b in mine], f"{label}:group{g}"))
        return layouts

    def _binding(self, d: DescriptorInfo, vis: int, fmt: str | None, path: Path,
                 who: str) -> Binding:
        entry: dict[str, Any] = {"binding": d.binding, "visibility": vis}
        declared = None
        if d.kind == "uniform_buffer":
            entry["buffer"] = {"type": "uniform"}
        elif d.kind == "storage_buffer":
            entry["buffer"] = {"type": "storage" if d.writable else "read-only-storage"}
            if d.writable:
                entry["visibility"] = vis & ~wgpu.ShaderStage.VERTEX
        elif d.kind == "sampler":
            entry["sampler"] = {"type": "comparison" if d.compared else "filtering"}
        elif d.kind == "storage_image":
            declared = format_info(d.format).wgpu if d.format else fmt
            if declared is None:
                raise ShaderError(f"{who}{path}: storage image '{d.name}' declares no format "
                                  "(layout(rgba8) and the like) and nothing is bound to it")
            access = "read-write" if d.readable and d.writable else \
                "write-only" if d.writable else "read-only"
            entry["storage_texture"] = {"access": access, "format": declared,
                                        "view_dimension": d.dim}
            if d.writable:
                entry["visibility"] = vis & ~wgpu.ShaderStage.VERTEX
        else:
            entry["texture"] = {"sample_type": _sample_type(d, fmt, self.device.features),
                                "view_dimension": d.dim, "multisampled": d.multisampled}
        return Binding(d.name, d.set, d.binding, entry, declared, d.compared, str(path))

    def _wgsl(self, path: Path, defines: dict[str, object], kind: str,
              formats: dict[str, str]) -> Program:
        source = preprocess(path, defines)
        key = (source.hash, kind, tuple(sorted(formats.items())))
        if key in self.programs:
            return self.programs[key]
        module = self._module(path, source.text, lambda msg: explain(source, msg))
        vis = wgpu.ShaderStage.COMPUTE if kind == "compute" else \
            wgpu.ShaderStage.VERTEX | wgpu.ShaderStage.FRAGMENT
        filterable32 = "float32-filterable" in self.device.features
        bindings = {b.name: Binding(b.name, b.group, b.binding,
                                    _layout_entry(b, vis, formats.get(b.name), filterable32),
                                    _storage_format(b) if b.kind == "storage-texture" else None,
                                    b.type.startswith("texture_depth"),
                                    _declared_at(source, b.name))
                    for b in reflect_wgsl(source).values()}
        groups: dict[int, list[dict]] = defaultdict(list)
        for b in bindings.values():
            groups[b.group].append(b.entry)
        dev = self.device.device
        layouts = [dev.create_bind_group_layout(entries=groups.get(g, []),
                                                label=f"{path.name}:group{g}")
                   for g in range(max(groups, default=-1) + 1)]
        m = _WG_SIZE.search(source.text)
        wg = tuple(int(v) if v else 1 for v in m.groups()) if m else (1, 1, 1)
        stages = {"comp": (module, "main")} if kind == "compute" else \
            {"vert": (module, "vs_main"), "frag": (module, "fs_main")}
        prog = Program((path,), stages, bindings, layouts,
                       dev.create_pipeline_layout(bind_group_layouts=layouts,
                                                  label=path.name), wg)
        prog.key = key
        self.programs[key] = prog
        return prog


def _check_portable(d: DescriptorInfo, path: Path, who: str) -> None:
    """A ShaderError for a binding WebGPU has no counterpart of."""
    if d.count != 1 or d.kind in ("combined_image_sampler", "acceleration_structure"):
        what = {"combined_image_sampler": "a combined image sampler (declare a texture and a "
                "sampler)", "acceleration_structure": "an acceleration structure (this pass "
                "needs --backend vk)"}.get(d.kind, "an array of bindings")
        raise ShaderError(f"{who}{path}: binding '{d.name}' is {what}: WebGPU has none")


def _identity(resource: Any) -> Any:
    """What makes two bound resources the same: the objects (by id) and any numbers
    (a buffer binding's offset and size)."""
    if isinstance(resource, dict):
        return tuple((k, v if isinstance(v, int) else id(v))
                     for k, v in sorted(resource.items()))
    return id(resource)


def _stamps(paths: Any) -> tuple:
    """When and how large each file is: a changed include recompiles (hot reload)."""
    out = []
    for p in paths:
        try:
            st = p.stat()
            out.append((p, st.st_mtime_ns, st.st_size))
        except OSError:
            out.append((p, None, None))
    return tuple(out)


def _sample_type(d: DescriptorInfo, fmt: str | None, features: tuple[str, ...]) -> str:
    if d.compared:
        return "depth"
    if d.texel != "float":
        return d.texel
    # a depth texture read as numbers, or a 32-bit float one without float32-filterable
    if fmt is not None and (format_info(fmt).depth or (
            fmt in _UNFILTERABLE and "float32-filterable" not in features)):
        return "unfilterable-float"
    return "float"


def _layout_entry(b: BindingInfo, visibility: int, fmt: str | None,
                  filterable32: bool = False) -> dict:
    entry: dict[str, Any] = {"binding": b.binding, "visibility": visibility}
    if b.kind in ("uniform", "storage", "read-only-storage"):
        if b.kind == "storage":
            entry["visibility"] = visibility & ~wgpu.ShaderStage.VERTEX
        entry["buffer"] = {"type": b.kind}
    elif b.kind == "sampler":
        entry["sampler"] = {"type": "comparison" if "comparison" in b.type else "filtering"}
    elif b.kind == "storage-texture":
        inner = b.type[b.type.index("<") + 1:b.type.rindex(">")].split(",")
        access = {"write": "write-only", "read": "read-only",
                  "read_write": "read-write"}[inner[1].strip()]
        entry["visibility"] = visibility & ~wgpu.ShaderStage.VERTEX
        entry["storage_texture"] = {"access": access, "format": _storage_format(b),
                                    "view_dimension": _dimension(b.type)}
    else:
        if "depth" in b.type:
            sample = "depth"
        elif "<u32>" in b.type:
            sample = "uint"
        elif "<i32>" in b.type:
            sample = "sint"
        elif fmt in _UNFILTERABLE and not filterable32:
            sample = "unfilterable-float"
        else:
            sample = "float"
        entry["texture"] = {"sample_type": sample, "view_dimension": _dimension(b.type),
                            "multisampled": "multisampled" in b.type}
    return entry


def _declared_at(source: Source, name: str) -> str:
    """``file:line`` of the binding's declaration (it may be in an include)."""
    m = re.search(rf"\bvar(?:<[^>]*>)?\s+{re.escape(name)}\s*:", source.text)
    return source.where(source.text.count("\n", 0, m.start()) + 1) if m else "?"


def _storage_format(b: BindingInfo) -> str:
    # texture_storage_2d<rgba8unorm, write>: the texel format is the first parameter
    return b.type[b.type.index("<") + 1:b.type.rindex(">")].split(",")[0].strip()


def _dimension(wtype: str) -> str:
    for token, dim in (("cube_array", "cube-array"), ("cube", "cube"),
                       ("2d_array", "2d-array"), ("3d", "3d"), ("1d", "1d")):
        if f"_{token}" in wtype:
            return dim
    return "2d"


# ---------------------------------------------------------------------------------------------
# the per-pass recording context


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


class PassContext(SlotContext):
    """What ``Pass.record`` sees: its resources by slot name and ways to record work."""

    def __init__(self, executor: Executor, pass_: Pass, encoder: Any, slots: dict[str, str]):
        self.executor = executor
        self.pass_ = pass_
        self.encoder = encoder
        self.slots = slots  # slot -> resource
        self.scene = executor.scene
        self.device = executor.device.device
        self.frame = executor.frame_index

    # resources ----------------------------------------------------------------------------
    def texture(self, slot: str) -> Any:
        return self.executor.texture(self.resource(slot))

    def extent(self, slot: str) -> tuple[int, int]:
        r = self.executor.plan.resource(self.resource(slot))
        return r.width, r.height

    def view(self, slot: str, *, mip: int | None = None) -> Any:
        """The slot's texture view; ``mip``: a view of that one mip level only."""
        return self.executor.view(self.resource(slot), mip=mip)

    def sampled(self, slot: str) -> Any:
        return self.executor.view(self.resource(slot))

    storage = view

    _step = -1  # the declared step (Pass.steps) the pass is in
    _bundles = 0  # scene draws recorded by this pass so far in this frame

    def replay(self, *key: Any) -> bool:
        """Always False: WebGPU replays render bundles only, and scene draws use them
        (``draw_scene``); a pass's other commands are recorded every frame."""
        return False

    def step(self, index: int) -> None:
        """Enter step ``index`` of the pass's declared steps: wgpu orders a pass's work
        itself, so nothing is recorded; the order is checked as on Vulkan."""
        self.executor.plan.barriers_before_step(self.pass_.name, index, self._step)
        self._step = index

    def mips(self, slot: str) -> int:
        return self.executor.plan.resource(self.resource(slot)).mips

    def buffer(self, slot: str) -> Any:
        """The GPU buffer behind a buffer slot (bind it as ``{"buffer": ...}`` or directly)."""
        return self.executor.buffer(self.resource(slot))

    def format(self, slot: str) -> str:
        return wgpu_format(self.executor.plan.resource(self.resource(slot)).format)

    def sampler(self, *, filter: str = "linear", address: str = "clamp-to-edge",
                compare: str | None = None) -> Any:
        """A sampler made once per executor (rfw.context.PassContext.sampler)."""
        return self.executor.sampler(filter=filter, address=address, compare=compare)

    # recording ----------------------------------------------------------------------------
    def _timestamps(self) -> dict | None:
        return self.executor.timestamp_writes(self.pass_.name)

    def program(self, kind: str, *, shader: str | None = None,
                defines: dict[str, object] | None = None,
                formats: dict[str, str] | None = None) -> Program:
        """The pass's program (``kind``: compute | render) of ``shader`` (default: the
        pass's), its files found by ``rfw.shaders.program_files``."""
        name = shader or self.pass_.shader
        if not name:
            raise ShaderError(f"pass '{self.pass_.name}' records work but declares no shader")
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


# ---------------------------------------------------------------------------------------------
# the executor


def check_caps(passes: dict[str, Pass], caps: frozenset[str]) -> None:
    """A ShaderError naming the first pass that needs what wgpu lacks (mesh shaders, ray
    queries, acceleration structures), before any of its work is set up."""
    for name, p in passes.items():
        lacking = [c for c in (*IMPLIED_CAPS.get(p.type, ()), *p.requires) if c not in caps]
        if lacking:
            raise ShaderError(f"pass '{name}' ({type(p).id or type(p).__name__}) needs "
                              f"{', '.join(lacking)}, which the wgpu backend does not have "
                              "(run it on vk: --backend vk, or backend = \"vk\" on the pass)")


@dataclass(eq=False)
class FrameSlot:
    """What one frame in flight owns until it is finished: its timestamp query set and
    the buffer its queries resolve into (copied from there into the executor's
    :class:`Stamps`), a mappable copy for a frame's earlier submits (``flush``: read at
    once), and the index of the submit that finishes the frame (waited for when the slot
    comes round again)."""

    query_set: Any
    resolve: Any
    readback: Any
    calls: FrameCalls
    index: int | None = None  # the last submit of the slot's frame, until waited for

    def wait(self) -> None:
        """Wait until the slot's last submit is done."""
        index, self.index = self.index, None
        if index is not None:
            self.calls.wait(index)

    def destroy(self) -> None:
        for obj in (self.query_set, self.resolve, self.readback):
            if obj is not None:
                obj.destroy()


STAMP_BATCH = 32  # frames whose timestamps are read back together (rfw.backends.wgpu_backend.Stamps)


class Stamps:
    """Frames' timestamps, read back ``frames`` frames at a time (a mapping costs more
    than the rest of a short frame's fixed calls together). Frame ``f`` copies its
    resolved queries into buffer ``(f // frames) % 2`` at its place in that batch; once
    the batch's last frame is finished (or the executor drains), the buffer is mapped,
    read and unmapped in one go. Frames in flight (at most ``frames``) write the other
    buffer meanwhile, so a mapped buffer is never one a submitted copy writes."""

    def __init__(self, device: Any, frame_bytes: int, frames: int):
        self.frame_bytes, self.frames = frame_bytes, frames
        self.buffers = [device.create_buffer(
            size=frame_bytes * frames,
            usage=wgpu.BufferUsage.MAP_READ | wgpu.BufferUsage.COPY_DST,
            label=f"rfw:timestamps:read{k}") for k in range(2)]
        # frames finished and not read yet: (frame index, bytes used, what to do with them)
        self.unread: list[tuple[int, int, Callable[[np.ndarray], None]]] = []

    def place(self, frame: int) -> tuple[Any, int]:
        """The buffer and offset frame ``frame`` copies its timestamps to."""
        return self.buffers[(frame // self.frames) % 2], (frame % self.frames) * self.frame_bytes

    def finished(self, frame: int, used: int, done: Callable[[np.ndarray], None]) -> None:
        """Frame ``frame`` is finished: ``done(stamps)`` gets its ``used`` bytes of
        timestamps (as uint64) once its batch is read."""
        self.unread.append((frame, used, done))
        if frame % self.frames == self.frames - 1:
            self.read()

    def read(self) -> None:
        """Read every finished frame's timestamps (their submits are done), oldest first."""
        unread, self.unread = self.unread, []
        for k in dict.fromkeys((f // self.frames) % 2 for f, _, _ in unread):
            buf = self.buffers[k]
            buf.map_sync("READ_NOSYNC")
            try:
                raw = np.frombuffer(buf.read_mapped(), np.uint64)
            finally:
                buf.unmap()
            for f, used, done in unread:
                if (f // self.frames) % 2 == k:
                    at = (f % self.frames) * self.frame_bytes // 8
                    done(raw[at:at + used // 8])

    def destroy(self) -> None:
        for b in self.buffers:
            b.destroy()
        self.unread.clear()


class Executor(FrameExecutor):
    """Owns the textures of one compiled graph on one device and records its frames."""

    def __init__(self, device: Device, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: Any = None,
                 readback: tuple[str, ...] = (), present: tuple[str, ...] = ()):
        self.device = device
        self.plan = plan
        self.passes = passes
        self.slots = slots
        self.scene = scene
        self.readback = tuple(readback)
        self.present = tuple(present)  # outputs a window samples to show them
        self.shaders = ShaderCache(device)
        self.frame_index = 0
        self.timings = pass_timings(plan.order)
        # a bridge's side on this backend (rfw.frame): the host copies, nothing is recorded
        self._bridges = tuple(name for name in plan.order if name not in passes and
                              name.startswith("bridge.") and all(
                                  a.usages <= {"transfer_src", "transfer_dst"}
                                  for a in plan.accesses.get(name, ())))
        for name in self._bridges:
            if len(plan.accesses[name]) > 1:
                raise ShaderError(f"pass '{name}' copies between backends: the plan mixes "
                                  "them, and runs through rfw.render.render (rfw.frame "
                                  "gives each backend its part of it)")
        self._textures: dict[str, Any] = {}
        self._views: dict[str, Any] = {}
        self._uniforms: dict[tuple[str, str], Any] = {}
        self._samplers = Samplers(self._make_sampler)
        # per call site (pass, n-th dispatch or scene draw): the last call and what it found
        self.call_sites: dict[tuple, tuple] = {}
        # bind groups by layout and bound objects: [group, what it holds, frame last used]
        self._bind_groups: dict[tuple, list] = {}
        # (pass, its n-th scene draw) -> (key, bundle, draws): replayed while the key holds
        self._bundles: dict[tuple[str, int], tuple[tuple, Any, int]] = {}
        self.bundles_recorded = 0
        self._written: dict[tuple[str, str], bytes] = {}  # what each uniform buffer holds
        self._packs: dict[tuple[str, str], tuple[tuple, bytes]] = {}  # Settings.pack() kept
        self._allocate()
        self._timestamp_enabled = "timestamp-query" in device.features
        self._query_set = None  # the frame's slot's
        self.calls = FrameCalls(device.device)
        self.stamps: Stamps | None = None
        self.in_flight = InFlight([])
        self.keep_in_flight(frames_in_flight())
        check_caps(passes, device.caps)
        for p in passes.values():
            p.setup(self)

    # resources ----------------------------------------------------------------------------
    def _allocate(self) -> None:
        names = list(self.plan.order)
        pos = {n: i for i, n in enumerate(names)}
        spans = {r.name: (pos.get(r.first, 0), pos.get(r.last, len(names)))
                 for r in self.plan.resources}
        images = [r for r in self.plan.resources if r.kind == "image" and r.format]
        self.owner = share_textures(images, set(self.readback) | set(self.present), spans)
        for r in images:
            if self.owner[r.name] != r.name:
                continue
            # user-owned images are filled by the user: they take copies in
            upload = wgpu.TextureUsage.COPY_DST if r.external else 0
            if r.name in self.present:
                upload |= wgpu.TextureUsage.TEXTURE_BINDING
            self._textures[r.name] = self.device.device.create_texture(
                size=(r.width, r.height, r.layers), format=wgpu_format(r.format),
                usage=(texture_usage(r, r.name in self.readback) | upload) or
                wgpu.TextureUsage.TEXTURE_BINDING,
                mip_level_count=r.mips, sample_count=r.samples, label=r.name)
        self.texture_count = len(self._textures)
        self._buffers: dict[str, Any] = {}
        for r in self.plan.resources:
            if r.kind == "buffer" and r.raw_bytes > 0:
                self._buffers[r.name] = self.device.device.create_buffer(
                    size=align_up(r.raw_bytes, 4), usage=buffer_usage(r), label=r.name)

    def texture(self, resource: str) -> Any:
        return self._textures[self.owner[resource]]

    def buffer(self, resource: str) -> Any:
        return self._buffers[resource]

    def view(self, resource: str, *, mip: int | None = None) -> Any:
        """The resource's view (every mip), or a view of mip ``mip`` alone."""
        key = resource if mip is None else f"{resource}@mip{mip}"
        if key not in self._views:
            tex = self.texture(resource)
            if mip is not None and not 0 <= mip < tex.mip_level_count:
                raise ShaderError(f"'{resource}' has {tex.mip_level_count} mip levels, no "
                                  f"mip {mip}")
            self._views[key] = tex.create_view(label=resource) if mip is None else \
                tex.create_view(base_mip_level=mip, mip_level_count=1, label=resource)
        return self._views[key]

    def format_of(self, value: Any) -> str | None:
        tex = getattr(value, "texture", None)
        return getattr(tex, "format", None) if tex is not None else None

    def scene_bindings(self) -> dict[str, Any]:
        return self.scene.bindings() if self.scene is not None else {}

    def sampler(self, *, filter: str = "linear", address: str = "clamp-to-edge",
                compare: str | None = None) -> Any:
        """A sampler made once per (filter, address, compare) and kept by the executor."""
        return self._samplers.get(filter, address, compare)

    def _make_sampler(self, filter: str, address: str, compare: str | None) -> Any:
        return self.device.device.create_sampler(
            mag_filter=filter, min_filter=filter, mipmap_filter=filter,
            address_mode_u=address, address_mode_v=address, address_mode_w=address,
            compare=compare, label=f"rfw:sampler:{filter}:{address}")

    def uniform(self, owner: str, name: str, data: bytes) -> Any:
        """The uniform buffer of ``owner``'s binding ``name`` holding ``data``: written
        when the bytes differ from the ones it holds (a frame that changes no setting
        writes nothing)."""
        key = (owner, name)
        buf = self._uniforms.get(key)
        if buf is None or buf.size < len(data):
            buf = self._uniforms[key] = self.device.device.create_buffer(
                size=max(16, len(data)), usage=wgpu.BufferUsage.UNIFORM |
                wgpu.BufferUsage.COPY_DST, label=f"{owner}.{name}")
            self._written.pop(key, None)
        if self._written.get(key) != data:
            self.device.device.queue.write_buffer(buf, 0, data)
            self._written[key] = bytes(data)
        return buf

    def as_resource(self, value: Any, b: Binding, owner: Pass) -> Any:
        if isinstance(value, Settings):
            data = self._pack((owner.name, b.name), value)
            return {"buffer": self.uniform(owner.name, b.name, data)}
        if isinstance(value, np.ndarray | bytes):
            data = value.tobytes() if isinstance(value, np.ndarray) else value
            return {"buffer": self.uniform(owner.name, b.name, data)}
        if isinstance(value, wgpu.GPUBuffer):
            return {"buffer": value}
        return value

    def _pack(self, key: tuple[str, str], settings: Settings) -> bytes:
        # packing walks the type hints: the bytes are kept while the values read the same
        snap = (type(settings), repr(vars(settings)))
        hit = self._packs.get(key)
        if hit is None or hit[0] != snap:
            hit = self._packs[key] = (snap, settings.pack())
        return hit[1]

    def bind_group(self, layout: Any, resources: list[tuple[int, Any]], *,
                   label: str = "") -> Any:
        """The bind group of ``layout`` over ``resources`` [(binding, resource)], made once
        while the same objects are bound (a uniform's buffer stays while its size fits)."""
        key = (id(layout), *((k, _identity(r)) for k, r in resources))
        hit = self._bind_groups.get(key)
        if hit is None:
            entries = [{"binding": k, "resource": r} for k, r in resources]
            group = self.device.device.create_bind_group(layout=layout, entries=entries,
                                                         label=label)
            # holding what the key names keeps their ids from being reused
            hit = self._bind_groups[key] = [group, (layout, resources), self.frame_index]
        hit[2] = self.frame_index
        return hit[0]

    def bundle(self, slot: tuple[str, int], key: tuple, record: Any, *,
               color_formats: tuple[str, ...], depth_format: str | None,
               depth_read_only: bool) -> tuple[Any, int]:
        """The render bundle of ``slot`` (a pass and its n-th scene draw) and its draw
        count: ``record(encoder)`` fills a new one when ``key`` (pipeline, bind groups,
        scene, formats) differs from the last one's, else the last one is replayed."""
        hit = self._bundles.get(slot)
        if hit is not None and hit[0] == key:
            return hit[1], hit[2]
        enc = self.device.device.create_render_bundle_encoder(
            color_formats=list(color_formats), depth_stencil_format=depth_format,
            depth_read_only=depth_read_only, stencil_read_only=depth_read_only,
            label=f"{slot[0]}:scene")
        draws = record(enc)
        bundle = enc.finish(label=f"{slot[0]}:scene")
        self._bundles[slot] = (key, bundle, draws)
        self.bundles_recorded += 1
        return bundle, draws

    # frames -------------------------------------------------------------------------------
    def timestamp_writes(self, pass_name: str) -> dict | None:
        if not self._timestamp_enabled:
            return None
        k = self._next_query
        if k + 2 > self._query_set.count:
            return None
        self._next_query += 2
        self._query_owner.append(pass_name)
        return {"query_set": self._query_set, "beginning_of_pass_write_index": k,
                "end_of_pass_write_index": k + 1}

    def keep_in_flight(self, frames: int) -> None:
        """Keep up to ``frames`` frames in flight (:func:`rfw.frame.frames_in_flight`): one
        :class:`FrameSlot` each. Frames in flight now are finished first."""
        frames = frames_in_flight(frames)
        self.drain()
        for slot in self.in_flight.slots:
            slot.destroy()
        if self.stamps is not None:
            self.stamps.destroy()
            self.stamps = None
        self.in_flight = InFlight([self._slot(k) for k in range(frames)])
        if self._timestamp_enabled:
            self.stamps = Stamps(self.device.device, 8 * self.in_flight.slots[0].query_set.count,
                                 max(STAMP_BATCH, frames))

    def _slot(self, k: int) -> FrameSlot:
        dev = self.device.device
        if not self._timestamp_enabled:
            return FrameSlot(None, None, None, self.calls)
        n = 2 * len(self.plan.order) * 4  # up to four GPU passes per rfw pass
        return FrameSlot(
            dev.create_query_set(type="timestamp", count=n, label=f"rfw:timestamps{k}"),
            dev.create_buffer(size=8 * n, usage=wgpu.BufferUsage.QUERY_RESOLVE |
                              wgpu.BufferUsage.COPY_SRC, label=f"rfw:timestamps{k}"),
            dev.create_buffer(size=8 * n, usage=wgpu.BufferUsage.MAP_READ |
                              wgpu.BufferUsage.COPY_DST, label=f"rfw:timestamps{k}:read"),
            self.calls)

    def run(self, frames: int = 1) -> None:
        """``frames`` frames; returns once they are done (the last one drains)."""
        run_frames(self, frames)

    def drain(self) -> None:
        """Wait for every frame in flight; their timings are appended, oldest first."""
        self.in_flight.drain()
        if self.stamps is not None and self.stamps.unread:
            self.stamps.read()

    # a frame driven pass by pass (mixed-backend frames: rfw.frame) -----------------------
    def begin_frame(self) -> None:
        """Start a frame; ``record`` passes into it, ``flush`` to run what was recorded and
        wait for it, ``end_frame`` to submit the rest without waiting. The frame takes the
        next slot once the frame that used it last is finished. Host writes need no drain
        here: WebGPU orders ``queue.write_buffer`` before the next submit and keeps what a
        submitted frame uses alive."""
        slot = self._frame_slot = self.in_flight.slot(self.frame_index)
        self._query_set = slot.query_set
        self._encoder: Any = None
        self._next_query = 0
        self._query_owner: list[str] = []
        self._cpu: dict[str, float] = {}
        self._gpu: dict[str, float] | None = None
        self._recorded: list[str] = []
        self._segment = 0

    def record(self, name: str) -> None:
        """Record pass ``name`` into the frame's open command encoder (made on first use).

        A bridge's side of the plan (``rfw.frame``: the copy goes through the host between
        flushes, and WebGPU tracks the usage itself) records nothing."""
        if name in self._bridges:
            return
        p = self.passes[name]
        if self._encoder is None:
            self._encoder = self.calls.encoder()
        encoder = self._encoder
        ctx = PassContext(self, p, encoder, self.slots[name])
        # no debug group around the pass: each compute and render pass it begins carries
        # its name as label already, and a group costs two native calls per pass a frame
        t = time.perf_counter()
        with naming(f"pass '{name}'"):
            p.record(ctx)
        self._cpu[name] = self._cpu.get(name, 0.0) + (time.perf_counter() - t) * 1e3
        self._recorded.append(name)

    def flush(self) -> None:
        """Submit what was recorded since the last flush, wait for it and collect its
        timestamps (a bridge then copies what it wrote). Nothing recorded: nothing happens."""
        slot, owners = self._frame_slot, self._query_owner
        if not self._submit(slot, last=False):
            return
        slot.wait()
        if owners:
            slot.readback.map_sync("READ_NOSYNC")
            try:
                raw = np.frombuffer(slot.readback.read_mapped(0, 16 * len(owners)), np.uint64)
            finally:
                slot.readback.unmap()
            self._gpu = self._add_timestamps(raw, owners, self._gpu)

    def end_frame(self) -> None:
        """Submit what is left without waiting: the frame's timings are appended when it
        is finished (its slot comes round again, or a drain). One frame in flight waits
        here (the last frame of ``run`` drains after: ``frame(drain=True)``), as every frame did before frames in flight."""
        slot, owners = self._frame_slot, self._query_owner
        self._submit(slot, last=True)
        # bind groups unused last frame and this one name objects no pass binds any more
        if len(self._bind_groups) > 64:
            self._bind_groups = {k: v for k, v in self._bind_groups.items()
                                 if v[2] >= self.frame_index - 1}
        frame = (self.frame_index, owners, self._cpu, self._gpu, self._recorded)
        self.in_flight.submitted(slot, lambda: self._finish(slot, *frame))
        self.frame_index += 1
        if len(self.in_flight) == 1:
            self.drain()

    def _submit(self, slot: FrameSlot, *, last: bool) -> bool:
        """Submit the open encoder with its queries resolved and copied to where they are
        read (the frame's place in :class:`Stamps` for its ``last`` submit, else the
        slot's own readback, read at once): False if none is open."""
        encoder = self._encoder
        if encoder is None:
            return False
        self._encoder = None
        self._segment += 1
        n = self._next_query
        if n:
            encoder.resolve_query_set(slot.query_set, 0, n, slot.resolve, 0)
            if last:
                buf, at = self.stamps.place(self.frame_index)
                encoder.copy_buffer_to_buffer(slot.resolve, 0, buf, at, 8 * n)
            else:
                encoder.copy_buffer_to_buffer(slot.resolve, 0, slot.readback, 0, 8 * n)
        slot.index = self.calls.submit(encoder)
        self._next_query = 0
        self._query_owner = []
        return True

    def _finish(self, slot: FrameSlot, frame: int, owners: list[str], cpu: dict[str, float],
                gpu: dict[str, float] | None, recorded: list[str]) -> None:
        """Wait for a submitted frame, then append its timings of the passes recorded (once
        its timestamps are read, if its last submit had any)."""
        slot.wait()

        def append(raw: np.ndarray | None) -> None:
            times = self._add_timestamps(raw, owners, gpu) if owners else gpu
            for name in dict.fromkeys(recorded):
                self.timings[name].cpu_ms.append(cpu[name])
                if times is not None:
                    self.timings[name].gpu_ms.append(times.get(name, 0.0))

        if self.stamps is not None:  # every frame: a batch is read after its last frame
            self.stamps.finished(frame, 16 * len(owners), append)
        else:
            append(None)

    def _add_timestamps(self, raw: np.ndarray, owners: list[str],
                        gpu: dict[str, float] | None) -> dict[str, float]:
        """Pass ``owners[k]``'s begin and end stamps (``raw[2k]``, ``raw[2k + 1]``) added
        to the frame's GPU ms per pass."""
        gpu = {} if gpu is None else gpu
        period = self.device.timestamp_period * 1e-6
        for k, name in enumerate(owners):
            begin, end = int(raw[2 * k]), int(raw[2 * k + 1])
            gpu[name] = gpu.get(name, 0.0) + max(0, end - begin) * period
        return gpu

    def upload(self, resource: str, array: np.ndarray) -> None:
        """Fill an external image from an (H, W, C) array of its texel type."""
        r = self.plan.resource(resource)
        data = np.ascontiguousarray(array)
        self.device.device.queue.write_texture(
            {"texture": self.texture(resource), "mip_level": 0},
            data, {"bytes_per_row": data.nbytes // r.height}, (r.width, r.height, 1))

    def read(self, resource: str) -> np.ndarray:
        """Read an image back as (H, W, C) numpy array in its own texel type, once every
        frame in flight is done."""
        self.drain()
        r = self.plan.resource(resource)
        info = format_info(r.format)
        tex = self.texture(resource)
        bpp = info.block_bytes
        data = self.device.device.queue.read_texture(
            {"texture": tex, "mip_level": 0, "origin": (0, 0, 0)},
            {"offset": 0, "bytes_per_row": r.width * bpp}, (r.width, r.height, 1))
        dtype = {"float": np.float16 if bpp // max(1, info.components) == 2 else np.float32,
                 "unorm": np.uint8 if bpp // max(1, info.components) == 1 else np.uint16,
                 "uint": np.uint32, "depth": np.float32}.get(info.kind, np.uint8)
        arr = np.frombuffer(data, dtype=dtype)
        return arr.reshape(r.height, r.width, -1)

    def destroy(self) -> None:
        """Destroy what the executor made; frames in flight are finished first (or
        dropped, if that fails)."""
        failed = None
        try:
            self.drain()
        except Exception as e:  # destroy everything still, then say what went wrong
            failed = e
        self.in_flight.forget()
        for slot in self.in_flight.slots:
            slot.destroy()
        self.in_flight.slots.clear()
        if self.stamps is not None:
            self.stamps.destroy()
            self.stamps = None
        self.calls.clear()
        for t in self._textures.values():
            t.destroy()
        self._textures.clear()
        for b in self._buffers.values():
            b.destroy()
        self._buffers.clear()
        self._views.clear()
        self._bundles.clear()
        self._bind_groups.clear()
        for b in self._uniforms.values():
            b.destroy()
        self._uniforms.clear()
        self._written.clear()
        self._packs.clear()
        self._samplers.clear()
        self._query_set = None
        if failed is not None:
            raise failed
