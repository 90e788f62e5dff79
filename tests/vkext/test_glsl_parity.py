"""GLSL twins of WGSL passes: the same bindings, workgroup sizes, stage interfaces and uniform
byte layouts, so a Vulkan backend runs the pass's unchanged ``record()``.

Needs glslang and spirv-tools only (no Vulkan device): every variant compiles through
``vkext.spirv``, passes ``spirv-val``, and its reflection is compared with ``rfw.shaders``'s
reflection of the WGSL. Uniform offsets come from ``spirv-dis`` (OpMemberDecorate Offset) and
are checked against WGSL's layout rules and against ``Settings.pack()``.
"""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

from passes.deferred_lighting.deferred_lighting import DeferredLightingPass
from passes.gbuffer.gbuffer import GBufferPass
from passes.shadow_map.shadow_map import ShadowMapPass
from passes.tonemap.tonemap import TonemapPass
from rfw.shaders import preprocess
from rfw.shaders import reflect as reflect_wgsl
from vkext.spirv import compile_glsl
from vkext.spirv import reflect as reflect_spirv

pytestmark = pytest.mark.skipif(
    any(shutil.which(t) is None for t in ("glslangValidator", "spirv-val", "spirv-dis")),
    reason="needs glslangValidator and spirv-tools (scripts/setup-system.sh)")

ROOT = Path(__file__).resolve().parents[2]
TARGET = "vulkan1.3"

# every define combination the pass's record() can ask for
VARIANTS = {
    ShadowMapPass: [{}],
    GBufferPass: [{}],  # prepass changes pipeline state only, not the shader
    DeferredLightingPass: [{}, {"HAS_SHADOW": 1}, {"HAS_AO": 1}, {"HAS_SHADOW": 1, "HAS_AO": 1},
                           {"HAS_VISIBILITY": 1, "HAS_AO": 1}],
    TonemapPass: [{}],
}
CASES = [pytest.param(cls, d, id=f"{cls.__name__}-{'+'.join(d) or 'base'}")
         for cls, variants in VARIANTS.items() for d in variants]

KIND = {"uniform": "uniform_buffer", "texture": "sampled_image",
        "storage-texture": "storage_image", "sampler": "sampler",
        "read-only-storage": "storage_buffer", "storage": "storage_buffer"}
IMAGE_FORMAT = {"rgba16float": "Rgba16f", "rgba8unorm": "Rgba8", "rgba32float": "Rgba32f",
                "r32float": "R32f", "rgba8snorm": "Rgba8Snorm", "r32uint": "R32ui"}


@pytest.fixture(autouse=True)
def private_cache(private_spirv_cache):
    pass


# ---------------------------------------------------------------------------------------------
# the shaders of a pass


def wgsl_path(cls) -> Path:
    return ROOT / "passes" / cls.__module__.split(".")[1] / cls.shader


def twins(wgsl: Path) -> list[Path]:
    """``X.comp.wgsl`` -> ``X.comp.glsl``; ``X.wgsl`` -> ``X.vert.glsl`` (+ ``X.frag.glsl``)."""
    if wgsl.name.endswith(".comp.wgsl"):
        return [wgsl.with_name(wgsl.name.removesuffix(".wgsl") + ".glsl")]
    stem = wgsl.name.removesuffix(".wgsl")
    frag = wgsl.with_name(f"{stem}.frag.glsl")
    return [wgsl.with_name(f"{stem}.vert.glsl"), *([frag] if frag.is_file() else [])]


@dataclass
class Module:
    path: Path
    code: bytes
    dis: Dis


def compile_all(cls, defines: dict, tmp_path: Path) -> list[Module]:
    out = []
    for path in twins(wgsl_path(cls)):
        assert path.is_file(), f"{cls.__name__}: missing GLSL twin {path.name}"
        spv = compile_glsl(path, defines)
        blob = tmp_path / f"{path.name}.spv"
        blob.write_bytes(spv.code)
        val = subprocess.run(["spirv-val", "--target-env", TARGET, str(blob)],
                             capture_output=True, text=True, check=False)
        assert val.returncode == 0, f"{path.name} {defines}: spirv-val: {val.stdout}{val.stderr}"
        dis = subprocess.run(["spirv-dis", "--raw-id", str(blob)], capture_output=True,
                             text=True, check=True).stdout
        out.append(Module(path, spv.code, Dis(dis)))
    return out


# ---------------------------------------------------------------------------------------------
# spirv-dis text: names, decorations, types, variables


class Dis:
    """The parts of a disassembled module the layout checks read."""

    def __init__(self, text: str):
        self.names: dict[str, str] = {}
        self.member_names: dict[tuple[str, int], str] = {}
        self.offsets: dict[tuple[str, int], int] = {}
        self.decor: dict[str, dict[str, list[str]]] = {}
        self.member_decor: dict[tuple[str, int], set[str]] = {}
        self.types: dict[str, list[str]] = {}
        self.consts: dict[str, int] = {}
        self.variables: dict[str, tuple[str, str]] = {}  # id -> (pointer type, storage class)
        for line in text.splitlines():
            tok = re.findall(r'"[^"]*"|\S+', line.split(";", 1)[0])
            if not tok:
                continue
            result = None
            if len(tok) > 2 and tok[1] == "=":
                result, tok = tok[0], tok[2:]
            op, args = tok[0], tok[1:]
            if op == "OpName":
                self.names[args[0]] = args[1].strip('"')
            elif op == "OpMemberName":
                self.member_names[(args[0], int(args[1]))] = args[2].strip('"')
            elif op == "OpMemberDecorate":
                key = (args[0], int(args[1]))
                if args[2] == "Offset":
                    self.offsets[key] = int(args[3])
                self.member_decor.setdefault(key, set()).add(args[2])
            elif op == "OpDecorate":
                self.decor.setdefault(args[0], {})[args[1]] = args[2:]
            elif op.startswith("OpType"):
                self.types[result] = [op, *args]
            elif op == "OpConstant":
                self.consts[result] = int(args[1], 0) if re.fullmatch(r"-?\d+", args[1]) else 0
            elif op == "OpVariable":
                self.variables[result] = (args[0], args[1])

    def pointee(self, var: str) -> str:
        return self.types[self.variables[var][0]][2]

    def type_name(self, t: str) -> str:
        """A leaf type in WGSL spelling: f32, vec3<f32>, mat4x4<f32>..."""
        op, *args = self.types[t]
        if op == "OpTypeFloat":
            return "f32"
        if op == "OpTypeInt":
            return "i32" if args[1] == "1" else "u32"
        if op == "OpTypeVector":
            return f"vec{args[1]}<{self.type_name(args[0])}>"
        if op == "OpTypeMatrix":
            col = self.types[args[0]]
            return f"mat{args[1]}x{col[2]}<{self.type_name(col[1])}>"
        raise AssertionError(f"unexpected type {op}")

    def flatten(self, t: str, base: int = 0, prefix: str = "") -> dict[str, tuple]:
        """{path: (offset, type)} for leaves; {path[]: ('array', stride, count)} for arrays."""
        op, *args = self.types[t]
        if op == "OpTypeStruct":
            out: dict[str, tuple] = {}
            for k, member in enumerate(args):
                name = self.member_names[(t, k)]
                out |= self.flatten(member, base + self.offsets[(t, k)],
                                    f"{prefix}.{name}" if prefix else name)
            return out
        if op == "OpTypeArray":
            stride = int(self.decor[t]["ArrayStride"][0])
            return {f"{prefix}[]": ("array", stride, self.consts[args[1]]),
                    **self.flatten(args[0], base, f"{prefix}[]")}
        return {prefix: (base, self.type_name(t))}

    def uniform_blocks(self) -> dict[str, str]:
        """Instance name -> block struct type, for every uniform buffer."""
        return {self.names[v]: self.pointee(v) for v, (_, sc) in self.variables.items()
                if sc == "Uniform" and v in self.names}

    def image_formats(self) -> dict[str, str]:
        out = {}
        for v, (_, sc) in self.variables.items():
            t = self.types.get(self.pointee(v), [""]) if sc == "UniformConstant" else [""]
            if t[0] == "OpTypeImage" and t[6] == "2":  # Sampled 2: storage image
                out[self.names[v]] = t[7]
        return out

    def interface(self, storage: str) -> dict[int, str]:
        """Location -> type of the stage's user inputs or outputs."""
        return {int(self.decor[v]["Location"][0]): self.type_name(self.pointee(v))
                for v, (_, sc) in self.variables.items()
                if sc == storage and "Location" in self.decor.get(v, {})}

    def invariant_position(self) -> bool:
        builtins = {v: d["BuiltIn"][0] for v, d in self.decor.items() if "BuiltIn" in d}
        if "Position" in builtins.values() and any(
                builtins.get(v) == "Position" and "Invariant" in self.decor[v] for v in builtins):
            return True
        # gl_PerVertex block: the member decorated BuiltIn Position
        for (t, k), decs in self.member_decor.items():
            if "Invariant" in decs and self.member_names.get((t, k)) == "gl_Position":
                return True
        return False


# ---------------------------------------------------------------------------------------------
# WGSL layout rules (uniform address space) and stage interfaces


def _normalize(wtype: str) -> str:
    wtype = "".join(wtype.split())
    short = {"f": "f32", "i": "i32", "u": "u32"}
    if m := re.fullmatch(r"(vec\d|mat\dx\d)([fiu])", wtype):
        return f"{m.group(1)}<{short[m.group(2)]}>"
    return wtype


def _split_top(text: str) -> list[str]:
    """Split at commas outside <...>."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        depth += (ch == "<") - (ch == ">")
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return [p for p in (*parts, cur) if p.strip()]


def wgsl_structs(text: str) -> dict[str, list[tuple[dict[str, str], str, str]]]:
    """struct name -> [(attributes, member, type)]."""
    text = re.sub(r"//[^\n]*", "", text)
    out = {}
    for name, body in re.findall(r"struct\s+(\w+)\s*\{([^}]*)\}", text):
        members = []
        for part in _split_top(body):
            attrs = dict(re.findall(r"@(\w+)(?:\(([^)]*)\))?", part))
            decl = re.sub(r"@\w+(?:\([^)]*\))?", "", part).strip()
            member, _, wtype = decl.partition(":")
            members.append((attrs, member.strip(), _normalize(wtype)))
        out[name] = members
    return out


class WgslLayout:
    def __init__(self, text: str):
        self.structs = wgsl_structs(text)

    def align_size(self, t: str) -> tuple[int, int]:
        if t in ("f32", "i32", "u32"):
            return 4, 4
        if m := re.fullmatch(r"vec(\d)<\w+>", t):
            n = int(m.group(1))
            return (8, 8) if n == 2 else (16, 4 * n)
        if m := re.fullmatch(r"mat(\d)x(\d)<\w+>", t):
            a, s = self.align_size(f"vec{m.group(2)}<f32>")
            return a, int(m.group(1)) * _round(a, s)
        if m := re.fullmatch(r"array<(.+),(\d+)u?>", t):
            a, s = self.align_size(m.group(1))
            return a, int(m.group(2)) * _round(a, s)
        _, align, end = self._members(t)
        return align, _round(align, end)

    def _members(self, t: str) -> tuple[list[int], int, int]:
        offsets, align, end = [], 1, 0
        for attrs, _, mtype in self.structs[t]:
            a, s = self.align_size(mtype)
            a, s = int(attrs.get("align") or a), int(attrs.get("size") or s)
            offsets.append(_round(a, end))
            end = offsets[-1] + s
            align = max(align, a)
        return offsets, align, end

    def flatten(self, t: str, base: int = 0, prefix: str = "") -> dict[str, tuple]:
        if m := re.fullmatch(r"array<(.+),(\d+)u?>", t):
            a, s = self.align_size(m.group(1))
            return {f"{prefix}[]": ("array", _round(a, s), int(m.group(2))),
                    **self.flatten(m.group(1), base, f"{prefix}[]")}
        if t in self.structs:
            out: dict[str, tuple] = {}
            offsets, _, _ = self._members(t)
            for (_, member, mtype), off in zip(self.structs[t], offsets, strict=True):
                out |= self.flatten(mtype, base + off, f"{prefix}.{member}" if prefix else member)
            return out
        return {prefix: (base, t)}


def _round(align: int, n: int) -> int:
    return -(-n // align) * align


def wgsl_interface(text: str, entry: str) -> tuple[dict[int, str], dict[int, str]]:
    """(inputs, outputs) by location of a WGSL entry point."""
    text = re.sub(r"//[^\n]*", "", text)
    m = re.search(rf"fn\s+{entry}\s*\(([^)]*(?:\([^)]*\)[^)]*)*)\)\s*(?:->\s*([^{{]+))?\{{", text)
    assert m, f"no entry point {entry}"
    structs = wgsl_structs(text)

    def locations(decls: list[str]) -> dict[int, str]:
        out = {}
        for decl in decls:
            attrs = dict(re.findall(r"@(\w+)(?:\(([^)]*)\))?", decl))
            wtype = _normalize(re.sub(r"@\w+(?:\([^)]*\))?", "", decl).split(":")[-1])
            if wtype in structs:
                out |= {int(a["location"]): t for a, _, t in structs[wtype] if "location" in a}
            elif "location" in attrs:
                out[int(attrs["location"])] = wtype
        return out

    return locations(_split_top(m.group(1))), locations([m.group(2) or ""])


# ---------------------------------------------------------------------------------------------
# tests


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_bindings_match_wgsl(cls, defines, tmp_path):
    source = preprocess(wgsl_path(cls), defines)
    wgsl = reflect_wgsl(source)
    want = {b.name: (b.group, b.binding, KIND[b.kind]) for b in wgsl.values()}
    got: dict[str, tuple[int, int, str]] = {}
    images: dict[str, str] = {}
    for mod in compile_all(cls, defines, tmp_path):
        for d in reflect_spirv(mod.code).descriptors.values():
            entry = (d.set, d.binding, d.kind)
            assert got.setdefault(d.name, entry) == entry, \
                f"{mod.path.name}: '{d.name}' differs between stages"
        images |= mod.dis.image_formats()
    assert got == want
    # storage images carry WGSL's texel format
    formats = {b.name: IMAGE_FORMAT[b.type.split("<")[1].split(",")[0].strip()]
               for b in wgsl.values() if b.kind == "storage-texture"}
    assert images == formats


@pytest.mark.parametrize("cls", list(VARIANTS))
def test_variants_cover_every_define(cls):
    # a new #ifdef in the WGSL needs a new variant here (and in the GLSL twin)
    text = wgsl_path(cls).read_text()
    used = set(re.findall(r"^\s*#\s*ifn?def\s+(\w+)", text, re.M))
    assert used <= {k for d in VARIANTS[cls] for k in d}


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_stages_and_workgroup_size(cls, defines, tmp_path):
    text = preprocess(wgsl_path(cls), defines).text
    mods = compile_all(cls, defines, tmp_path)
    stages = [reflect_spirv(m.code).stage for m in mods]
    if cls.shader.endswith(".comp.wgsl"):
        m = re.search(r"@workgroup_size\(([^)]*)\)", text)
        size = (*(int(x) for x in m.group(1).split(",")), 1, 1)[:3]
        assert stages == ["comp"]
        assert reflect_spirv(mods[0].code).local_size == size
        return
    assert stages[0] == "vert" and stages[1:] in ([], ["frag"])
    assert (len(stages) == 2) == ("fn fs_main" in text)
    vert_in, vert_out = wgsl_interface(text, "vs_main")
    assert mods[0].dis.interface("Input") == vert_in
    assert mods[0].dis.interface("Output") == vert_out
    assert mods[0].dis.invariant_position() == ("@invariant" in re.sub(r"//[^\n]*", "", text))
    if len(mods) == 2:
        frag_in, frag_out = wgsl_interface(text, "fs_main")
        assert mods[1].dis.interface("Input") == frag_in
        assert mods[1].dis.interface("Output") == frag_out


@pytest.mark.parametrize(("cls", "defines"), CASES)
def test_uniform_layouts_match_wgsl(cls, defines, tmp_path):
    source = preprocess(wgsl_path(cls), defines)
    wgsl = reflect_wgsl(source)
    layout = WgslLayout(source.text)
    for mod in compile_all(cls, defines, tmp_path):
        for name, block in mod.dis.uniform_blocks().items():
            assert name in wgsl, f"{mod.path.name}: uniform '{name}' is not in the WGSL"
            wtype = _normalize(wgsl[name].type)
            got, want = mod.dis.flatten(block), layout.flatten(wtype)
            assert got == want, f"{mod.path.name}: uniform '{name}' differs from WGSL {wtype}"
            # the block may end before WGSL's struct padding, never after it
            end = max(v[0] + layout.align_size(v[1])[1] for v in got.values() if len(v) == 2)
            assert end <= layout.align_size(wtype)[1]


@pytest.mark.parametrize("cls", [c for c in VARIANTS if "u_params" in
                                 reflect_wgsl(preprocess(wgsl_path(c)))])
def test_settings_pack_lands_on_glsl_offsets(cls, tmp_path):
    # distinct values per field, read back at the offsets glslang assigned
    fields = cls.Params.fields()
    values = {}
    for k, (name, (kind, _)) in enumerate(fields.items()):
        if kind is float:
            values[name] = 0.25 + k
        elif kind is int:
            values[name] = 3 + k
        elif kind is bool:
            values[name] = True
        else:
            values[name] = tuple(0.5 + k + j for j in range(len(kind.__args__)))
    data = cls.Params(**values).pack()
    mod = compile_all(cls, {}, tmp_path)[0]
    flat = mod.dis.flatten(mod.dis.uniform_blocks()["u_params"])
    assert set(flat) == set(values)
    for name, value in values.items():
        off, t = flat[name]
        n = int(t[3]) if t.startswith("vec") else 1
        fmt = {"f32": "f", "i32": "i", "u32": "I"}[t.split("<")[-1].rstrip(">")] * n
        got = struct.unpack_from("<" + fmt, data, off)
        want = tuple(value) if isinstance(value, tuple) else (int(value) if fmt == "I"
                                                              else value,)
        assert got == pytest.approx(want), f"{cls.__name__}.Params.{name} at offset {off}"


def assert_variants_cover(cls, variants: list[dict], *includes: str) -> None:
    """Every ``#ifdef`` of ``cls``'s WGSL (and of ``includes`` beside it) is set by one of
    ``variants``, so the define combinations checked are all the shader has."""
    path = wgsl_path(cls)
    text = path.read_text() + "".join((path.parent / n).read_text() for n in includes)
    used = set(re.findall(r"^\s*#\s*ifn?def\s+(\w+)", text, re.M))
    assert used <= {k for d in variants for k in d}
