"""The pass contract: named, typed, described slots; typed settings; ``record(ctx)``.

A pass is a class in ``passes/<id>/<id>.py`` with its shader beside it::

    @register_pass("tonemap")
    class TonemapPass(ComputePass):
        \"\"\"Exposure, then a filmic curve, then display encoding.\"\"\"
        shader = "tonemap.comp.glsl"
        inputs = {"hdr": Tex2D(desc="linear HDR scene color")}
        outputs = {"ldr": Tex2D("rgba8unorm", size_of="hdr", desc="display color")}

        class Params(Settings):
            exposure: float = 1.0

        def record(self, ctx):
            ctx.dispatch(threads=ctx.extent("ldr"), t_hdr=ctx.sampled("hdr"),
                         s_ldr=ctx.storage("ldr"), u_params=self.params)

Synchronization is the graph's: no pass records a barrier, and no backend adds one of its
own inside a pass. The work of one step is unordered: two dispatches (or traces) recorded
without a step between them may run at the same time, so neither may read what the other
writes. A pass whose work depends on its own earlier work (a blur reading what the dispatch
before it wrote, one dispatch per mip of a chain) declares ordered steps in ``steps()``: each
:class:`rfw.graph.Step` names the parts (``Part(slot, mips=(first, count))`` of an image,
``bytes=(offset, size)`` of a buffer, or a bare slot name for all of it) it reads and writes.
The compiler plans the barriers between steps as it plans those between passes, and
``record`` calls ``ctx.step(i)`` before recording step ``i``'s work: on Vulkan that records
the barriers planned before step ``i``, on wgpu (which orders a pass's dispatches itself)
nothing. A pass that declares steps must write its resources in them.

A pass defined where there is no file (a notebook cell, the REPL, ``python -c``) gives its
shaders as text, ``shader_source = "#version 460 ..."`` (the one file ``shader`` names) or
``{"blur.comp.glsl": ..., "common.glsl": ...}``, or names the folder they are in with
``@register_pass("id", folder=...)``; see :meth:`Pass.folder`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import math
import os
import re
import struct
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

from .errors import RfwTypeError, check_number, check_type, is_identifier, type_name, warn
from .graph.errors import GraphError, did_you_mean
from .graph.resources import SizeRule, Slot, Step, _slot


class SettingsError(GraphError):
    """An unknown or ill-typed setting; names the pass and suggests the closest key."""


# the GLSL type of the uniform block member that reads a packed field, and its struct format
# (floats f32, ints i32, bools u32, tuples of 2-4 floats vec2-vec4)
_GLSL = {float: "float", int: "int", bool: "uint"}
_FORMATS = {"float": "<f", "int": "<i", "uint": "<I", "vec2": "<2f", "vec3": "<3f",
            "vec4": "<4f"}


class PackedField(typing.NamedTuple):
    """Where ``Settings.pack()`` writes one field: its name, byte offset and the GLSL type
    of the uniform block member that reads it (a bool is a ``uint``, or a GLSL ``bool``,
    which SPIR-V keeps as one)."""

    name: str
    offset: int
    type: str


class Range(typing.NamedTuple):
    """Bounds of a number setting, declared with ``typing.Annotated``; either may be None."""

    lo: float | None = None
    hi: float | None = None

    def check(self, value: Any, where: str) -> None:
        if (self.lo is not None and value < self.lo) or (self.hi is not None
                                                         and value > self.hi):
            raise SettingsError(f"{where}: {value!r} is outside {self.lo}..{self.hi}")


def _base(hint: Any) -> Any:
    # Annotated[int, Range(...)] is an int to convert and pack
    return typing.get_args(hint)[0] if hasattr(hint, "__metadata__") else hint


class Settings:
    """Typed settings with defaults, declared as annotated class attributes.

    Unknown keys raise with a suggestion; values are converted to the declared type. Floats,
    ints, bools and tuples of 2-4 floats pack into a WGSL uniform struct in declaration order
    (``pack()``); strings and other types are host-side only.
    """

    def __init__(self, _owner: str = "", **values: Any):
        fields = self.fields()
        for key in values:
            if key not in fields:
                raise SettingsError(f"{_owner or type(self).__qualname__}: unknown setting "
                                    f"'{key}'" + did_you_mean(key, fields))
        bounds = self.bounds()
        for name, (kind, default) in fields.items():
            where = f"{_owner}: setting '{name}'"
            value = _convert(values.get(name, default), kind, where)
            if name in bounds:
                bounds[name].check(value, where)
            object.__setattr__(self, name, value)

    @classmethod
    def _hints(cls) -> dict[str, Any]:
        hints = typing.get_type_hints(cls, include_extras=True)
        out = {}
        for klass in reversed(cls.__mro__):
            for name in getattr(klass, "__annotations__", {}):
                if not name.startswith("_"):
                    out[name] = hints[name]
        return out

    @classmethod
    def fields(cls) -> dict[str, tuple[Any, Any]]:
        return {name: (_base(hint), getattr(cls, name, None))
                for name, hint in cls._hints().items()}

    @classmethod
    def bounds(cls) -> dict[str, Range]:
        """Declared bounds: ``resolution: Annotated[int, Range(1, 16384)] = 2048``."""
        out = {}
        for name, hint in cls._hints().items():
            for extra in getattr(hint, "__metadata__", ()):
                if isinstance(extra, Range):
                    out[name] = extra
        return out

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.fields()}

    def replace(self, **values: Any) -> Settings:
        return type(self)(**{**self.as_dict(), **values})

    @classmethod
    def layout(cls) -> tuple[PackedField, ...]:
        """The fields ``pack()`` writes, in declaration order, each at its offset by the
        alignment rules WGSL and GLSL's std140 share (scalars 4, vec2 8, vec3 and vec4 16):
        what a shader's settings block is checked against (``rfw.settings_layout``)."""
        out, end = [], 0
        for name, (kind, _) in cls.fields().items():
            if kind in _GLSL:
                glsl, align = _GLSL[kind], 4
            elif _is_vec(kind):
                n = len(typing.get_args(kind))
                glsl, align = f"vec{n}", 8 if n == 2 else 16
            else:
                continue  # host-side only (strings and the like)
            end += -end % align
            out.append(PackedField(name, end, glsl))
            end += struct.calcsize(_FORMATS[glsl])
        return tuple(out)

    def pack(self) -> bytes:
        """The GPU-visible settings as a WGSL uniform struct (``layout()``), padded to whole
        16 bytes."""
        out = bytearray()
        for f in self.layout():
            value = getattr(self, f.name)
            out += b"\0" * (f.offset - len(out))
            if f.type.startswith("vec"):
                out += struct.pack(_FORMATS[f.type], *value)
            else:
                out += struct.pack(_FORMATS[f.type], float(value) if f.type == "float"
                                   else int(value))
        _pad(out, 16)
        return bytes(out or b"\0" * 16)

    def __repr__(self) -> str:
        return f"{type(self).__qualname__}({self.as_dict()})"

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.as_dict() == self.as_dict()


def _is_vec(kind: Any) -> bool:
    args = typing.get_args(kind)
    return typing.get_origin(kind) is tuple and 2 <= len(args) <= 4 and \
        all(a is float for a in args)


def _pad(buf: bytearray, n: int) -> None:
    buf += b"\0" * (-len(buf) % n)


# ints are packed as WGSL i32, floats as f32: values outside these never reach a shader
I32 = (-(1 << 31), (1 << 31) - 1)
F32_MAX = 3.4028234663852886e38
_TRUE, _FALSE = ("true", "1", "yes", "on"), ("false", "0", "no", "off")


def _convert(value: Any, kind: Any, where: str) -> Any:
    """``value`` as the declared ``kind``: strings (from ``--set``) are parsed, other types
    must match (``5`` is no string, ``"two"`` no number); numbers must be finite and fit the
    type the shader reads."""
    if kind is bool:
        return _to_bool(value, where)
    if kind is int:
        return _to_int(value, where)
    if kind is float:
        return _to_float(value, where)
    if kind is str:
        # a whole number stands for its digits (mode = 3 picks a mode by number)
        if isinstance(value, int) and not isinstance(value, bool):
            return str(value)
        if not isinstance(value, str):
            raise SettingsError(f"{where}: expected a string, got {value!r}")
        return value
    if _is_vec(kind):
        items = value.split(",") if isinstance(value, str) else value
        n = len(typing.get_args(kind))
        if not isinstance(items, list | tuple) or len(items) != n:
            raise SettingsError(f"{where}: expected {n} numbers, got {value!r}")
        return tuple(_to_float(v, where) for v in items)
    return value


def _to_bool(value: Any, where: str) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
        return value.strip().lower() in _TRUE
    raise SettingsError(f"{where}: expected true or false, got {value!r}")


def _to_int(value: Any, where: str) -> int:
    if isinstance(value, str):
        try:
            value = int(value.strip())
        except ValueError:
            raise SettingsError(f"{where}: expected an integer, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int):
        raise SettingsError(f"{where}: expected an integer, got {value!r}")
    if not I32[0] <= value <= I32[1]:
        raise SettingsError(f"{where}: {value} does not fit a 32-bit integer "
                            f"({I32[0]}..{I32[1]})")
    return value


def _to_float(value: Any, where: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            raise SettingsError(f"{where}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SettingsError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, int) and abs(value) > F32_MAX:
        raise SettingsError(f"{where}: {value} does not fit a 32-bit float")
    value = float(value)
    if not math.isfinite(value):
        raise SettingsError(f"{where}: must be finite, got {value!r}")
    if abs(value) > F32_MAX:
        raise SettingsError(f"{where}: {value!r} does not fit a 32-bit float")
    return value


def Tex2D(format: str | None = None, *, size_of: str | None = None,
          format_of: str | None = None, scale: float = 1.0, **kw: Any) -> Slot:
    """A 2D texture slot; ``size_of`` and ``format_of`` name another slot of the same pass
    whose resource's size (times ``scale``) or format this output takes."""
    for key, value in (("format", format), ("size_of", size_of), ("format_of", format_of)):
        if value is not None:
            check_type(value, key, str, "a str", element="rfw.Tex2D")
    scale = check_number(scale, "scale", lo=1e-6, hi=1e6, element="rfw.Tex2D")
    unknown = sorted(set(kw) - {f.name for f in dataclasses.fields(Slot)} - {"type"})
    if unknown:
        raise RfwTypeError(f"no slot property '{unknown[0]}'" + did_you_mean(
            unknown[0], [f.name for f in dataclasses.fields(Slot)]), element="rfw.Tex2D")
    if format_of is not None:
        kw["format_of"] = format_of
    if size_of is not None:
        kw["size"] = SizeRule.like(size_of, scale)
    elif scale != 1.0:
        kw["size"] = SizeRule.output(scale)
    return _slot("texture", format, kw)


# GLSL's storage image qualifiers: <channels><bits><kind> of the WebGPU name
_GLSL_KIND = {"unorm": "", "snorm": "_snorm", "uint": "ui", "sint": "i", "float": "f"}
_GLSL_PACKED = {"rgb10a2unorm": "rgb10_a2", "rgb10a2uint": "rgb10_a2ui",
                "rg11b10ufloat": "r11f_g11f_b10f"}


def storage_format(format: str) -> str:
    """The GLSL layout qualifier of a storage image of ``format`` (``rgba8unorm`` ->
    ``rgba8``): a shader whose output follows its input (``format_of``) gets it as a
    define, ``ctx.dispatch(..., defines={"DST_FORMAT": storage_format(ctx.format("dst"))})``."""
    m = re.fullmatch(r"(r|rg|rgba)(8|16|32)(unorm|snorm|uint|sint|float)", format)
    if m and not (m[2] == "32" and m[3] in ("unorm", "snorm")):
        return f"{m[1]}{m[2]}{_GLSL_KIND[m[3]]}"
    if format in _GLSL_PACKED:
        return _GLSL_PACKED[format]
    raise GraphError(f"format {format} has no GLSL storage image qualifier (a storage "
                     "output needs a plain r/rg/rgba format, not sRGB or bgra)")


# what ``Pass.replay`` may say
REPLAY = ("auto", False)

# what ``Pass.scene_needs`` may name, and whether a scene (rfw.scene.Scene) holds it
SCENE_NEEDS: dict[str, Any] = {
    "strokes": lambda scene: bool(scene.stroke_instances),  # points or lines (glTF 0-3)
}


class Pass:
    """Base of every pass. Subclasses declare slots, settings and a shader, and record."""

    id: ClassVar[str] = ""
    type: ClassVar[str] = "graphics"
    shader: ClassVar[str | None] = None
    inputs: ClassVar[dict[str, Slot]] = {}
    outputs: ClassVar[dict[str, Slot]] = {}
    requires: ClassVar[tuple[str, ...]] = ()
    side_effect: ClassVar[bool] = False
    backend: ClassVar[str | None] = None  # "vk" for passes that need raw Vulkan (vkext)
    # what a scene must hold for the pass to have work (one of SCENE_NEEDS, e.g. "strokes"):
    # a run on a scene without it leaves the pass out of the graph, so it records nothing
    # and has no timing row. Only for passes whose outputs nothing reads.
    scene_needs: ClassVar[str | None] = None
    # "auto": the pass's commands depend on nothing but its settings, the resources behind
    # its slots, the scene and ``replay_key(ctx)``, so an executor that can keep them
    # executes them again instead of calling ``record`` (rfw.exec.replay); False: recorded
    # every frame (commands that depend on anything else, e.g. bytes computed per frame)
    replay: ClassVar[str | bool] = False  # one of REPLAY (register_pass checks)

    class Params(Settings):
        pass

    # where the shaders are when no file holds the class: their text (one file's, named by
    # ``shader``, or {file name: text}) or a folder (``@register_pass(id, folder=...)``)
    shader_source: ClassVar[str | Mapping[str, str] | None] = None
    shader_folder: ClassVar[Path | None] = None

    def __init__(self, name: str, params: Settings | None = None, **settings: Any):
        check_type(name, "name", str, "a pass name (str)", element=type(self).__name__)
        if params is not None and not isinstance(params, Settings):
            raise RfwTypeError(f"'params' must be {type(self).__name__}.Params settings, not "
                               f"{type_name(params)}", element=f"pass '{name}'")
        self.name = name
        self.params = params if params is not None else self.Params(f"pass '{name}'",
                                                                    **settings)

    @classmethod
    def folder(cls) -> Path:
        """The folder of the pass's shaders: ``shader_source`` written once into a
        content-addressed folder of the shader cache, else ``shader_folder``, else the
        folder of the file that defines the class. A class with none of these (defined in
        a notebook or the REPL, shaders as files) is a GraphError saying what to give."""
        sources = shader_sources(cls)
        if sources:
            return _written(sources)
        if cls.shader_folder is not None:
            return Path(cls.shader_folder)
        try:
            file = inspect.getfile(cls)
        except (OSError, TypeError):  # __main__ of a notebook, the REPL, python -c
            file = "<none>"
        if file.startswith("<") or not os.path.isfile(file):  # '<stdin>', '<string>'
            raise GraphError(
                f"pass class {cls.__qualname__} is not defined in a file (a notebook cell or "
                "the REPL?), so its shader files cannot be found beside it: give the shader "
                "as text (shader_source = '...') or its folder (@register_pass(id, "
                "folder=...))", element=f"pass '{cls.id or cls.__name__}'")
        return Path(file).parent

    @classmethod
    def describe(cls) -> str:
        return inspect.getdoc(cls) or ""

    def declare(self) -> tuple[dict[str, Slot], dict[str, Slot]]:
        """This instance's input and output slots; override when settings change them."""
        return dict(self.inputs), dict(self.outputs)

    def steps(self) -> tuple[Step, ...]:
        """The ordered steps inside this pass, with the parts of slots each reads and writes
        (see the module docstring); none by default: the pass is one step."""
        return ()

    def setup(self, ctx: Any) -> None:
        """Make what the pass keeps across frames (tables of the scene as buffers:
        ``ctx.buffer``); ``ctx`` is a :class:`rfw.authoring.SetupContext`. Called once per
        executor, before its first frame."""

    def camera_jitter(self) -> int:
        """How many phases of sub-pixel camera jitter (Halton 2, 3) this pass needs; 0, the
        default: none. A temporal resolve asks for it, and then every pass of the frame
        draws with the jittered camera (the largest count any pass asks for)."""
        return 0

    def replay_key(self, ctx: Any) -> Any:
        """What else a ``replay = "auto"`` pass's commands depend on (hashable; read before
        ``record`` with the same ``ctx``): none by default."""
        return ()

    def record(self, ctx: Any) -> None:
        raise NotImplementedError(f"{type(self).__name__}.record")


def shader_sources(cls: type[Pass]) -> dict[str, str]:
    """``cls.shader_source`` as {file name: text}, checked (empty: the pass has none)."""
    src = cls.__dict__.get("_checked_sources")
    if src is not None and src[0] is cls.shader_source:
        return src[1]
    where = f"pass '{cls.id or cls.__name__}'"
    value = cls.shader_source
    if value is None:
        return {}
    if isinstance(value, str):
        name = cls.shader
        if not (isinstance(name, str) and name.endswith((".glsl", ".wgsl"))):
            raise GraphError("a str shader_source is the text of the one file 'shader' "
                             f"names (shader = 'x.comp.glsl'), not of {name!r}: give several "
                             "files as {file name: text}", element=where)
        value = {name: value}
    check_type(value, "shader_source", Mapping, "the shader's text (str) or {file name: text}",
               element=where)
    if not value:
        raise GraphError("'shader_source' is empty", element=where)
    for name, text in value.items():
        if not is_identifier(name) or not name.endswith((".glsl", ".wgsl")):
            raise GraphError(f"'shader_source' file name {name!r} is not a plain file name "
                             "ending in .glsl or .wgsl (x.comp.glsl, common.glsl)",
                             element=where)
        check_type(text, f"shader_source[{name!r}]", str, "the file's text (str)",
                   element=where)
    out = dict(value)
    type.__setattr__(cls, "_checked_sources", (cls.shader_source, out))
    return out


_WRITTEN: dict[str, Path] = {}


def _written(sources: dict[str, str]) -> Path:
    # one folder per content, so the SPIR-V cache, #include and error lines work as for
    # files on disk; written through a temporary name, so concurrent writers agree
    from .spirv import cache_dir

    h = hashlib.sha256()
    for name, text in sorted(sources.items()):
        h.update(name.encode() + b"\0" + text.encode() + b"\0")
    key = h.hexdigest()[:24]
    folder = _WRITTEN.get(key)
    if folder is not None and all((folder / n).is_file() for n in sources):
        return folder
    for root in (cache_dir() / "sources", Path(_tempdir()) / "rfw-shader-sources"):
        folder = root / key
        try:
            folder.mkdir(parents=True, exist_ok=True)
            for name, text in sources.items():
                path = folder / name
                if path.is_file() and path.read_text(encoding="utf-8") == text:
                    continue
                tmp = folder / f".{name}.{os.getpid()}.tmp"
                tmp.write_text(text, encoding="utf-8")
                os.replace(tmp, path)
        except OSError as e:
            warn(f"{root}: cannot write shader sources ({e.strerror or e}); trying another")
            continue
        _WRITTEN[key] = folder
        return folder
    raise GraphError("cannot write the shader sources anywhere (see the warnings above)")


def _tempdir() -> str:
    import tempfile

    return tempfile.gettempdir()


class DepthPrepassMixin:
    """For raster passes with a ``prepass`` setting: the ``depth`` output becomes a
    read-only ``depth`` input fed by a depth prepass. A setting, not the wiring, decides:
    ``declare()`` runs before inputs are wired."""

    PREPASS_DEPTH = _slot("depth", None, {"read_only": True,
                                          "desc": "scene depth from a depth prepass"})

    def declare(self) -> tuple[dict[str, Slot], dict[str, Slot]]:
        if not self.params.prepass:  # type: ignore[attr-defined]
            return dict(self.inputs), dict(self.outputs)  # type: ignore[attr-defined]
        outs = {k: v for k, v in self.outputs.items() if k != "depth"}  # type: ignore
        return {**self.inputs, "depth": self.PREPASS_DEPTH}, outs  # type: ignore


class ComputePass(Pass):
    type = "compute"


# how a ray-traced pass can trace: its pass type and what the device must have
RAY_METHODS: dict[str, tuple[str, tuple[str, ...]]] = {
    "ray_query": ("compute", ("VK_KHR_acceleration_structure", "VK_KHR_ray_query")),
    "ray_pipeline": ("ray_tracing", ("VK_KHR_acceleration_structure",
                                     "VK_KHR_ray_tracing_pipeline")),
}


class RayTracedPass(Pass):
    """A pass that traces rays in one of two ways, chosen by its ``method`` setting:
    ``"ray_query"`` runs ``shaders["ray_query"]`` (a compute shader with GL_EXT_ray_query),
    ``"ray_pipeline"`` runs ``shaders["ray_pipeline"]`` (a raygen shader; ``miss`` beside it)
    through a ray-tracing pipeline. The method sets the pass type (so acceleration structures
    are read in compute or ray-tracing stages) and the extensions a device must have, which
    the compiler checks by pass name. Ray tracing needs raw Vulkan: vk only."""

    backend = "vk"
    shaders: ClassVar[dict[str, str]] = {}
    miss: ClassVar[str | None] = None  # ray pipeline: the miss shader beside the raygen one
    closest_hit: ClassVar[str | None] = None  # and its closest-hit shader, if any
    any_hit: ClassVar[str | None] = None  # and its any-hit shader (non-opaque geometry), if any

    class Params(Settings):
        method: str = "ray_pipeline"  # ray_query | ray_pipeline
        max_recursion: int = 1  # ray pipeline: deepest traceRayEXT nesting

    def __init__(self, name: str, params: Settings | None = None, **settings: Any):
        super().__init__(name, params, **settings)
        method = self.params.method  # type: ignore[attr-defined]
        if method not in RAY_METHODS:
            raise SettingsError(f"pass '{name}': method '{method}' is not one of "
                                f"{', '.join(RAY_METHODS)}" + did_you_mean(method, RAY_METHODS))
        self.type, self.requires = RAY_METHODS[method]  # type: ignore[misc]
        self.shader = self.shaders[method]  # type: ignore[misc]

    def trace(self, ctx: Any, size: tuple[int, int], **bindings: Any) -> None:
        """One ray-tracing thread or launch per texel of ``size``."""
        if self.params.method == "ray_query":  # type: ignore[attr-defined]
            ctx.dispatch(threads=size, **bindings)
        else:
            ctx.trace_rays(size=size, miss=self.miss, closest_hit=self.closest_hit,
                           any_hit=self.any_hit, max_recursion=self.params.max_recursion,  # type: ignore[attr-defined]
                           **bindings)


class RenderPass(Pass):
    type = "graphics"
