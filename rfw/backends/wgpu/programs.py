"""Programs: GLSL through SPIR-V (every built-in pass), WGSL for wgpu-only plugins, reflected
into bind group layouts and cached by their sources and bound formats, whose files are looked
at again every ``RECHECK_S`` for hot reload."""

from __future__ import annotations

import re
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import wgpu

from ...graph.formats import format_info
from ...shaders import BindingInfo, ShaderError, Source, explain, preprocess
from ...shaders import reflect as reflect_wgsl
from ...spirv import (
    DescriptorInfo,
    ShaderCompileError,
    Spirv,
    compile_glsl,
    readonly_blocks_marked,
    reflect,
)
from ..scene_data import SCENE_GROUPS
from .device import Device
from .scene import scene_layout_entries

# seconds between looks at a pass's shader sources while frames replay its program
RECHECK_S = 0.25


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
    spirvs: tuple[Spirv, ...] = ()  # its GLSL files compiled (rfw.settings_layout reads them)
    # (uniform block, Settings type) pairs whose layout was checked against each other
    settings_checked: set[tuple[str, type]] = field(default_factory=set)

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
                                                  label=paths[0].name), workgroup,
                       spirvs=tuple(spirvs))

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
