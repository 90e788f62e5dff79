"""GLSL to SPIR-V with glslang, cached by content; bindings reflected from the SPIR-V.

One compiler and one reflection for both backends: the wgpu backend hands the SPIR-V to
``create_shader_module(code=...)``, vkext to ``vkCreateShaderModule``. Shaders are
``<pass>[_<part>].<stage>.glsl`` beside their pass (``rfw.shaders.program_files``);
``#include`` (through GL_GOOGLE_include_directive, added when missing) searches the pass
folder, then ``shaders/common``. The cache key hashes the source, every file it includes,
the defines, the target and the glslang version, so an edit anywhere recompiles and nothing
stale is ever used. Layouts are never hand-written: ``reflect()`` reads them from the binary.

Stages both backends run (comp, vert, frag) compile for Vulkan 1.1: naga (wgpu) rejects the
``LocalSizeId`` and ``OpTerminateInvocation`` that a 1.3 target emits, and the one binary
serves vk too. Mesh, task and ray-tracing stages (vk only) need SPIR-V 1.4 and compile for
Vulkan 1.3.

One module of ~630 lines on purpose: compiling, caching and reading the binary (descriptors,
blocks, entry points) share one SPIR-V word parser and its cache keys.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import struct
import subprocess
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from .errors import warn
from .fileio import atomic_write
from .shaders import COMMON, STAGES, ShaderError, read_source

# stages both backends run: one Vulkan 1.1 binary feeds naga and vkCreateShaderModule alike
PORTABLE_STAGES = ("comp", "vert", "frag")


class ShaderCompileError(ShaderError):
    """glslang refused a shader: the message names the file and line."""


def target_of(stage: str) -> str:
    """The glslang ``--target-env`` for ``stage``: vulkan1.1 where wgpu may run it."""
    return "vulkan1.1" if stage in PORTABLE_STAGES else "vulkan1.3"


def cache_dir() -> Path:
    from . import env

    return env.get("RFW_CACHE_SPIRV") or Path(os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "rfw", "spirv"))


def stage_of(path: Path) -> str:
    parts = path.name.split(".")
    if len(parts) < 3 or parts[-1] != "glsl" or parts[-2] not in STAGES:
        raise ShaderCompileError(f"{path}: shader files are named <name>.<stage>.glsl with stage "
                                 f"one of {', '.join(STAGES)}")
    return parts[-2]


_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def _sources(path: Path, search: list[Path], seen: dict[Path, bytes]) -> None:
    """The shader and everything it includes (for the cache key)."""
    try:
        data = read_source(path)
    except OSError as e:
        raise ShaderCompileError(f"{path}: cannot read shader: {e.strerror or e}") from None
    seen[path] = data
    for name in _INCLUDE.findall(data.decode("utf-8", "replace")):
        target = next((d / name for d in [path.parent, *search] if (d / name).is_file()), None)
        if target is not None and target not in seen:
            _sources(target, search, seen)


def _glslang() -> str:
    exe = shutil.which("glslangValidator")
    if exe is None:
        raise ShaderCompileError("glslangValidator not found: run scripts/setup-system.sh "
                                 "(Debian: glslang-tools)")
    return exe


@functools.lru_cache(maxsize=8)
def _glslang_version(exe: str) -> str:  # asked once per process, not once per compile
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, check=False)
    return out.stdout.splitlines()[0] if out.stdout else ""


@dataclass(frozen=True)
class Spirv:
    path: Path
    stage: str
    code: bytes
    key: str
    sources: tuple[Path, ...] = ()  # the file and every file it includes


def compile_glsl(path: str | Path, defines: dict[str, object] | None = None, *,
                 search: tuple[Path, ...] = (), target: str | None = None) -> Spirv:
    """Compile one GLSL file to SPIR-V, from the cache when nothing changed; ``target``
    defaults to the stage's (``target_of``)."""
    path = Path(path).resolve()
    stage = stage_of(path)
    target = target or target_of(stage)
    dirs = [*search, COMMON]
    seen: dict[Path, bytes] = {}
    _sources(path, dirs, seen)
    exe = _glslang()
    h = hashlib.sha256()
    h.update(_glslang_version(exe).encode())
    h.update(target.encode())
    for k, v in sorted((defines or {}).items()):
        h.update(f"-D{k}={v}\0".encode())
    for p in sorted(seen):
        h.update(str(p).encode() + b"\0" + seen[p] + b"\0")
    key = h.hexdigest()
    cached = cache_dir() / f"{key}.spv"
    code = _cached(cached)
    if code is not None:
        return _seen(Spirv(path, stage, code, key, tuple(seen)), defines, target)
    with tempfile.TemporaryDirectory(prefix="rfw-glsl-") as tmp:
        out = Path(tmp) / "out.spv"
        source = _with_include_extension(path, seen[path], Path(tmp))
        cmd = [exe, "-V", "--target-env", target, "-S", stage, "-o", str(out),
               *(f"-I{d}" for d in [path.parent, *dirs]),
               *(f"-D{k}={v}" for k, v in sorted((defines or {}).items())), str(source)]
        done = subprocess.run(cmd, capture_output=True, text=True, errors="replace",
                              check=False)
        if done.returncode != 0 or not out.is_file():
            raise ShaderCompileError(_first_error(done.stdout + done.stderr, path, source))
        code = out.read_bytes()
    try:  # a parallel compile never sees half a file
        atomic_write(cached, lambda f: f.write(code))
    except OSError as e:  # the compile stands; only later runs pay for it again
        warn(f"{cache_dir()}: cannot write the SPIR-V cache ({e.strerror or e}); "
             "shaders are compiled every run")
    return _seen(Spirv(path, stage, code, key, tuple(seen)), defines, target)


# dicts that see every module compile_glsl returns, ``{"<file> <target> -DK=V...": sha256 of
# its SPIR-V}`` (rfw.bench.inputs.watching_spirv: a benchmark bundle names what ran)
spirv_watchers: list[dict[str, str]] = []


def _seen(spirv: Spirv, defines: dict[str, object] | None, target: str) -> Spirv:
    if spirv_watchers:
        name = " ".join([str(spirv.path), target,
                         *(f"-D{k}={v}" for k, v in sorted((defines or {}).items()))])
        digest = hashlib.sha256(spirv.code).hexdigest()
        for seen in spirv_watchers:
            seen.setdefault(name, digest)
    return spirv


def _cached(path: Path) -> bytes | None:
    """The cache entry's SPIR-V, or None to compile: a missing entry, or a corrupt one
    (truncated, garbled), which is discarded with a warning so the compile replaces it."""
    if not path.is_file():
        return None
    try:
        code = path.read_bytes()
    except OSError as e:
        warn(f"{path}: cannot read SPIR-V cache entry ({e.strerror or e}); recompiling")
        return None
    try:
        reflect(code)  # checks the module whole (check_module) before reading it
    except ShaderCompileError as e:
        warn(f"{path}: corrupt SPIR-V cache entry ({e.message}); discarded and recompiled")
        path.unlink(missing_ok=True)
        return None
    return code


def _with_include_extension(path: Path, data: bytes, tmp: Path) -> Path:
    # glslang needs GL_GOOGLE_include_directive for #include; add it after #version so
    # shader files stay plain, and keep line numbers with #line (``data``: the bytes
    # _sources read and hashed, so the compile sees what the cache key names)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise ShaderCompileError(f"not UTF-8 text (byte {data[e.start]:#04x}: {e.reason})",
                                 file=f"{path}:{line}") from None
    if "#include" not in text or "GL_GOOGLE_include_directive" in text:
        return path
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith("#version"):
            lines[i + 1:i + 1] = ["#extension GL_GOOGLE_include_directive : require",
                                  f'#line {i + 2} "{path}"']
            break
    out = tmp / path.name
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


def _first_error(text: str, path: Path, source: Path) -> str:
    errors = [line.strip() for line in text.splitlines() if line.startswith("ERROR:")
              and "compilation terminated" not in line and "compilation errors" not in line]
    first = errors[0] if errors else (text.strip().splitlines() or ["glslang failed"])[-1]
    first = first.removeprefix("ERROR:").strip().replace(str(source), str(path))
    # glslang writes "file:line: 'x' : message"; lead with the file as rfw errors do
    m = re.match(r"(.+?):(\d+):\s*(.*)", first)
    if m and not m.group(1).startswith("/") and not Path(m.group(1)).exists():
        first = f"{path}:{m.group(2)}: {m.group(3)}"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return " ".join(first.split()) + more


# ---------------------------------------------------------------------------------------------
# the binding-name check both backends make


def check_bindings(owner: str, where: str, declared: Iterable[str], given: Iterable[str], *,
                   missing: bool = False) -> None:
    """Bindings match by name: a ShaderError naming the pass and the shader for a name
    ``given`` that the shader does not declare, or (``missing``) one declared but not given."""
    declared, given = list(declared), list(given)
    if missing:
        absent = [n for n in declared if n not in given]
        if absent:
            raise ShaderError(f"pass '{owner}': shader {where} binds {', '.join(absent)} but "
                              f"the pass gives {', '.join(sorted(given)) or 'nothing'}")
        return
    extra = [n for n in given if n not in declared]
    if extra:
        raise ShaderError(f"pass '{owner}': {where} has no binding named {', '.join(extra)} "
                          f"(it declares {', '.join(sorted(declared)) or 'none'})")


# ---------------------------------------------------------------------------------------------
# reflection


@dataclass(frozen=True)
class DescriptorInfo:
    name: str
    set: int
    binding: int
    kind: str  # uniform_buffer | storage_buffer | sampled_image | storage_image |
    #            combined_image_sampler | sampler | acceleration_structure
    count: int = 1
    writable: bool = True
    format: str | None = None  # a storage image's declared format (Vulkan name), None: any
    # what a WebGPU layout needs beyond Vulkan's: an image's texel type (float, sint,
    # uint) and view dimension, whether it is multisampled, whether an image or sampler is
    # used for depth comparison, and whether a storage image is ever read
    texel: str = "float"
    dim: str = "2d"
    multisampled: bool = False
    compared: bool = False
    readable: bool = True


@dataclass
class Reflection:
    stage: str
    entry: str = "main"
    descriptors: dict[str, DescriptorInfo] = field(default_factory=dict)
    push_constant_size: int = 0
    local_size: tuple[int, int, int] = (1, 1, 1)

    def sets(self) -> dict[int, list[DescriptorInfo]]:
        out: dict[int, list[DescriptorInfo]] = {}
        for d in sorted(self.descriptors.values(), key=lambda d: (d.set, d.binding)):
            out.setdefault(d.set, []).append(d)
        return out


# SPIR-V opcodes and enums the reflection needs (SPIR-V 1.6 specification)
_OP_NAME, _OP_MEMBER_NAME, _OP_ENTRY_POINT, _OP_EXECUTION_MODE = 5, 6, 15, 16
_OP_TYPE_INT, _OP_TYPE_FLOAT, _OP_TYPE_VECTOR, _OP_TYPE_MATRIX = 21, 22, 23, 24
_OP_TYPE_IMAGE, _OP_TYPE_SAMPLER, _OP_TYPE_SAMPLED_IMAGE = 25, 26, 27
_OP_TYPE_ARRAY, _OP_TYPE_RUNTIME_ARRAY, _OP_TYPE_STRUCT, _OP_TYPE_POINTER = 28, 29, 30, 32
_OP_CONSTANT, _OP_VARIABLE, _OP_DECORATE, _OP_MEMBER_DECORATE = 43, 59, 71, 72
_OP_TYPE_ACCEL = 5341
_DEC_BLOCK, _DEC_BUFFER_BLOCK, _DEC_OFFSET, _DEC_BINDING, _DEC_SET = 2, 3, 35, 33, 34
_DEC_NON_WRITABLE, _DEC_NON_READABLE = 24, 25
_OP_FUNCTION, _OP_FUNCTION_PARAMETER, _OP_FUNCTION_CALL, _OP_LOAD = 54, 55, 57, 61
_OP_COPY_OBJECT, _OP_SAMPLED_IMAGE = 83, 86
# sampling with a depth reference (Dref): the image is a depth texture, the sampler compares
_DREF_OPS = {89, 90, 93, 94, 97, 307, 308, 311, 312, 316}
_DIMS = {0: "1d", 1: "2d", 2: "3d", 3: "cube"}
_SC_UNIFORM_CONSTANT, _SC_UNIFORM, _SC_PUSH_CONSTANT, _SC_STORAGE_BUFFER = 0, 2, 9, 12
_MODE_LOCAL_SIZE, _MODE_LOCAL_SIZE_ID, _OP_EXECUTION_MODE_ID = 17, 38, 331
_MODELS = {0: "vert", 4: "frag", 5: "comp", 5267: "task", 5268: "mesh", 5364: "task",
           5365: "mesh", 5313: "rgen", 5314: "rint", 5315: "rahit", 5316: "rchit",
           5317: "rmiss", 5318: "rcall"}


# OpTypeImage's Image Format operand -> the Vulkan format it requires (SPIR-V 1.6, 3.11;
# Vulkan "Compatibility Between SPIR-V Image Formats and Vulkan Formats"); 0 is Unknown
_IMAGE_FORMATS = {
    1: "R32G32B32A32_SFLOAT", 2: "R16G16B16A16_SFLOAT", 3: "R32_SFLOAT", 4: "R8G8B8A8_UNORM",
    5: "R8G8B8A8_SNORM", 6: "R32G32_SFLOAT", 7: "R16G16_SFLOAT", 8: "B10G11R11_UFLOAT_PACK32",
    9: "R16_SFLOAT", 10: "R16G16B16A16_UNORM", 11: "A2B10G10R10_UNORM_PACK32",
    12: "R16G16_UNORM", 13: "R8G8_UNORM", 14: "R16_UNORM", 15: "R8_UNORM",
    16: "R16G16B16A16_SNORM", 17: "R16G16_SNORM", 18: "R8G8_SNORM", 19: "R16_SNORM",
    20: "R8_SNORM", 21: "R32G32B32A32_SINT", 22: "R16G16B16A16_SINT", 23: "R8G8B8A8_SINT",
    24: "R32_SINT", 25: "R32G32_SINT", 26: "R16G16_SINT", 27: "R8G8_SINT", 28: "R16_SINT",
    29: "R8_SINT", 30: "R32G32B32A32_UINT", 31: "R16G16B16A16_UINT", 32: "R8G8B8A8_UINT",
    33: "R32_UINT", 34: "A2B10G10R10_UINT_PACK32", 35: "R32G32_UINT", 36: "R16G16_UINT",
    37: "R8G8_UINT", 38: "R16_UINT", 39: "R8_UINT", 40: "R64_UINT", 41: "R64_SINT"}
_OP_FUNCTION_END = 56


def check_module(code: bytes) -> None:
    """A ShaderCompileError unless ``code`` is whole SPIR-V: the magic number, whole words,
    instructions that fit, and a last function that ends (a truncated file fails one)."""
    if len(code) < 20 or struct.unpack_from("<I", code)[0] != 0x07230203:
        raise ShaderCompileError("not a SPIR-V module (bad magic number)")
    if len(code) % 4:
        raise ShaderCompileError(f"malformed SPIR-V: {len(code)} bytes is not whole words")
    words = struct.unpack(f"<{len(code) // 4}I", code)
    i, last = 5, -1
    while i < len(words):
        count = words[i] >> 16
        if count == 0 or i + count > len(words):
            raise ShaderCompileError(f"malformed SPIR-V: instruction at word {i} "
                                     f"{'is empty' if count == 0 else 'runs past the end'}")
        last, i = words[i] & 0xFFFF, i + count
    if last != _OP_FUNCTION_END:
        raise ShaderCompileError("malformed SPIR-V: the module does not end with a function "
                                 "end (truncated?)")


def readonly_blocks_marked(code: bytes) -> bytes:
    """``code`` with every storage-buffer variable whose block members are all NonWritable
    (GLSL ``readonly buffer``) decorated NonWritable itself. glslang marks the members only;
    naga takes a StorageBuffer-class variable's access from the variable's decorations, so
    without this it reads the block as read-write, and a read-only-storage layout (the only
    kind a vertex stage may bind) fails to match. A no-op for modules without such blocks."""
    words = list(struct.unpack(f"<{len(code) // 4}I", code))
    readonly: dict[int, set[int]] = {}  # struct -> members decorated NonWritable
    members: dict[int, int] = {}  # struct -> member count
    pointers: dict[int, int] = {}  # pointer type -> pointee
    marked: set[int] = set()  # ids already NonWritable
    variables: list[tuple[int, int]] = []  # (pointer type, variable) of StorageBuffer class
    last_annotation = 0
    i = 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        args = words[i + 1:i + count]
        if op == _OP_MEMBER_DECORATE and args[2] == _DEC_NON_WRITABLE:
            readonly.setdefault(args[0], set()).add(args[1])
        elif op == _OP_DECORATE and args[1] == _DEC_NON_WRITABLE:
            marked.add(args[0])
        elif op == _OP_TYPE_STRUCT:
            members[args[0]] = count - 2
        elif op == _OP_TYPE_POINTER:
            pointers[args[0]] = args[2]
        elif op == _OP_VARIABLE and args[2] == _SC_STORAGE_BUFFER:
            variables.append((args[0], args[1]))
        if op in (_OP_DECORATE, _OP_MEMBER_DECORATE):
            last_annotation = i + count
        i += count
    add = [v for ptr, v in variables if v not in marked and
           0 < members.get(pointers.get(ptr, -1), 0) == len(readonly.get(pointers[ptr], ()))]
    if not add or not last_annotation:
        return code
    extra = [w for v in add for w in ((3 << 16) | _OP_DECORATE, v, _DEC_NON_WRITABLE)]
    words[last_annotation:last_annotation] = extra
    return struct.pack(f"<{len(words)}I", *words)


def _string(words: list[int]) -> str:
    raw = b"".join(struct.pack("<I", w) for w in words)
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


def reflect(code: bytes) -> Reflection:
    """Descriptor sets and bindings, push-constant size and workgroup size from SPIR-V;
    a module that is not whole SPIR-V is a ShaderCompileError (``check_module``)."""
    check_module(code)
    try:
        return _reflect(list(struct.unpack(f"<{len(code) // 4}I", code)))
    except (IndexError, KeyError, RecursionError) as e:
        # operands missing or ids that point nowhere: garbled, though whole, SPIR-V
        raise ShaderCompileError(f"malformed SPIR-V: {type(e).__name__} while reflecting "
                                 f"({e})") from None


def _reflect(words: list[int]) -> Reflection:
    names: dict[int, str] = {}
    decorations: dict[int, dict[int, int]] = {}
    member_offsets: dict[int, dict[int, int]] = {}
    decorations_of_members: dict[int, dict[int, set[int]]] = {}
    types: dict[int, tuple] = {}
    constants: dict[int, int] = {}
    variables: list[tuple[int, int, int]] = []  # (type pointer id, result id, storage class)
    refl = Reflection("?")
    flow = _Flow()
    size_ids: tuple[int, int, int] | None = None
    i = 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        if count == 0:
            raise ShaderCompileError("malformed SPIR-V: zero-length instruction")
        args = words[i + 1:i + count]
        if op == _OP_NAME:
            names[args[0]] = _string(args[1:])
        elif op == _OP_ENTRY_POINT:
            refl.stage = _MODELS.get(args[0], str(args[0]))
            refl.entry = _string(args[2:])
        elif op == _OP_EXECUTION_MODE and args[1] == _MODE_LOCAL_SIZE:
            refl.local_size = (args[2], args[3], args[4])
        elif op == _OP_EXECUTION_MODE_ID and args[1] == _MODE_LOCAL_SIZE_ID:
            size_ids = (args[2], args[3], args[4])  # constants: resolved after the walk
        elif op == _OP_DECORATE:
            decorations.setdefault(args[0], {})[args[1]] = args[2] if len(args) > 2 else 1
        elif op == _OP_MEMBER_DECORATE:
            if args[2] == _DEC_OFFSET:
                member_offsets.setdefault(args[0], {})[args[1]] = args[3]
            decorations_of_members.setdefault(args[0], {}).setdefault(args[1], set()).add(
                args[2])
        elif op == _OP_TYPE_INT:
            types[args[0]] = ("scalar", args[1] // 8, "sint" if args[2] else "uint")
        elif op == _OP_TYPE_FLOAT:
            types[args[0]] = ("scalar", args[1] // 8, "float")
        elif op == _OP_TYPE_VECTOR:
            types[args[0]] = ("vector", args[1], args[2])
        elif op == _OP_TYPE_MATRIX:
            types[args[0]] = ("matrix", args[1], args[2])
        elif op == _OP_TYPE_IMAGE:
            # dim, sampled (1 yes, 2 storage), image format, texel type, arrayed, multisampled
            types[args[0]] = ("image", args[2], args[6], args[7], args[1], args[4], args[5])
        elif op == _OP_TYPE_SAMPLER:
            types[args[0]] = ("sampler",)
        elif op == _OP_TYPE_SAMPLED_IMAGE:
            types[args[0]] = ("sampled_image", args[1])
        elif op == _OP_TYPE_ARRAY:
            types[args[0]] = ("array", args[1], args[2])
        elif op == _OP_TYPE_RUNTIME_ARRAY:
            types[args[0]] = ("runtime_array", args[1])
        elif op == _OP_TYPE_STRUCT:
            types[args[0]] = ("struct", tuple(args[1:]))
        elif op == _OP_TYPE_POINTER:
            types[args[0]] = ("pointer", args[1], args[2])
        elif op == _OP_TYPE_ACCEL:
            types[args[0]] = ("accel",)
        elif op == _OP_CONSTANT and len(args) >= 3:
            constants[args[1]] = args[2]
        elif op == _OP_VARIABLE:
            variables.append((args[0], args[1], args[2]))
        else:
            flow.note(op, args)
        i += count
    if size_ids is not None:
        refl.local_size = tuple(constants.get(k, 1) for k in size_ids)  # type: ignore[assignment]

    def size_of(t: int) -> int:
        kind = types.get(t, ("?",))
        if kind[0] == "scalar":
            return kind[1]
        if kind[0] == "vector":
            return size_of(kind[1]) * kind[2]
        if kind[0] == "matrix":
            return size_of(kind[1]) * kind[2]
        if kind[0] == "array":
            stride = decorations.get(t, {}).get(6, size_of(kind[1]))  # ArrayStride
            return stride * constants.get(kind[2], 1)
        if kind[0] == "struct":
            offs = member_offsets.get(t, {})
            return max((offs.get(k, 0) + size_of(m) for k, m in enumerate(kind[1])), default=0)
        return 0

    dref = flow.compared()
    for ptr, var, storage in variables:
        pointee = types.get(ptr, ("?", 0, 0))[2] if types.get(ptr, ("?",))[0] == "pointer" \
            else None
        if pointee is None:
            continue
        if storage == _SC_PUSH_CONSTANT:
            refl.push_constant_size = max(refl.push_constant_size, size_of(pointee))
            continue
        dec = decorations.get(var, {})
        if _DEC_BINDING not in dec or storage not in (_SC_UNIFORM_CONSTANT, _SC_UNIFORM,
                                                      _SC_STORAGE_BUFFER):
            continue
        t, count = pointee, 1
        compared = var in dref
        while types.get(t, ("?",))[0] in ("array", "runtime_array"):
            kind = types[t]
            count *= constants.get(kind[2], 1) if kind[0] == "array" else 0
            t = kind[1]
        kind = types.get(t, ("?",))
        tdec = decorations.get(t, {})
        if storage == _SC_STORAGE_BUFFER or (storage == _SC_UNIFORM and _DEC_BUFFER_BLOCK in
                                             tdec):
            what = "storage_buffer"
        elif storage == _SC_UNIFORM:
            what = "uniform_buffer"
        elif kind[0] == "sampled_image":
            what = "combined_image_sampler"
        elif kind[0] == "image":
            what = "storage_image" if kind[2] == 2 else "sampled_image"
        elif kind[0] == "sampler":
            what = "sampler"
        elif kind[0] == "accel":
            what = "acceleration_structure"
        else:
            continue
        name = names.get(var) or names.get(t) or f"set{dec.get(_DEC_SET, 0)}_b{dec[_DEC_BINDING]}"
        members = decorations_of_members.get(t, {})
        # a readonly block decorates its members, not the variable
        writable = _DEC_NON_WRITABLE not in dec and not (
            members and all(_DEC_NON_WRITABLE in m for m in members.values()))
        fmt = _IMAGE_FORMATS.get(kind[3]) if what == "storage_image" else None
        image = kind if kind[0] == "image" else types.get(kind[1], ("?",)) \
            if kind[0] == "sampled_image" else None
        extra: dict = {}
        if image is not None and image[0] == "image":
            texel = types.get(image[4], ("?", 0, "float"))
            extra = {"texel": texel[2] if texel[0] == "scalar" else "float",
                     "dim": _DIMS.get(image[1], "2d") + ("-array" if image[5] else ""),
                     "multisampled": bool(image[6])}
        refl.descriptors[name] = DescriptorInfo(
            name, dec.get(_DEC_SET, 0), dec[_DEC_BINDING], what, count, writable,
            None if fmt is None else f"VK_FORMAT_{fmt}", compared=compared,
            readable=_DEC_NON_READABLE not in dec, **extra)
    return refl


@dataclass(frozen=True)
class BlockMember:
    """One member of a uniform block as the SPIR-V lays it out: its name, byte offset and
    GLSL type (``float``, ``int``, ``uint`` (a GLSL ``bool`` too: SPIR-V blocks hold bools
    as uints), ``vec3``, ``ivec2``, ``mat4``, ``float[4]``, ``struct Light``, ...)."""

    name: str
    offset: int
    type: str


def uniform_blocks(code: bytes) -> dict[str, tuple[BlockMember, ...]]:
    """The members of every uniform block in ``code``, by binding name as ``reflect()``
    names the binding (the variable's name, else the block's), in declaration order."""
    check_module(code)
    words = struct.unpack(f"<{len(code) // 4}I", code)
    names: dict[int, str] = {}
    members: dict[tuple[int, int], str] = {}
    offsets: dict[tuple[int, int], int] = {}
    buffer_blocks: set[int] = set()  # uniform-class blocks that are storage buffers (old GLSL)
    types: dict[int, tuple] = {}
    constants: dict[int, int] = {}
    variables: list[tuple[int, int]] = []  # (pointer type, variable) of Uniform class
    i = 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        args = words[i + 1:i + count]
        if op == _OP_NAME:
            names[args[0]] = _string(list(args[1:]))
        elif op == _OP_MEMBER_NAME:
            members[args[0], args[1]] = _string(list(args[2:]))
        elif op == _OP_MEMBER_DECORATE and args[2] == _DEC_OFFSET:
            offsets[args[0], args[1]] = args[3]
        elif op == _OP_DECORATE and args[1] == _DEC_BUFFER_BLOCK:
            buffer_blocks.add(args[0])
        elif op in (_OP_TYPE_INT, _OP_TYPE_FLOAT, _OP_TYPE_VECTOR, _OP_TYPE_MATRIX,
                    _OP_TYPE_ARRAY, _OP_TYPE_RUNTIME_ARRAY, _OP_TYPE_STRUCT, _OP_TYPE_POINTER):
            types[args[0]] = (op, *args[1:])
        elif op == _OP_CONSTANT and len(args) >= 3:
            constants[args[1]] = args[2]
        elif op == _OP_VARIABLE and args[2] == _SC_UNIFORM:
            variables.append((args[0], args[1]))
        i += count

    def glsl(t: int) -> str:
        op, *rest = types.get(t, (0,))
        if op == _OP_TYPE_FLOAT:
            return {32: "float", 64: "double"}.get(rest[0], f"float{rest[0]}_t")
        if op == _OP_TYPE_INT:
            return {(32, 1): "int", (32, 0): "uint"}.get(
                (rest[0], rest[1]), f"{'u' * (not rest[1])}int{rest[0]}_t")
        if op == _OP_TYPE_VECTOR:
            prefix = {"float": "", "double": "d", "int": "i", "uint": "u"}.get(
                glsl(rest[0]), glsl(rest[0]) + "_")
            return f"{prefix}vec{rest[1]}"
        if op == _OP_TYPE_MATRIX:
            rows = int(glsl(rest[0])[-1])
            return f"mat{rest[1]}" if rows == rest[1] else f"mat{rest[1]}x{rows}"
        if op == _OP_TYPE_ARRAY:
            return f"{glsl(rest[0])}[{constants.get(rest[1], '?')}]"
        if op == _OP_TYPE_RUNTIME_ARRAY:
            return f"{glsl(rest[0])}[]"
        if op == _OP_TYPE_STRUCT:
            return f"struct {names[t]}" if names.get(t) else "struct"
        return "?"

    out: dict[str, tuple[BlockMember, ...]] = {}
    for ptr, var in variables:
        block = types.get(ptr, (0, 0, 0))[2]
        while types.get(block, (0,))[0] == _OP_TYPE_ARRAY:  # an array of blocks
            block = types[block][1]
        if types.get(block, (0,))[0] != _OP_TYPE_STRUCT or block in buffer_blocks:
            continue
        name = names.get(var) or names.get(block)
        if name:
            out[name] = tuple(BlockMember(members.get((block, k), f"member{k}"),
                                          offsets.get((block, k), -1), glsl(m))
                              for k, m in enumerate(types[block][1:]))
    return out


class _Flow:
    """Where loaded images and samplers come from (variables, through loads, copies and
    function parameters), to find those a Dref instruction samples."""

    def __init__(self) -> None:
        self.sources: dict[int, set[int]] = {}  # id -> ids it may hold the value of
        self.sampled: dict[int, tuple[int, int]] = {}  # sampled image -> (image, sampler)
        self.dref: list[int] = []  # sampled images sampled with a depth reference
        self.params: dict[int, list[int]] = {}  # function -> its parameters
        self.calls: list[tuple[int, list[int]]] = []
        self._function = 0

    def note(self, op: int, args: list[int]) -> None:
        if op in (_OP_LOAD, _OP_COPY_OBJECT):
            self.sources.setdefault(args[1], set()).add(args[2])
        elif op == _OP_SAMPLED_IMAGE:
            self.sampled[args[1]] = (args[2], args[3])
        elif op in _DREF_OPS:
            self.dref.append(args[2])
        elif op == _OP_FUNCTION:
            self._function = args[1]
            self.params[self._function] = []
        elif op == _OP_FUNCTION_PARAMETER:
            self.params.setdefault(self._function, []).append(args[1])
        elif op == _OP_FUNCTION_CALL:
            self.calls.append((args[2], args[3:]))

    def compared(self) -> set[int]:
        """Every id a Dref-sampled image or its sampler may come from (variables included)."""
        if not self.dref:
            return set()
        for fn, call_args in self.calls:
            for param, arg in zip(self.params.get(fn, []), call_args, strict=False):
                self.sources.setdefault(param, set()).add(arg)
        seen: set[int] = set()
        todo = [i for s in self.dref for i in self.sampled.get(s, ())]
        while todo:
            i = todo.pop()
            if i not in seen:
                seen.add(i)
                todo.extend(self.sources.get(i, ()))
        return seen
