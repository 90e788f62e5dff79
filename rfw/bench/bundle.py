"""Benchmark bundles: one file, ``OUT/bundle.tar``, with everything that defines a bench.

Every ``rfw bench`` writes it beside ``results.jsonl``. It is one uncompressed tar (the
images are PNG already) so that it travels as one file to another machine, is checked as a
whole (the manifest names the sha256 of every member: a damaged or edited member is found
before anything runs) and is the same bytes for the same bench (members sorted, times,
owners and modes fixed). Its members:

- ``manifest.json`` (``schema``, ``version``): the plan (size, frames, warm-up, repeats,
  order and seed, timeout, ``--reference``, ``--diff-scale``), every job with its config
  (the file's bytes are the member ``config``), its effective settings (``--set`` and the
  ``--vary`` choices), the graph it builds (as rfw TOML, a member), its camera table, its
  scene (a built-in's name and the rfw version; a file's sha256, embedded when all of a
  bench's scene files fit in ``MAX_EMBED`` bytes, else its path, and ``embedded`` null
  says so), backend; the rfw commit and version, each variant's adapters (device, driver,
  backend), the SPIR-V and shader-source hashes of every module the runs used, the sha256
  of the bench's ``report.md`` and ``report.html``, and ``files``: every member's sha256;
- ``results.jsonl`` as the bench wrote it: every run's raw per-frame GPU, CPU and wall ms
  per pass, its device and driver, camera path frames and input hashes;
- the files the report reads, at their paths in the bench folder (``runs/<id>/r<k>/
  image.png``, ``truth.json`` and ``reference/`` with ``--reference pathtrace``), so that
  the bundle unpacked is a bench folder ``rfw bench report`` reads;
- ``inputs/<sha12>/<name>``: the config files, graphs and embedded scene files.

``rfw bench replay BUNDLE`` re-runs it (:mod:`rfw.bench.replay`); ``rfw bench report
BUNDLE`` writes its report again from it alone.
"""

from __future__ import annotations

import io
import json
import os
import tarfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import RfwError
from ..fileio import atomic_write, inside
from .inputs import sha256

SCHEMA = "rfw.bench.bundle"
VERSION = 1
NAME = "bundle.tar"
MANIFEST = "manifest.json"
RESULTS = "results.jsonl"
MAX_EMBED = 64 * 1024 * 1024  # scene bytes a bundle holds; larger scenes: hash and path
# what the report writes (a regenerated report writes it again) and what the bundle is
REPORT_FILES = ("report.md", "report.html")
NOT_BUNDLED = {*REPORT_FILES, "results.csv", "truth.csv", "charts", "images", NAME,
               "compare", "original", "inputs", "replay.json"}
RUN_NOT_BUNDLED = {"record.json", "log.txt"}  # record.json is its line of results.jsonl


# ---------------------------------------------------------------------------------------------
# writing


def write_bundle(folder: Path, plan: Any, *, reference: str | None = None,
                 diff_scale: str = "own") -> tuple[Path, dict[str, Any]]:
    """Write ``folder/bundle.tar`` of the bench in ``folder`` (its ``results.jsonl``, run
    images and reports written) run from ``plan`` (:class:`rfw.bench.runner.Plan`); returns
    its path and the manifest written into it."""
    from .. import __version__
    from .records import parse_results

    folder = Path(folder)
    members: dict[str, bytes] = {RESULTS: (folder / RESULTS).read_bytes()}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder)
        if not path.is_file() or path.is_symlink() or rel.parts[0] in NOT_BUNDLED \
                or rel.parts[0].startswith(".") or rel.name in RUN_NOT_BUNDLED \
                or rel.as_posix() == RESULTS:
            continue
        members[rel.as_posix()] = path.read_bytes()
    records = parse_results(members[RESULTS], folder / RESULTS)
    embedded = [0]  # scene bytes embedded so far
    jobs = [_job(j, plan, members, embedded) for j in plan.jobs]
    first = records[0] if records else {}
    spirv: dict[str, str] = {}
    shaders: dict[str, str] = {}
    adapters: dict[str, list[list[Any]]] = {}
    for r in records:
        if r.get("error"):
            continue
        spirv.update(r.get("spirv") or {})
        shaders.update(r.get("shader_files") or {})
        seen = adapters.setdefault(r["variant_id"], [])
        adapter = [r.get("device"), r.get("driver"), r.get("backend")]
        if adapter not in seen:
            seen.append(adapter)
    manifest = {
        "schema": SCHEMA, "version": VERSION,
        "rfw": {"version": __version__, "commit": first.get("rfw_commit"),
                "commit_source": first.get("rfw_commit_source")},
        "plan": {"size": list(plan.size), "frames": plan.frames, "warmup": plan.warmup,
                 "repeat": plan.repeat, "order": plan.order, "seed": plan.seed,
                 "timeout": plan.timeout, "peer_frames": plan.peer_frames,
                 "notes": list(plan.notes), "reference": reference,
                 "diff_scale": diff_scale},
        "jobs": jobs, "adapters": adapters,
        "spirv": dict(sorted(spirv.items())), "shader_files": dict(sorted(shaders.items())),
        "timings": f"{RESULTS}: per run, passes[].gpu_ms/cpu_ms and frame.gpu_ms/cpu_ms/"
                   "wall_ms, one number per timed frame",
        "images": sorted(n for n in members if n.endswith(".png") and n.startswith("runs/")),
        "reports": {n: sha256((folder / n).read_bytes()) for n in REPORT_FILES
                    if (folder / n).is_file()},
    }
    path = folder / NAME
    return path, pack(path, manifest, members)


def _job(job: Any, plan: Any, members: dict[str, bytes], embedded: list[int]
         ) -> dict[str, Any]:
    """One job of the manifest; its config, graph and scene files go into ``members``."""
    out: dict[str, Any] = {"kind": job.kind, "label": job.label, "id": job.id,
                           "backend": job.backend, "sets": list(job.sets),
                           "varied": list(job.varied), "scene_arg": job.scene}
    if job.kind == "peer":
        out["peer"] = job.peer
        out["scene"] = _scene(job.scene, members, embedded)
        return out
    from ..config import build
    from ..graph import to_toml
    from .runner import _check

    config = Path(job.config)
    data = config.read_bytes()
    digest = sha256(data)
    member = f"inputs/{digest[:12]}/{config.name}"
    members[member] = data
    w, h = plan.size
    cfg = _check(config, [*job.sets, f"size={w}x{h}"])
    graph = to_toml(build(cfg).graph).encode()
    members[f"inputs/graphs/{job.id}.toml"] = graph
    out.update(config={"member": member, "path": str(config), "sha256": digest},
               graph={"member": f"inputs/graphs/{job.id}.toml", "sha256": sha256(graph)},
               camera=json.loads(json.dumps(cfg.camera, default=list)),
               scene=_scene(job.scene or cfg.scene, members, embedded))
    return out


def _scene(scene: str | None, members: dict[str, bytes], embedded: list[int]
           ) -> dict[str, Any]:
    """A scene as the manifest names it: a built-in by name and rfw version, a file by its
    sha256 (:func:`rfw.bench.inputs.scene_hash`), embedded while the bench's scene files
    fit in ``MAX_EMBED``."""
    from .. import __version__
    from ..scene import is_builtin
    from .inputs import scene_file_hash, scene_names

    p = Path(scene) if scene else None
    if p is None or not p.is_file():
        name = scene or "default"
        return {"kind": "builtin" if name == "default" or is_builtin(name) else "missing",
                "name": name, "rfw_version": __version__}
    data = p.read_bytes()
    names = scene_names(p, data)
    files = [p.name, *names]
    safe = all(_safe_name(f) for f in files)
    sizes = [(p.parent / f).stat().st_size for f in files if (p.parent / f).is_file()]
    fits = embedded[0] + sum(sizes) <= MAX_EMBED
    kept: dict[str, bytes] = {}  # the files it names, read for the hash, kept to embed
    digest = scene_file_hash(p, data, names, kept if safe and fits else None)
    out = {"kind": "file", "name": p.name, "path": str(p), "sha256": digest,
           "embedded": None}
    base = f"inputs/{digest[:12]}"
    if f"{base}/{p.name}" in members:
        out["embedded"] = f"{base}/{p.name}"
        return out
    if not safe:
        out["why"] = "a file it names is outside its folder: not embedded"
    elif not fits:
        out["why"] = (f"over the {MAX_EMBED >> 20} MiB of scene files a bundle embeds: "
                      "replay needs this file at this path with this sha256")
    else:
        for f in files:
            if f == p.name:
                members[f"{base}/{f}"] = data
            elif f in kept:
                members[f"{base}/{f}"] = kept[f]
        embedded[0] += sum(sizes)
        out["embedded"] = f"{base}/{p.name}"
    return out


def pack(path: Path, manifest: dict[str, Any], members: dict[str, bytes]) -> dict[str, Any]:
    """Write the tar: ``manifest`` (its ``files`` set to the members' sha256) first, then
    ``members`` sorted, each with a fixed time, owner and mode (the same bench, the same
    bytes); returns the manifest as written."""
    manifest = {**manifest, "files": {n: sha256(members[n]) for n in sorted(members)}}
    items = [(MANIFEST, (json.dumps(manifest, indent=1, sort_keys=True) + "\n").encode()),
             *((n, members[n]) for n in sorted(members))]

    def write(f: Any) -> None:
        with tarfile.open(fileobj=f, mode="w", format=tarfile.PAX_FORMAT) as tar:
            for name, data in items:
                info = tarfile.TarInfo(name)
                info.size, info.mtime, info.mode = len(data), 0, 0o644
                tar.addfile(info, io.BytesIO(data))

    atomic_write(path, write)
    return manifest


# ---------------------------------------------------------------------------------------------
# reading


@dataclass
class Bundle:
    """A bundle read and checked: its manifest and its members' bytes."""

    path: Path
    manifest: dict[str, Any]
    members: dict[str, bytes]

    @property
    def plan(self) -> dict[str, Any]:
        return self.manifest["plan"]

    def bench_files(self) -> list[str]:
        """The members that make the bench folder (results, run images, references)."""
        return [n for n in self.members if not n.startswith("inputs/")]

    def extract(self, dest: Path, names: list[str] | None = None, *, strip: str = "") -> None:
        """Write ``names`` (default: the bench files) under ``dest``, at their member paths
        less the prefix ``strip``; a file already holding a member's bytes is left as it is."""
        for name in self.bench_files() if names is None else names:
            target = inside(dest, name.removeprefix(strip))
            target.parent.mkdir(parents=True, exist_ok=True)
            data = self.members[name]
            if not (target.is_file() and target.read_bytes() == data):
                atomic_write(target, lambda f, d=data: f.write(d))


def read_bundle(path: str | Path) -> Bundle:
    """The bundle at ``path`` (a ``bundle.tar``, or a bench folder holding one), checked:
    a tar of regular files with safe names, a manifest of this schema and version, every
    member present with the sha256 the manifest names, and nothing else (RfwError, one
    line, naming the file)."""
    path = Path(path)
    if path.is_dir():
        path = path / NAME
    where = str(path)
    if not path.is_file():
        raise RfwError("no bundle here (rfw bench writes OUT/bundle.tar)" if not path.exists()
                       else "not a regular file", file=where)
    members: dict[str, bytes] = {}
    try:
        with tarfile.open(path, mode="r:") as tar:
            for info in tar:
                if not info.isfile() or not _safe_name(info.name):
                    raise RfwError(f"not a bundle: member {info.name!r} is not a plain file "
                                   "with a relative name", file=where)
                if info.name in members:
                    raise RfwError(f"damaged: member {info.name!r} is in it twice", file=where)
                f = tar.extractfile(info)
                members[info.name] = f.read() if f is not None else b""
    except (tarfile.TarError, EOFError, OSError) as e:
        raise RfwError(f"not a readable bundle (tar: {e})", file=where) from None
    data = members.pop(MANIFEST, None)
    if data is None:
        raise RfwError(f"not a bundle: no {MANIFEST}", file=where)
    try:
        manifest = json.loads(data.decode("utf-8"))
    except (ValueError, RecursionError) as e:
        raise RfwError(f"damaged: {MANIFEST} is not JSON ({e})", file=where) from None
    _check_manifest(manifest, members, where)
    return Bundle(path, manifest, members)


def _check_manifest(m: Any, members: dict[str, bytes], where: str) -> None:
    if not isinstance(m, dict) or m.get("schema") != SCHEMA:
        raise RfwError(f"not a bundle: {MANIFEST} is no {SCHEMA} manifest", file=where)
    version = m.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise RfwError(f"damaged: {MANIFEST}: version {version!r}", file=where)
    if version > VERSION:
        raise RfwError(f"written by a newer rfw (bundle version {version}; this rfw reads "
                       f"up to {VERSION})", file=where)
    files = m.get("files")
    if not isinstance(files, dict):
        raise RfwError(f"damaged: {MANIFEST} lists no files", file=where)
    for name in sorted(set(files) | set(members)):
        if name not in members:
            raise RfwError(f"damaged: {name} is missing", file=where)
        if name not in files:
            raise RfwError(f"damaged: {name} is not in the manifest", file=where)
        if sha256(members[name]) != files[name]:
            raise RfwError(f"damaged: {name} does not match its sha256 in the manifest",
                           file=where)
    if RESULTS not in members:
        raise RfwError(f"not a bundle: no {RESULTS}", file=where)
    plan, jobs = m.get("plan"), m.get("jobs")
    if not isinstance(plan, dict) or not isinstance(jobs, list) or not all(
            isinstance(j, dict) and j.get("kind") in ("rfw", "peer") for j in jobs):
        raise RfwError(f"damaged: {MANIFEST} has no plan and jobs", file=where)
    for key in ("size", "frames", "warmup", "repeat", "order", "seed", "timeout"):
        if key not in plan:
            raise RfwError(f"damaged: {MANIFEST}: plan has no {key}", file=where)
    for j in jobs:
        if j["kind"] == "rfw" and (not isinstance(j.get("config"), dict)
                                   or j["config"].get("member") not in members):
            raise RfwError(f"damaged: {MANIFEST}: job {j.get('label')!r} names no config in "
                           "the bundle", file=where)


def _safe_name(name: str) -> bool:
    p = PurePosixPath(name)
    return bool(name) and not p.is_absolute() and ".." not in p.parts and "\\" not in name \
        and "\0" not in name and not os.path.isabs(name)
