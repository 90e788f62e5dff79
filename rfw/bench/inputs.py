"""What a benchmark run measured, as hashes: its config file, graph, scene and shaders.

The worker writes ``inputs: {config, graph, scene, shaders}`` (sha256 hex) into each run's
record, and ``shader_files: {path: sha256}`` for every shader source the run compiled, its
includes with it. ``rfw bench compare`` names each input that differs between OLD and NEW
(``config changed: configs/deferred.toml (sha 1a2b3c4d5e6f -> 7a8b9c0d1e2f)``), so a time
difference is read beside what changed; records written before this existed say "inputs
not recorded".

- ``config``: the config file's bytes.
- ``graph``: the frame graph the config built with the run's ``--set`` values and variants,
  as rfw TOML (passes, settings, slots, formats, size).
- ``scene``: a scene file's bytes (a ``.gltf`` with the buffers and images it names beside
  it); a built-in scene's name and parameters (``stress:1000``).
- ``shaders``: every shader file the run's passes compiled (GLSL through ``rfw.spirv``, WGSL
  through ``rfw.shaders``), includes too, seen while it compiled them.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
KEYS = ("config", "graph", "scene", "shaders")
SHORT = 12  # hex digits shown of a hash


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def shown(path: str | Path) -> str:
    """A path as reports show it: from the working folder or the rfw checkout if inside."""
    p = Path(path)
    for base in (Path.cwd(), ROOT):
        try:
            return str(p.resolve().relative_to(base.resolve()))
        except (ValueError, OSError):
            continue
    return str(p)


def _stable(path: Path) -> str:
    # a shader's name in the hash: from the rfw checkout, so the working folder changes nothing
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


@contextmanager
def _watching(registry: list[dict[Any, Any]]) -> Iterator[dict[Any, Any]]:
    """Inside: a new dict in ``registry`` (a compiler's list of watchers), removed after."""
    seen: dict[Any, Any] = {}
    registry.append(seen)
    try:
        yield seen
    finally:
        registry.remove(seen)


def watching_shaders() -> AbstractContextManager[dict[Path, bytes]]:
    """Inside: every shader file read for a compile, with its bytes (both compilers read a
    shader and its includes through :func:`rfw.shaders.read_source`)."""
    from ..shaders import watchers

    return _watching(watchers)


def watching_spirv() -> AbstractContextManager[dict[str, str]]:
    """Inside: every SPIR-V module :func:`rfw.spirv.compile_glsl` returned, as
    ``{"<file from the rfw checkout> <target> -DK=V...": sha256 of the SPIR-V}``."""
    from ..spirv import spirv_watchers

    return _watching(spirv_watchers)


def spirv_names(seen: dict[str, str]) -> dict[str, str]:
    """:func:`watching_spirv`'s modules, their files named from the rfw checkout, sorted."""
    out = {}
    for name, digest in seen.items():
        file, _, rest = name.partition(" ")
        out[f"{_stable(Path(file))} {rest}".strip()] = digest
    return dict(sorted(out.items()))


def scene_hash(scene: str) -> str:
    """A scene file's bytes (a ``.gltf`` with the files it names), or a built-in's name."""
    from ..scene import is_builtin

    p = Path(scene)
    if not p.is_file():
        if scene in ("default", "") or is_builtin(scene):
            return sha256(f"builtin:{scene or 'default'}".encode())
        return sha256(f"missing:{scene}".encode())
    data = p.read_bytes()
    return scene_file_hash(p, data, scene_names(p, data))


def scene_names(path: Path, data: bytes) -> list[str]:
    """The files beside the scene file ``path`` (its bytes ``data``) that it names: a
    ``.gltf``'s buffers and images (:func:`_gltf_files`), none for other formats."""
    return _gltf_files(data) if path.suffix.lower() == ".gltf" else []


def scene_file_hash(path: Path, data: bytes, names: list[str],
                    keep: dict[str, bytes] | None = None) -> str:
    """:func:`scene_hash` of the scene file ``path`` (its bytes ``data``) with the files
    ``names`` beside it that exist, each read once; into ``keep``, when given, their bytes
    by name."""
    h = hashlib.sha256(data)
    for name in names:
        extra = path.parent / name
        if extra.is_file():
            more = extra.read_bytes()
            h.update(b"\0" + name.encode() + b"\0" + more)
            if keep is not None:
                keep[name] = more
    return h.hexdigest()


def _gltf_files(data: bytes) -> list[str]:
    """The relative buffer and image URIs a glTF's bytes name (data: URIs are in the JSON)."""
    try:
        doc = json.loads(data.decode("utf-8"))
    except (ValueError, RecursionError):
        return []
    names = []
    for key in ("buffers", "images"):
        items = doc.get(key) if isinstance(doc, dict) else None
        for item in items if isinstance(items, list) else []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and uri and not uri.startswith("data:") \
                    and ":" not in uri and not os.path.isabs(uri):
                names.append(uri)
    return sorted(set(names))


def run_inputs(config: str | Path, cfg: Any, shader_sources: dict[Path, bytes]
               ) -> dict[str, Any]:
    """``{inputs: {config, graph, scene, shaders}, shader_files: {path: sha}}`` of one run:
    ``config`` its file, ``cfg`` the config with the run's settings applied, the shader
    sources :func:`watching_shaders` saw it compile."""
    from ..config import build
    from ..graph import to_toml

    files = {_stable(p): sha256(data) for p, data in shader_sources.items()}
    together = "".join(f"{name}\0{digest}\n" for name, digest in sorted(files.items()))
    return {"inputs": {"config": sha256(Path(config).read_bytes()),
                       "graph": sha256(to_toml(build(cfg).graph).encode()),
                       "scene": scene_hash(str(cfg.scene)),
                       "shaders": sha256(together.encode())},
            "shader_files": dict(sorted(files.items()))}


# ---------------------------------------------------------------------------------------------
# compare: what changed between OLD and NEW


def _of(records: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        if not r.get("error") and r.get("kind", "rfw") == "rfw":
            out.setdefault(r["variant"], []).append(r)
    return out


def input_changes(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[str]:
    """One line per input (config, graph, scene, shaders) that differs between the runs of
    a variant in OLD and in NEW, each said once; ``inputs not recorded`` for a side whose
    records have none (written before inputs were hashed); ``... differ between the runs``
    where the runs of one side measured different inputs (a file edited during the bench)."""
    olds, news = _of(old), _of(new)
    out: list[str] = []

    def say(line: str) -> None:
        if line not in out:
            out.append(line)

    for label in [k for k in olds if k in news]:
        sides = []
        for side, runs in (("OLD", olds[label]), ("NEW", news[label])):
            if any(not isinstance(r.get("inputs"), dict) for r in runs):
                say(f"inputs not recorded in {side} (results written before rfw hashed a "
                    "run's config, graph, scene and shaders): their changes are not reported")
                continue
            for key in KEYS:
                if len({r["inputs"].get(key) for r in runs}) > 1:
                    say(f"{label}: {key} differs between the runs of {side} (changed during "
                        "the bench?)")
            sides.append(runs[-1])
        if len(sides) != 2:
            continue
        a, b = sides
        for key in KEYS:
            was, now = a["inputs"].get(key), b["inputs"].get(key)
            if was != now:
                say(f"{key} changed: {_what(key, label, a, b)} (sha {_short(was)} -> "
                    f"{_short(now)})")
    return out


def _short(digest: Any) -> str:
    return str(digest)[:SHORT] if digest else "none"


def _what(key: str, label: str, a: dict[str, Any], b: dict[str, Any]) -> str:
    """The changed input in words: its file(s), or the variant whose graph it is."""
    if key == "config":
        return _pair(a.get("config_path"), b.get("config_path"))
    if key == "scene":
        return _pair(a.get("scene"), b.get("scene"), files=False)
    if key == "shaders":
        fa, fb = a.get("shader_files") or {}, b.get("shader_files") or {}
        parts = [f"{n}" for n in sorted(fa.keys() & fb.keys()) if fa[n] != fb[n]]
        parts += [f"{n} (new)" for n in sorted(fb.keys() - fa.keys())]
        parts += [f"{n} (gone)" for n in sorted(fa.keys() - fb.keys())]
        return ", ".join(parts) if parts else "shader files not recorded"
    return label


def _pair(was: Any, now: Any, *, files: bool = True) -> str:
    def name(x: Any) -> str:
        return shown(x) if files and x else str(x)

    return name(now) if was == now or not was else f"{name(was)} -> {name(now)}"
