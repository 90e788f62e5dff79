"""Shader sources: which files make a pass's program (one rule for both backends), and WGSL.

Built-in passes are written once, in Vulkan GLSL (``rfw.spirv`` compiles and reflects them
for both backends). WGSL stays for third-party passes that only target wgpu: for those,
``#include "name.wgsl"`` searches the shader's own folder, then ``shaders/common``.
``#define NAME value``, ``#ifdef``/``#ifndef``/``#else``/``#endif`` select variants; defines
passed by the host override the file's. Every output line remembers its file and line, so a
compile error points at the source the user wrote.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

from .graph.errors import GraphError

COMMON = Path(__file__).resolve().parents[1] / "shaders" / "common"


class ShaderError(GraphError):
    """A shader that does not preprocess, compile or match its pass: names file and line."""


# shader stages by file-name suffix (``<name>.<stage>.glsl``), in pipeline order
STAGES = ("comp", "vert", "frag", "task", "mesh", "rgen", "rchit", "rahit", "rmiss", "rint",
          "rcall")

# the dicts of every rfw.bench.inputs.watching_shaders open now: each file a compile reads
watchers: list[dict[Path, bytes]] = []


def read_source(path: Path) -> bytes:
    """A shader file's bytes, as both compilers read a shader and its includes (GLSL for the
    SPIR-V cache key, WGSL to preprocess), seen by every dict in :data:`watchers`."""
    data = path.read_bytes()
    for seen in watchers:
        seen.setdefault(path.resolve(), data)
    return data


def program_files(folder: Path, shader: str, *, owner: str = "") -> list[Path]:
    """The files that make a pass's program, the one rule both backends follow.

    ``x.<stage>.glsl`` and ``x.wgsl`` name one file; a bare name ``x`` means every
    ``x.<stage>.glsl`` beside the pass, in stage order (``shader = "forward"`` ->
    ``forward.vert.glsl`` + ``forward.frag.glsl``). A ShaderError names what is missing."""
    who = f"pass '{owner}': " if owner else ""
    if shader.endswith((".glsl", ".wgsl")):
        path = folder / shader
        if not path.is_file():
            raise ShaderError(f"{who}shader {path} not found")
        return [path]
    found = [folder / f"{shader}.{stage}.glsl" for stage in STAGES
             if (folder / f"{shader}.{stage}.glsl").is_file()]
    if not found:
        raise ShaderError(f"{who}no shader {shader}.<stage>.glsl in {folder} (stages: "
                          f"{', '.join(STAGES)})")
    return found


@dataclass(frozen=True)
class Source:
    text: str
    lines: tuple[tuple[str, int], ...]  # output line (0-based) -> (file, 1-based line)
    hash: str

    def where(self, line: int) -> str:
        """``file:line`` for a 1-based line of the preprocessed text."""
        if 1 <= line <= len(self.lines):
            f, n = self.lines[line - 1]
            return f"{f}:{n}"
        return f"<generated>:{line}"


_DIRECTIVE = re.compile(r"^\s*#\s*(include|define|undef|ifdef|ifndef|else|endif)\b\s*(.*)$")


def preprocess(path: str | Path, defines: dict[str, object] | None = None,
               search: tuple[Path, ...] = ()) -> Source:
    """Expand includes and conditionals; substitute defined names as whole words."""
    path = Path(path)
    host = {k: str(v) for k, v in (defines or {}).items()}
    env: dict[str, str] = dict(host)
    out: list[str] = []
    where: list[tuple[str, int]] = []
    _expand(path, env, host, out, where, [*search, path.parent, COMMON], set())
    text = "\n".join(out) + "\n"
    digest = hashlib.sha256(text.encode()).hexdigest()
    return Source(text, tuple(where), digest)


def _expand(path: Path, env: dict[str, str], host: dict[str, str], out: list[str],
            where: list[tuple[str, int]], search: list[Path], once: set[Path]) -> None:
    try:
        data = read_source(path)
    except OSError as e:
        raise ShaderError(f"{path}: cannot read shader: {e.strerror or e}") from None
    try:
        lines = data.decode("utf-8").splitlines()
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise ShaderError(f"{path}:{line}: not UTF-8 (byte {e.start}: "
                          f"{data[e.start:e.end].hex()})") from None
    once.add(path.resolve())
    active = [True]  # one entry per open conditional
    for n, line in enumerate(lines, 1):
        m = _DIRECTIVE.match(line)
        if m is None:
            if all(active):
                out.append(_substitute(line, env))
                where.append((str(path), n))
            continue
        word, rest = m.group(1), m.group(2).strip()
        here = f"{path}:{n}"
        if word == "ifdef" or word == "ifndef":
            active.append((rest in env) == (word == "ifdef"))
        elif word == "else":
            if len(active) == 1:
                raise ShaderError(f"{here}: #else without #ifdef")
            active[-1] = not active[-1]
        elif word == "endif":
            if len(active) == 1:
                raise ShaderError(f"{here}: #endif without #ifdef")
            active.pop()
        elif not all(active):
            continue
        elif word == "define":
            name, _, value = rest.partition(" ")
            if name not in host:  # the host's variant choice wins
                env[name] = value.strip() or "1"
        elif word == "undef":
            env.pop(rest, None)
        elif word == "include":
            name = rest.strip('"<> ')
            target = next((d / name for d in [path.parent, *search] if (d / name).is_file()),
                          None)
            if target is None:
                raise ShaderError(f"{here}: include '{name}' not found (searched "
                                  f"{', '.join(str(d) for d in [path.parent, *search])})")
            if target.resolve() not in once:  # every include is once-only, so no cycles
                _expand(target.resolve(), env, host, out, where, search, once)
    if len(active) != 1:
        raise ShaderError(f"{path}: #ifdef without #endif")


def _substitute(line: str, env: dict[str, str]) -> str:
    if not env:
        return line
    return re.sub(r"\b[A-Z_][A-Z0-9_]*\b", lambda m: env.get(m.group(0), m.group(0)), line)


@dataclass(frozen=True)
class BindingInfo:
    name: str
    group: int
    binding: int
    kind: str  # uniform | storage | read-only-storage | texture | storage-texture | sampler
    type: str  # the WGSL type as written
    access: str = ""  # for storage textures and buffers: read | write | read_write


_VAR = re.compile(
    r"@group\((\d+)\)\s*@binding\((\d+)\)\s*var(?:<([^>]*)>)?\s+(\w+)\s*:\s*([^;]+);")


def reflect(source: Source) -> dict[str, BindingInfo]:
    """Bindings declared in WGSL, by variable name: the shader is the truth for layouts."""
    text = re.sub(r"//[^\n]*", "", source.text)
    found: dict[str, BindingInfo] = {}
    for m in _VAR.finditer(text):
        group, binding, space, name, wtype = m.groups()
        wtype = " ".join(wtype.split())
        space = (space or "").replace(" ", "")
        if space.startswith("uniform"):
            kind, access = "uniform", ""
        elif space.startswith("storage"):
            access = space.split(",")[1] if "," in space else "read"
            kind = "read-only-storage" if access == "read" else "storage"
        elif wtype.startswith("texture_storage"):
            kind = "storage-texture"
            access = wtype.rsplit(",", 1)[-1].strip(" >")
        elif wtype.startswith("texture"):
            kind = "texture"
            access = ""
        elif wtype.startswith("sampler"):
            kind, access = "sampler", ""
        else:
            raise ShaderError(f"{source.where(text.count(chr(10), 0, m.start()) + 1)}: cannot "
                              f"reflect binding '{name}: {wtype}'")
        found[name] = BindingInfo(name, int(group), int(binding), kind, wtype, access)
    return found


_ERROR_LINE = re.compile(r"(?:wgsl|<source>|shader)?:(\d+):(\d+)")


def explain(source: Source, message: str) -> str:
    """Rewrite a compiler message so its line numbers point at the original files."""

    def fix(m: re.Match[str]) -> str:
        return f"{source.where(int(m.group(1)))}:{m.group(2)}"

    first = _ERROR_LINE.search(message)
    head = f"{source.where(int(first.group(1)))}: " if first else ""
    body = " ".join(_ERROR_LINE.sub(fix, message).split())
    return head + body
