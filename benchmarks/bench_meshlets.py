"""Vertex pipeline against mesh pipeline, with each meshlet culling combination (issue 5).

Renders ``configs/meshlet.toml`` (deferred shading on Vulkan) with the classic vertex-shader
G-buffer and with the task + mesh shader G-buffer under every combination of the meshlet
culling tests (normal cone, frustum, occlusion), on two heavy fetched scenes, each from a
camera with little occlusion and one with heavy occlusion:

- ``dragon_grid``: the 871k-triangle Stanford dragon instanced K x K on a grid (``--grid``);
  ``open`` looks down on the whole grid from above, ``row`` stands low in front of the first
  row and looks along the rows, so the front dragons hide the rest;
- ``city``: Sionna RT's Munich (2,367 meshes); ``aerial`` frames the whole city from above,
  ``street`` stands at eye height in the free street cell nearest the centre, looking down
  its longest free line of sight.

Cameras are computed from the scene bounds (and for ``street`` from a height map of the
triangles), never hard-coded. Per measurement it records the per-pass GPU times (timestamp
queries; medians over ``--frames`` frames after ``--warmup`` frames), the G-buffer time (all
passes but shading, so the early pass, the depth pyramid and the late pass of two-phase
occlusion all count), the frame total, the meshlets culled by each test as fractions of the
meshlets submitted, the meshlets and triangles drawn, the GPU bytes of scene geometry of each
path and the frame graph's transient bytes. Figures are compared as ratios against the vertex
path of the same run, same scene, camera and size.

Usage::

    rfw scenes fetch dragon city                       # once (network): GLBs in the cache
    .venv/bin/python benchmarks/bench_meshlets.py      # everything, defaults by device
    .venv/bin/python benchmarks/bench_meshlets.py --scenes dragon_grid --grid 3 \\
        --variants vertex,mesh+cone+frustum --frames 10 --size 1280x720
    .venv/bin/python benchmarks/bench_meshlets.py --list          # variants, their overrides
    .venv/bin/python benchmarks/bench_meshlets.py --export-scenes .scenes   # compact .npz
    .venv/bin/python benchmarks/bench_meshlets.py --from-jsonl a.jsonl b.jsonl   # merge

``--images DIR`` also writes every measurement's picture (to check the cameras and that both
paths draw the same), ``--digest`` prints the digest of the sources that records carry.

Each measurement runs in a process of its own (``--inprocess`` runs them all in this one,
sharing one device: faster, less isolated); the variants' order is rotated on every repeat
so that none always runs first. Defaults depend on the device: on lavapipe (a CPU) 640x360,
a 2x2 grid, 5 frames after 2 warm-up frames, one repeat; on a GPU 1920x1080, a 4x4 grid
(14M triangles), 100 frames after 10 warm-up frames, 2 repeats. ``--budget`` stops starting
measurements when the next would likely end past it (the report covers what was done).

Scenes are read from ``--scene-dir`` folders (``<name>.npz`` as ``--export-scenes`` writes
them: float32 positions, snorm8 normals, uint32 indices, instances and materials, compressed)
and then from the ``rfw scenes`` cache (``<name>.glb``). ``benchmarks/device_meshlets.sh``
runs the benchmark from ``.scenes/`` on a machine without network.

Output: a markdown report (``--out``, default ``out/bench_meshlets.md``) that is also printed,
with a verdict per scene and camera (mesh time / vertex time for each culling combination),
and one JSON line per measurement (``--jsonl``, default beside ``--out``) with the device,
driver, rfw commit, a digest of the sources, scene, camera, variant, overrides and size.

The override strings of each geometry path and culling test are in the tables below
(:data:`GEOMETRY`, :data:`CULLING`); a variant whose overrides the config refuses is reported
as unavailable, not run. By default the vertex path and the mesh path with every combination
of cone, frustum and occlusion culling run (per-triangle culling off), plus everything on.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.scene.model import Instance, Material, Mesh, Scene  # noqa: E402

CONFIG = ROOT / "configs" / "meshlet.toml"

# --------------------------------------------------------------------------------------------
# what is compared: --set overrides of CONFIG, easy to change

# the geometry path
GEOMETRY = {"vertex": ("geometry=vertex",), "mesh": ("geometry=meshlet",)}

# culling test -> (overrides turning it on, overrides turning it off); a variant sets every
# test of the table one way or the other
CULLING = {
    "cone": (("culling.cone=true",), ("culling.cone=false",)),  # normal cone, per meshlet
    "frustum": (("culling.frustum=true",), ("culling.frustum=false",)),  # instances, meshlets
    # two-phase: early pass (last frame's visible), depth pyramid, late pass (the rest)
    "occlusion": (("culling.occlusion=true",), ("culling.occlusion=false",)),
    "triangles": (("culling.triangles=true",), ("culling.triangles=false",)),  # backfaces
}

# the variants run by default: the vertex path, the mesh path with every combination of
# these tests (the others off), and the extra combinations listed
DEFAULT_TESTS = ("cone", "frustum", "occlusion")
EXTRA_VARIANTS = ("mesh+cone+frustum+occlusion+triangles",)

# passes that shade (the same work for both paths); every other pass is G-buffer work
SHADING_PASSES = ("lighting", "tonemap", "shadow")

# scene -> its cameras (name, how much of the scene they hide)
CAMERAS = {"dragon_grid": {"open": "little", "row": "heavy"},
           "city": {"aerial": "little", "street": "heavy"}}
SOURCES = {"dragon_grid": "dragon", "city": "city"}  # the fetched scene each one is built from

# per device kind: size, grid, frames, warmup, repeats (any of them overridden by its flag)
DEFAULTS = {"cpu": {"size": (640, 360), "grid": 2, "frames": 5, "warmup": 2, "repeats": 1},
            "gpu": {"size": (1920, 1080), "grid": 4, "frames": 100, "warmup": 10, "repeats": 2}}

YFOV = 50.0  # degrees, every camera
EYE_HEIGHT = 1.7  # street camera, scene units (metres in the city)
NPZ_FORMAT = "rfw-bench-scene/1"
MIB = 1 << 20


def variant_names(tests: tuple[str, ...] | None = None) -> list[str]:
    """``vertex`` and ``mesh`` with every subset of ``tests`` (default: all of
    :data:`CULLING`), in a fixed order: fewer tests first, then the table's order."""
    tests = tuple(CULLING) if tests is None else tests
    names = ["vertex"]
    for n in range(len(tests) + 1):
        for combo in itertools.combinations(tests, n):
            names.append("+".join(["mesh", *combo]))
    return names


def default_variants() -> list[str]:
    return variant_names(DEFAULT_TESTS) + [v for v in EXTRA_VARIANTS
                                           if v not in variant_names(DEFAULT_TESTS)]


def variant_tests(name: str) -> tuple[str, set[str]]:
    geometry, *tests = name.split("+")
    return geometry, set(tests)


def canonical(name: str) -> str:
    """``mesh+frustum+cone`` -> ``mesh+cone+frustum`` (the table's order)."""
    geometry, tests = variant_tests(name)
    known = list(CULLING)
    return "+".join([geometry, *sorted(tests, key=lambda t: (known.index(t) if t in known
                                                            else len(known), t))])


def _order(name: str) -> tuple[int, str]:
    names = variant_names()
    return (names.index(name) if name in names else len(names), name)


# --------------------------------------------------------------------------------------------
# overrides against the config


def _accepted(overrides: list[str]) -> bool:
    from rfw.config import apply_overrides, build, load_config
    from rfw.graph import GraphError

    try:
        build(apply_overrides(load_config(CONFIG), overrides))
    except (GraphError, ValueError, TypeError):
        return False
    return True


def resolve_variants(names: list[str]) -> dict[str, list[str] | str]:
    """Each variant's overrides, or why it is unavailable (a string: the config refused
    them, e.g. a switch it does not have)."""
    out: dict[str, list[str] | str] = {}
    for name in names:
        geometry, tests = variant_tests(name)
        overrides = list(GEOMETRY[geometry])
        if geometry == "mesh":
            for test, (on, off) in CULLING.items():
                overrides += on if test in tests else off
        out[name] = overrides if _accepted(overrides) else \
            "the config refuses " + " ".join(overrides)
    return out


# --------------------------------------------------------------------------------------------
# scenes: compact .npz, loading, the benchmark scenes


def export_npz(scene: Scene, path: Path, license_text: str = "") -> int:
    """``scene`` as a compressed ``.npz`` (what ``load_npz`` reads); returns its bytes.
    Untextured scenes only: uvs and tangents are not kept (tangents are recomputed)."""
    if scene.textures:
        raise ValueError(f"{scene.name}: has textures, which the .npz format leaves out")
    meshes = scene.meshes
    verts = np.cumsum([0] + [len(m.positions) for m in meshes])
    idx = np.cumsum([0] + [len(m.indices) for m in meshes])
    meta = {"format": NPZ_FORMAT, "name": scene.name,
            "materials": [dataclasses.asdict(m) for m in scene.materials],
            "meshes": [m.name for m in meshes],
            "instances": [i.name for i in scene.instances], "license": license_text}
    normals = np.concatenate([m.normals for m in meshes]) if meshes else np.zeros((0, 3))
    arrays = {
        "positions": np.concatenate([m.positions for m in meshes]).astype(np.float32),
        "normals": np.clip(np.round(normals * 127.0), -127, 127).astype(np.int8),
        "indices": np.concatenate([m.indices for m in meshes]).astype(np.uint32),
        "mesh_vertices": verts.astype(np.int64), "mesh_indices": idx.astype(np.int64),
        "mesh_material": np.array([m.material for m in meshes], np.int32),
        "instance_mesh": np.array([i.mesh for i in scene.instances], np.int32),
        "instance_transform": np.array([i.transform for i in scene.instances], np.float32),
        "meta": np.frombuffer(json.dumps(meta).encode(), np.uint8),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    tmp.replace(path)
    return path.stat().st_size


def load_npz(path: Path) -> Scene:
    from rfw.scene.util import compute_tangents, normalize

    with np.load(path) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        if meta.get("format") != NPZ_FORMAT:
            raise ValueError(f"{path}: not a {NPZ_FORMAT} file")
        pos, nor, ind = z["positions"], z["normals"], z["indices"]
        mv, mi, mm = z["mesh_vertices"], z["mesh_indices"], z["mesh_material"]
        meshes = []
        for k, name in enumerate(meta["meshes"]):
            p = np.ascontiguousarray(pos[mv[k]:mv[k + 1]])
            n = normalize(nor[mv[k]:mv[k + 1]].astype(np.float32) / 127.0).astype(np.float32)
            i = np.ascontiguousarray(ind[mi[k]:mi[k + 1]])
            meshes.append(Mesh(name, p, n, np.zeros((len(p), 2), np.float32),
                               compute_tangents(p, n, None, i), i, int(mm[k])))
        instances = [Instance(int(m), np.array(t, np.float32), name) for m, t, name in
                     zip(z["instance_mesh"], z["instance_transform"], meta["instances"],
                         strict=True)]
    materials = [Material(**{k: tuple(v) if isinstance(v, list) else v for k, v in m.items()})
                 for m in meta["materials"]]
    return Scene(meta["name"], meshes, materials, [], instances, source=str(path))


def find_source(name: str, scene_dirs: list[Path]) -> Path:
    """``<dir>/<name>.npz`` in the first scene dir that has it, else the fetched GLB."""
    for d in scene_dirs:
        if (d / f"{name}.npz").is_file():
            return d / f"{name}.npz"
    from rfw.scene.fetch import default_cache

    glb = default_cache() / f"{name}.glb"
    if glb.is_file():
        return glb
    where = ", ".join(str(d) for d in scene_dirs) or "no --scene-dir"
    raise FileNotFoundError(f"scene '{name}': no {name}.npz in {where} and no {glb} "
                            f"(run: rfw scenes fetch {name})")


def load_source(name: str, scene_dirs: list[Path]) -> Scene:
    path = find_source(name, scene_dirs)
    if path.suffix == ".npz":
        return load_npz(path)
    from rfw.scene import load_scene

    return load_scene(path)


def translate(x: float, y: float, z: float) -> np.ndarray:
    t = np.identity(4, np.float32)
    t[:3, 3] = (x, y, z)
    return t


def dragon_grid(dragon: Scene, k: int) -> Scene:
    """The dragon's one mesh instanced ``k`` x ``k`` on the XZ plane, standing on y = 0,
    centred on the origin; side by side along X (nearly touching, so a row is a wall seen
    from the front) and half a body apart along Z."""
    mesh = dragon.meshes[dragon.instances[0].mesh]
    lo, hi = mesh.bounds()
    size = hi - lo
    sx, sz = size[0] * 1.05, size[2] * 1.5
    centre = (lo + hi) / 2
    instances = []
    for i in range(k):
        for j in range(k):
            x = (i - (k - 1) / 2) * sx - centre[0]
            z = (j - (k - 1) / 2) * sz - centre[2]
            instances.append(Instance(0, translate(x, -lo[1], z), f"dragon_{i}_{j}"))
    mat = dragon.materials[mesh.material]
    return Scene(f"dragon_grid{k}", [dataclasses.replace(mesh, material=0)], [mat], [],
                 instances, source=dragon.source)


def build_scene(name: str, grid: int, scene_dirs: list[Path]) -> Scene:
    source = load_source(SOURCES[name], scene_dirs)
    return dragon_grid(source, grid) if name == "dragon_grid" else source


# --------------------------------------------------------------------------------------------
# cameras from the scene bounds


def _camera(eye: np.ndarray, target: np.ndarray, znear: float, zfar: float) -> dict[str, Any]:
    return {"position": [float(v) for v in eye], "target": [float(v) for v in target],
            "up": [0.0, 1.0, 0.0], "yfov": YFOV, "znear": float(znear), "zfar": float(zfar)}


def _orbit(lo: np.ndarray, hi: np.ndarray, elevation: float, azimuth: float,
           target_y: float) -> dict[str, Any]:
    """Looking at the bounds' centre from ``elevation`` / ``azimuth`` degrees, at the
    distance where their bounding sphere's radius spans 85% of the vertical half-view (flat
    scenes seen from above then fill the view; the corners may leave it)."""
    centre = (lo + hi) / 2
    centre[1] = target_y
    r = float(np.linalg.norm(hi - lo)) / 2
    d = 0.85 * r / math.tan(math.radians(YFOV) / 2)
    e, a = math.radians(elevation), math.radians(azimuth)
    eye = centre + d * np.array([math.cos(e) * math.sin(a), math.sin(e),
                                 math.cos(e) * math.cos(a)])
    return _camera(eye, centre, d * 0.01, d + 2 * r)


def grid_cameras(scene: Scene, aspect: float) -> dict[str, dict[str, Any]]:
    lo, hi = scene.bounds()
    height = hi[1] - lo[1]
    # row: at mid-dragon height in front of the first row (+Z), close enough that the row
    # fills the width of the view, looking along -Z: the rows behind shrink into its outline
    half_w = math.atan(aspect * math.tan(math.radians(YFOV) / 2))
    d = 0.95 * (hi[0] - lo[0]) / 2 / math.tan(half_w)
    y = lo[1] + 0.5 * height
    eye = np.array([(lo[0] + hi[0]) / 2, y, hi[2] + d])
    target = np.array([eye[0], y, (lo[2] + hi[2]) / 2])
    return {"open": _orbit(lo, hi, 55.0, 30.0, lo[1] + 0.3 * height),
            "row": _camera(eye, target, d * 0.05, d + 2 * (hi[2] - lo[2]))}


def _height_map(scene: Scene, lo: np.ndarray, cell: float,
                shape: tuple[int, int]) -> np.ndarray:
    """Per XZ cell: whether a triangle higher than the ground (+0.5) covers it (through the
    triangle's XZ bounding box: conservative, so free cells are really free)."""
    blocked = np.zeros(shape, bool)
    ground = lo[1] + 0.5
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        if len(m.indices) == 0:
            continue
        world = m.positions @ inst.transform[:3, :3].T + inst.transform[:3, 3]
        tri = world[m.indices.reshape(-1, 3)]
        tri = tri[tri[:, :, 1].max(axis=1) > ground]
        if len(tri) == 0:
            continue
        x0 = np.floor((tri[:, :, 0].min(axis=1) - lo[0]) / cell).astype(int)
        x1 = np.floor((tri[:, :, 0].max(axis=1) - lo[0]) / cell).astype(int)
        z0 = np.floor((tri[:, :, 2].min(axis=1) - lo[2]) / cell).astype(int)
        z1 = np.floor((tri[:, :, 2].max(axis=1) - lo[2]) / cell).astype(int)
        for a, b, c, d in zip(x0, x1, z0, z1, strict=True):
            blocked[max(a, 0):b + 1, max(c, 0):d + 1] = True
    return blocked


def city_cameras(scene: Scene, aspect: float, *, cell: float = 2.0,
                 clearance: int = 2) -> dict[str, dict[str, Any]]:
    lo, hi = scene.bounds()
    aerial = _orbit(lo, hi, 60.0, 30.0, lo[1])
    # street: the free cell (``clearance`` cells from any building) nearest the centre that
    # has a long free line of sight, looking down it at eye height
    shape = (int((hi[0] - lo[0]) / cell) + 1, int((hi[2] - lo[2]) / cell) + 1)
    blocked = _height_map(scene, lo, cell, shape)
    pad = np.pad(blocked, clearance, constant_values=True).astype(np.int32)
    s = np.pad(pad.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    w = 2 * clearance + 1
    near = s[w:, w:] - s[:-w, w:] - s[w:, :-w] + s[:-w, :-w]  # blocked cells within the window
    free = np.argwhere(near == 0)
    if len(free) == 0:
        raise ValueError(f"{scene.name}: no free street cell for the street camera")
    centre = (np.array(shape) - 1) / 2
    order = np.argsort(np.linalg.norm(free - centre, axis=1), kind="stable")
    dirs = [(math.cos(a), math.sin(a)) for a in np.linspace(0, 2 * math.pi, 32, endpoint=False)]
    want, best = 60.0 / cell, None  # a street at least 60 m long
    for fx, fz in free[order[:4000]]:
        for dx, dz in dirs:
            n = 1
            while n < 400:
                cx, cz = round(fx + dx * n), round(fz + dz * n)
                if not (0 <= cx < shape[0] and 0 <= cz < shape[1]) or blocked[cx, cz]:
                    break
                n += 1
            if best is None or n > best[0]:
                best = (n, fx, fz, dx, dz)
        if best[0] >= want:
            break
    n, fx, fz, dx, dz = best
    y = lo[1] + EYE_HEIGHT
    eye = np.array([lo[0] + (fx + 0.5) * cell, y, lo[2] + (fz + 0.5) * cell])
    target = eye + np.array([dx, 0.0, dz]) * n * cell
    return {"aerial": aerial,
            "street": _camera(eye, target, 0.1, float(np.linalg.norm(hi - lo)))}


def scene_cameras(name: str, scene: Scene, aspect: float) -> dict[str, dict[str, Any]]:
    return grid_cameras(scene, aspect) if name == "dragon_grid" else city_cameras(scene, aspect)


# --------------------------------------------------------------------------------------------
# one measurement


def vertex_geometry_bytes(scene: Scene) -> int:
    """What ``vkext.scene.VkScene`` uploads per mesh: four float32 attribute buffers
    (position, normal, uv, tangent: 48 B a vertex) and a uint32 index buffer."""
    return sum(max(16, len(m.positions) * 4 * k) for m in scene.meshes for k in (3, 3, 2, 4)) \
        + sum(max(16, len(m.indices) * 4) for m in scene.meshes)


def _pass_samples(result: Any) -> dict[str, list[float]]:
    out = {}
    for p in result.timings["passes"]:
        t = result.executor.timings.get(p["name"])
        out[p["name"]] = [float(v) for v in t.gpu_ms] if t is not None else []
    return out


def _meshlet_buffers(result: Any) -> dict[str, int] | None:
    for p in result.executor.passes.values():
        ms = getattr(p, "meshlets", None)
        if ms is not None and getattr(ms, "buffers", None):
            return {name: int(b.bytes) for name, b in ms.buffers.items()}
    return None


def _save_images(result: Any, folder: Path, stem: str) -> None:
    from PIL import Image

    from rfw.render import to_png_array

    formats = {r.name: r.format for r in result.frame.plan.resources}
    folder.mkdir(parents=True, exist_ok=True)
    for name, image in result.images.items():
        Image.fromarray(to_png_array(image, formats[name]), "RGBA").save(
            folder / f"{stem}.{name}.png")


_SCENES: dict[tuple, tuple[Scene, float]] = {}  # --inprocess: scenes built once


def measure(spec: dict[str, Any], device: Any = None) -> dict[str, Any]:
    """Render one (scene, camera, variant) and return its JSON record."""
    from rfw.config import apply_overrides, load_config
    from vkext.backend import render_vk

    t0 = time.perf_counter()
    load_before = os.getloadavg()[0]
    dirs = [Path(d) for d in spec["scene_dirs"]]
    key = (spec["scene"], spec["grid"], tuple(spec["scene_dirs"]))
    if key in _SCENES:
        scene, load_s = _SCENES[key]
    else:
        scene = build_scene(spec["scene"], spec["grid"], dirs)
        load_s = time.perf_counter() - t0
        if spec.get("keep_scene"):
            _SCENES[key] = (scene, load_s)
    w, h = spec["size"]
    camera = scene_cameras(spec["scene"], scene, w / h)[spec["camera"]]
    cfg = apply_overrides(load_config(CONFIG), [*spec["overrides"], f"size={w}x{h}"])
    cfg = dataclasses.replace(cfg, camera=camera)
    t1 = time.perf_counter()
    result = render_vk(cfg, scene=scene, frames=spec["frames"], warmup=spec["warmup"],
                       device=device)
    render_s = time.perf_counter() - t1
    if spec.get("images"):
        _save_images(result, Path(spec["images"]), f"{scene.name}_{spec['camera']}_"
                     f"{spec['variant']}")
    samples = _pass_samples(result)
    # per frame sums over the passes that have timestamps (every pass, where the device has
    # them)
    timed = {n: v for n, v in samples.items() if v}
    count = min((len(v) for v in timed.values()), default=0)
    frames = [sum(v[i] for v in timed.values()) for i in range(count)]
    geometry = [sum(v[i] for n, v in timed.items() if n not in SHADING_PASSES)
                for i in range(count)]
    t = result.timings
    culling = t.get("culling")
    triangles = scene.triangle_count
    if culling is None:  # the vertex path draws every triangle
        drawn, estimated = triangles, False
    elif culling.get("triangles_drawn") is not None:
        drawn, estimated = culling["triangles_drawn"], False
    else:  # meshlets are about equal in size: scale by the meshlets drawn
        total = culling["meshlets_total"] or 1
        drawn, estimated = round(triangles * culling["meshlets_drawn"] / total), True
    return {
        "kind": "meshlet_bench", **spec["env"], "device": t["device"], "driver": t["driver"],
        "api": t["api"], "scene": spec["scene"], "scene_name": scene.name,
        "grid": spec["grid"] if spec["scene"] == "dragon_grid" else None,
        "camera": spec["camera"], "occlusion": CAMERAS[spec["scene"]][spec["camera"]],
        "camera_params": camera, "variant": spec["variant"], "overrides": spec["overrides"],
        "variants_chosen": t.get("variants"), "size": [w, h], "frames": spec["frames"],
        "warmup": spec["warmup"], "repeat": spec["repeat"], "inprocess": spec["inprocess"],
        "triangles": triangles, "instances": len(scene.instances),
        "passes": {n: {"gpu_ms": v} for n, v in samples.items()},
        "gbuffer_ms": geometry, "frame_ms": frames,
        "gbuffer_ms_median": statistics.median(geometry) if geometry else None,
        "frame_ms_median": statistics.median(frames) if frames else None,
        "culling": culling, "gbuffer_passes": [n for n in samples if n not in SHADING_PASSES],
        "triangles_drawn": drawn, "triangles_drawn_estimated": estimated,
        "memory": {"vertex_geometry_bytes": vertex_geometry_bytes(scene),
                   "meshlet_buffers": _meshlet_buffers(result),
                   "transient_allocated_bytes": t["memory"]["transient_allocated_bytes"],
                   "frame_graph": t["memory"]},
        "load_s": load_s, "render_s": render_s, "wall_s": time.perf_counter() - t0,
        # the host's 1-minute load average before and after (this run's own load included):
        # on a CPU driver, other work on the host shows up in the GPU times
        "loadavg": [load_before, os.getloadavg()[0]],
    }


def run_worker(spec: dict[str, Any], timeout: float) -> dict[str, Any]:
    """``measure`` in a child process; a failure becomes an error record."""
    t0 = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)],
                              capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s"}
    for line in done.stdout.splitlines():
        if line.startswith("RFW_RECORD "):
            record = json.loads(line[len("RFW_RECORD "):])
            record["process_s"] = time.perf_counter() - t0
            return record
    tail = (done.stderr or done.stdout).strip().splitlines()[-6:]
    return {"error": f"exit {done.returncode}: " + " | ".join(tail)}


# --------------------------------------------------------------------------------------------
# environment


def source_digest() -> str:
    """sha256 of the sources that decide the numbers (also without git, as on the device)."""
    h = hashlib.sha256()
    for top in ("rfw", "vkext", "passes", "shaders", "configs", "benchmarks"):
        for path in sorted((ROOT / top).rglob("*")):
            if path.is_file() and path.suffix in (".py", ".glsl", ".wgsl", ".toml", ".sh"):
                h.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:12]


def environment() -> dict[str, Any]:
    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  check=False, timeout=10).stdout.strip()
        except (OSError, subprocess.TimeoutExpired):
            return ""

    commit = os.environ.get("RFW_COMMIT") or git("rev-parse", "--short", "HEAD")
    if commit and not os.environ.get("RFW_COMMIT") and git("status", "--porcelain",
                                                           "--untracked-files=no"):
        commit += "-dirty"
    from rfw.bench.runner import _cpu_name, gpu_clocks

    return {"commit": commit or "unknown", "source_sha": source_digest(),
            "python": platform.python_version(), "host": platform.node(),
            "cpu": _cpu_name(), "cpus": os.cpu_count(), "gpu_clocks_start": gpu_clocks()}


def probe_device(device: Any = None) -> dict[str, Any]:
    from vkext.device import VkDevice

    own = device is None
    dev = device or VkDevice()
    try:
        return {**dev.describe(), "device_type": dev.device_type,
                "mesh_shader": "VK_EXT_mesh_shader" in dev.caps}
    finally:
        if own:
            dev.destroy()


# --------------------------------------------------------------------------------------------
# the report


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def _iqr(values: list[float]) -> tuple[float, float] | None:
    if len(values) < 2:
        return None
    q = statistics.quantiles(values, n=4, method="inclusive")
    return q[0], q[2]


def _ms(values: list[float]) -> str:
    m, r = _median(values), _iqr(values)
    if m is None:
        return "-"
    return f"{m:.3f}" + (f" ({r[0]:.3f}-{r[1]:.3f})" if r else "")


def _pct(part: int | None, total: int | None) -> str:
    return "-" if part is None or not total else f"{100.0 * part / total:.1f}%"


def _ratio(a: float | None, b: float | None) -> str:
    return "-" if a is None or not b else f"{a / b:.2f}x"


def aggregate(records: list[dict[str, Any]]) -> dict[tuple, dict[str, Any]]:
    """Repeats pooled: (scene, grid, camera, variant) -> frames of all repeats and the last
    repeat's counters and memory (they do not change between repeats)."""
    out: dict[tuple, dict[str, Any]] = {}
    for r in records:
        if "error" in r:
            continue
        key = (r["scene"], r["grid"], r["camera"], r["variant"])
        a = out.setdefault(key, {"gbuffer": [], "frame": [], "passes": {}, "repeats": 0})
        a["gbuffer"] += r["gbuffer_ms"]
        a["frame"] += r["frame_ms"]
        for n, p in r["passes"].items():
            a["passes"].setdefault(n, []).extend(p["gpu_ms"])
        a["repeats"] += 1
        a["last"] = r
    return out


def verdicts(agg: dict[tuple, dict[str, Any]]) -> list[str]:
    lines = []
    blocks = sorted({k[:3] for k in agg}, key=lambda k: (k[0], k[1] or 0, k[2]))
    for scene, grid, camera in blocks:
        base = agg.get((scene, grid, camera, "vertex"))
        label = _label(scene, grid, camera)
        if base is None:
            lines.append(f"{label}: no vertex-path measurement to compare with")
            continue
        vg, vf = _median(base["gbuffer"]), _median(base["frame"])
        parts = []
        wins = 0
        best: tuple[float, str] | None = None
        mesh = [(k[3], a) for k, a in agg.items() if k[:3] == (scene, grid, camera)
                and k[3] != "vertex"]
        for name, a in sorted(mesh, key=lambda x: _order(x[0])):
            g = _median(a["gbuffer"])
            if g is None or not vg:
                continue
            ratio = g / vg
            wins += ratio < 1.0
            how = f"wins by {1 / ratio:.2f}x" if ratio < 1.0 else f"loses by {ratio:.2f}x"
            parts.append(f"  {name:<38} G-buffer {ratio:5.2f}x vertex ({how}), frame "
                         f"{_ratio(_median(a['frame']), vf)}")
            best = min(best or (ratio, name), (ratio, name))
        lines.append(f"{label}: mesh shading wins in {wins} of {len(parts)} culling "
                     f"combinations (mesh time / vertex time, G-buffer passes)"
                     + (f"; best {best[1]} at {best[0]:.2f}x" if best else ""))
        lines += parts
    return lines


def _label(scene: str, grid: int | None, camera: str) -> str:
    name = f"dragon_grid {grid}x{grid}" if scene == "dragon_grid" else scene
    return f"{name} / {camera} ({CAMERAS[scene][camera]} occlusion)"


def report(records: list[dict[str, Any]], unavailable: dict[str, str] | None = None,
           elapsed_s: float | None = None, notes: list[str] | None = None) -> str:
    """The markdown report of one device's records (``--from-jsonl`` splits by device)."""
    agg = aggregate(records)
    ok = [r for r in records if "error" not in r]
    lines = ["# Vertex pipeline against mesh pipeline (bench_meshlets.py)", ""]
    if ok:
        m = ok[0]
        commits = sorted({f"{r['commit']} (sources {r['source_sha']})" for r in ok})
        elapsed = elapsed_s if elapsed_s is not None else sum(r.get("process_s", r["wall_s"])
                                                              for r in ok)
        lines.append(f"{m['device']} ({m['driver']}); rfw {', '.join(commits)}; "
                     f"{m['size'][0]}x{m['size'][1]}, {m['frames']} frames after "
                     f"{m['warmup']} warm-up, {max(r['repeat'] for r in ok) + 1} repeat(s), "
                     f"{'one process' if m['inprocess'] else 'a process per measurement'}; "
                     f"{elapsed:.0f} s in all.")
        if m.get("cpu"):  # records before issue 13 have neither
            clocks = m.get("gpu_clocks_start")
            lines.append("")
            lines.append(f"CPU {m['cpu']} ({m.get('cpus')} threads); GPU clocks at the start: "
                         + ("; ".join(f"SM {g['sm_mhz']} of max {g['max_sm_mhz']} MHz, memory "
                                      f"{g['mem_mhz']} MHz" for g in clocks) if clocks
                            else "not reported (no nvidia-smi)") + ".")
    lines += notes or []
    lines += ["", "GPU ms: median over all frames of all repeats (interquartile range). "
              "G-buffer: every pass but " + ", ".join(SHADING_PASSES) + ". "
              "Culled: meshlets culled by each test / meshlets submitted. "
              "x vertex: this path's time / the vertex path's, same scene, camera and size. "
              "Triangles drawn: as the GPU counted them (after all culling), % of the scene's."
              + (" ~: estimated from the meshlets drawn (no triangle counter)."
                 if any(r.get("triangles_drawn_estimated") for r in ok) else "")]
    if unavailable:
        lines += ["", "Not run: " + "; ".join(f"{k} ({v})" for k, v in unavailable.items())]
    blocks = sorted({k[:3] for k in agg}, key=lambda k: (k[0], k[1] or 0, k[2]))
    for scene, grid, camera in blocks:
        rows = sorted([(k[3], a) for k, a in agg.items() if k[:3] == (scene, grid, camera)],
                      key=lambda x: _order(x[0]))
        base = agg.get((scene, grid, camera, "vertex"))
        vg = _median(base["gbuffer"]) if base else None
        vf = _median(base["frame"]) if base else None
        first = rows[0][1]["last"]
        cam = first["camera_params"]
        lines += ["", f"## {_label(scene, grid, camera)}", "",
                  f"{first['triangles']:,} triangles, {first['instances']:,} instances; camera "
                  f"at ({', '.join(f'{v:.3g}' for v in cam['position'])}) looking at "
                  f"({', '.join(f'{v:.3g}' for v in cam['target'])}), yfov {cam['yfov']:g} deg",
                  "", "| variant | G-buffer ms | x vertex | frame ms | x vertex | culled cone "
                  "| culled frustum | culled occlusion | meshlets drawn | triangles drawn "
                  "| G-buffer passes (median ms) | runs |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for name, a in rows:
            r = a["last"]
            c = r["culling"] or {}
            total = c.get("meshlets_total")
            passes = ", ".join(f"{n} {_median(v):.3f}" for n, v in a["passes"].items()
                               if n not in SHADING_PASSES and v)
            tri = f"{'~' if r['triangles_drawn_estimated'] else ''}{r['triangles_drawn']:,} " \
                f"({_pct(r['triangles_drawn'], r['triangles'])})"
            drawn = "-" if not c else f"{c['meshlets_drawn']:,} / {total:,}"
            lines.append(
                f"| {name} | {_ms(a['gbuffer'])} | {_ratio(_median(a['gbuffer']), vg)} | "
                f"{_ms(a['frame'])} | {_ratio(_median(a['frame']), vf)} | "
                f"{_pct(c.get('culled_cone'), total)} | {_pct(c.get('culled_frustum'), total)} "
                f"| {_pct(c.get('culled_occlusion'), total)} | {drawn} | {tri} | {passes} "
                f"| {a['repeats']} |")
    # memory: one row per scene (geometry does not depend on the camera)
    mem: dict[tuple, dict[str, Any]] = {}
    for r in ok:
        m = mem.setdefault((r["scene"], r["grid"]), {"transient": {}})
        m["vertex"] = r["memory"]["vertex_geometry_bytes"]
        if r["memory"]["meshlet_buffers"]:
            m["meshlet"] = r["memory"]["meshlet_buffers"]
        path = "vertex" if r["variant"] == "vertex" else "mesh"
        m["transient"][path] = max(m["transient"].get(path, 0),
                                   r["memory"]["transient_allocated_bytes"])
    if mem:
        lines += ["", "## GPU memory", "",
                  "Geometry: vertex path = vertex + index buffers (48 B a vertex, 4 B an "
                  "index); mesh path = the meshlet buffers (vec4 attributes, meshlet tables, "
                  "bounds and cones, instances; counters left out). The vertex and index "
                  "buffers stay resident in the mesh path too. Transient: the frame graph's "
                  "allocation (largest over cameras and culling variants).", "",
                  "| scene | vertex geometry MiB | mesh geometry MiB | x vertex | mesh "
                  "buffers MiB | transient MiB vertex | transient MiB mesh |",
                  "|---|---|---|---|---|---|---|"]
        for (scene, grid), m in sorted(mem.items(), key=lambda x: (x[0][0], x[0][1] or 0)):
            bufs = {k: v for k, v in (m.get("meshlet") or {}).items() if k != "counters"}
            total = sum(bufs.values()) if bufs else None
            detail = ", ".join(f"{k} {v / MIB:.2f}" for k, v in sorted(
                bufs.items(), key=lambda x: -x[1]))
            tv, tm = m["transient"].get("vertex"), m["transient"].get("mesh")
            name = f"dragon_grid {grid}x{grid}" if scene == "dragon_grid" else scene
            lines.append(f"| {name} | {m['vertex'] / MIB:.2f} | "
                         f"{'-' if total is None else f'{total / MIB:.2f}'} | "
                         f"{_ratio(total, m['vertex'])} | {detail or '-'} | "
                         f"{'-' if tv is None else f'{tv / MIB:.2f}'} | "
                         f"{'-' if tm is None else f'{tm / MIB:.2f}'} |")
    lines += ["", "## Verdict", "", "```", *verdicts(agg), "```"]
    errors = [r for r in records if "error" in r]
    if errors:
        lines += ["", "## Failed measurements", ""]
        lines += [f"- {r['scene']} / {r['camera']} / {r['variant']} (repeat {r['repeat']}): "
                  f"{r['error']}" for r in errors]
    wall = [r["wall_s"] for r in ok]
    if wall:
        lines += ["", f"Per measurement: {statistics.median(wall):.1f} s median "
                  f"(load {statistics.median(r['load_s'] for r in ok):.1f} s, render "
                  f"{statistics.median(r['render_s'] for r in ok):.1f} s), "
                  f"{len(ok)} measurement(s)."]
        loads = [v for r in ok for v in r.get("loadavg", [])]
        if loads:
            lines.append(f"Host load (1-minute average, this run included): median "
                         f"{statistics.median(loads):.2f}, max {max(loads):.2f} on "
                         f"{ok[0].get('cpus')} CPUs.")
    return "\n".join(lines) + "\n"


def report_files(paths: list[Path], out: Path) -> int:
    records = [json.loads(line) for p in paths for line in p.read_text().splitlines()
               if line.strip()]
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in records:
        # records of other sources are never pooled: one section per sources too
        key = (r.get("device"), r.get("driver"), tuple(r.get("size") or ()),
               r.get("source_sha"))
        groups.setdefault(key, []).append(r)
    text = "\n".join(report(g) for g in groups.values())
    print(text)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out} ({len(records)} records from {len(paths)} file(s))")
    return 0


# --------------------------------------------------------------------------------------------
# command line


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, got '{text}'") from None
    return w, h


def _csv(text: str) -> list[str]:
    return [v.strip() for v in text.split(",") if v.strip()]


def export_scenes(folder: Path) -> int:
    from rfw.scene import load_scene
    from rfw.scene.fetch import default_cache

    folder.mkdir(parents=True, exist_ok=True)
    # the folder ignores itself: exported data never shows in git status, yet can be carried
    if not (folder / ".gitignore").exists():
        (folder / ".gitignore").write_text("# written by benchmarks/bench_meshlets.py "
                                           "--export-scenes\n*\n")
    total = 0
    for name in sorted(set(SOURCES.values())):
        glb = default_cache() / f"{name}.glb"
        if not glb.is_file():
            print(f"{name}: {glb} is missing (run: rfw scenes fetch {name})", file=sys.stderr)
            return 1
        lic = glb.with_name(f"{name}.LICENSE.txt")
        text = lic.read_text("utf-8") if lic.is_file() else ""
        t = time.perf_counter()
        n = export_npz(load_scene(glb), folder / f"{name}.npz", text)
        if lic.is_file():
            (folder / lic.name).write_text(text, "utf-8")
        total += n
        print(f"wrote {folder / f'{name}.npz'}: {n / MIB:.1f} MiB from "
              f"{glb.stat().st_size / MIB:.1f} MiB of GLB ({time.perf_counter() - t:.1f} s)")
    print(f"{total / MIB:.1f} MiB in all")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", type=_csv, default=list(CAMERAS),
                    help=f"comma-separated, of {', '.join(CAMERAS)} (default: all)")
    ap.add_argument("--cameras", type=_csv, help="camera names or occlusion classes "
                    "(little, heavy); default: all")
    ap.add_argument("--variants", type=_csv, help="comma-separated: vertex, or mesh with any "
                    "of " + ", ".join(f"+{t}" for t in CULLING) + " in this order (default: "
                    + ", ".join(default_variants()) + "; 'all': every combination)")
    ap.add_argument("--grid", type=int, help="dragon_grid is K x K dragons (default: 2 on a "
                    "CPU, 4 on a GPU)")
    ap.add_argument("--size", type=_size, help="WxH (default: 640x360 on a CPU, 1920x1080)")
    ap.add_argument("--frames", type=int, help="timed frames (default: 5 on a CPU, 60)")
    ap.add_argument("--warmup", type=int, help="untimed frames first (default: 2 on a CPU, 10)")
    ap.add_argument("--repeats", type=int, help="repeats, interleaved (default: 1 on a CPU, 3)")
    ap.add_argument("--scene-dir", action="append", default=[], metavar="DIR",
                    help="folder of <scene>.npz (repeatable; then the rfw scenes cache)")
    ap.add_argument("--inprocess", action="store_true",
                    help="run every measurement in this process (faster, less isolated)")
    ap.add_argument("--timeout", type=float, default=1800.0,
                    help="seconds a measurement process may take (default: 1800)")
    ap.add_argument("--budget", type=float, metavar="SECONDS",
                    help="start no measurement that would likely end after SECONDS "
                    "(the report covers what was done)")
    ap.add_argument("--from-jsonl", nargs="+", metavar="FILE",
                    help="no measuring: write the report of these JSON lines (one section "
                    "per device, size and source digest) to --out")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench_meshlets.md"),
                    help="markdown report (default: out/bench_meshlets.md)")
    ap.add_argument("--jsonl", help="JSON lines, one per measurement (default: --out with "
                    ".jsonl)")
    ap.add_argument("--images", metavar="DIR", help="also write each measurement's output "
                    "image into DIR (<scene>_<camera>_<variant>.<output>.png)")
    ap.add_argument("--list", action="store_true",
                    help="print the variants with their overrides (or why unavailable), the "
                    "cameras and exit")
    ap.add_argument("--export-scenes", metavar="DIR",
                    help="write the fetched scenes as compact .npz into DIR and exit")
    ap.add_argument("--digest", action="store_true",
                    help="print the digest of the sources that records carry as source_sha")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker:
        record = measure(json.loads(args.worker))
        print("RFW_RECORD " + json.dumps(record), flush=True)
        return 0
    if args.digest:
        print(source_digest())
        return 0
    if args.export_scenes:
        return export_scenes(Path(args.export_scenes))
    if args.from_jsonl:
        return report_files([Path(p) for p in args.from_jsonl], Path(args.out))

    for s in args.scenes:
        if s not in CAMERAS:
            ap.error(f"unknown scene '{s}' (known: {', '.join(CAMERAS)})")
    names = args.variants or default_variants()
    if "all" in names:
        names = variant_names()
    names = [canonical(v) for v in names]
    for v in names:
        if v not in variant_names():
            ap.error(f"unknown variant '{v}' (known: {', '.join(variant_names())})")
    resolved = resolve_variants(names)
    unavailable = {k: v for k, v in resolved.items() if isinstance(v, str)}
    runnable = {k: v for k, v in resolved.items() if not isinstance(v, str)}

    device = None
    if args.inprocess:
        from vkext.device import VkDevice

        device = VkDevice()
    info = probe_device(device)
    kind = "cpu" if info["device_type"] == "cpu" else "gpu"
    d = DEFAULTS[kind]
    size = args.size or d["size"]
    grid = args.grid or d["grid"]
    frames = args.frames or d["frames"]
    warmup = d["warmup"] if args.warmup is None else args.warmup
    repeats = args.repeats or d["repeats"]
    cams = {s: [c for c in CAMERAS[s] if not args.cameras or c in args.cameras
                or CAMERAS[s][c] in args.cameras] for s in args.scenes}
    dirs = [str(Path(p).resolve()) for p in args.scene_dir]

    print(f"{info['device']} ({info['driver']}), {kind}; mesh shaders: "
          f"{'yes' if info['mesh_shader'] else 'no'}")
    for name, v in resolved.items():
        print(f"  {name:<38} " + (" ".join(v) if not isinstance(v, str) else f"unavailable: {v}"))
    if args.list:
        for s in args.scenes:
            try:
                scene = build_scene(s, grid, [Path(p) for p in dirs])
            except (FileNotFoundError, ValueError) as e:
                print(f"{s}: {e}")
                continue
            for c, cam in scene_cameras(s, scene, size[0] / size[1]).items():
                print(f"  {_label(s, grid, c)}: {json.dumps(cam)}")
        return 0
    if not info["mesh_shader"]:
        print("the device has no VK_EXT_mesh_shader: only the vertex path runs",
              file=sys.stderr)
        runnable = {k: v for k, v in runnable.items() if k == "vertex"}
    for s in args.scenes:
        try:
            find_source(SOURCES[s], [Path(p) for p in dirs])
        except FileNotFoundError as e:
            print(f"rfw: {e}", file=sys.stderr)
            return 1

    env = {**environment(), "device_type": info["device_type"]}
    out = Path(args.out)
    jsonl = Path(args.jsonl) if args.jsonl else out.with_suffix(".jsonl")
    jsonl.parent.mkdir(parents=True, exist_ok=True)
    jsonl.write_text("")
    plan = [(s, c) for s in args.scenes for c in cams[s]]
    count = len(plan) * len(runnable) * repeats
    print(f"{count} measurements: {len(plan)} scene/camera pairs x {len(runnable)} variants x "
          f"{repeats} repeat(s); {size[0]}x{size[1]}, {frames} frames after {warmup}, "
          f"grid {grid}x{grid}")
    records: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    stopped = False
    jobs = []
    for rep in range(repeats):
        order = list(runnable)
        order = order[rep % len(order):] + order[:rep % len(order)]  # interleave
        jobs += [(rep, s, c, v) for s, c in plan for v in order]
    for k, (rep, s, c, v) in enumerate(jobs, 1):
        # --budget: stop before a measurement that would likely overrun it
        if args.budget is not None:
            took = [r.get("process_s", r.get("wall_s", 0.0)) for r in records
                    if r.get("scene") == s and "error" not in r]
            guess = statistics.median(took) if took else 0.0
            if time.perf_counter() - t0 + guess > args.budget:
                stopped = True
                print(f"budget of {args.budget:.0f} s reached: {k - 1} of {count} "
                      "measurements done")
                break
        spec = {"scene": s, "grid": grid, "camera": c, "variant": v,
                "overrides": runnable[v], "size": list(size), "frames": frames,
                "warmup": warmup, "repeat": rep, "scene_dirs": dirs, "env": env,
                "inprocess": args.inprocess, "keep_scene": args.inprocess,
                "images": str(Path(args.images).resolve()) if args.images else None}
        if args.inprocess:
            try:
                record = measure(spec, device)
            except Exception as e:  # reported; the run goes on
                record = {"error": f"{type(e).__name__}: {e}"}
        else:
            record = run_worker(spec, args.timeout)
        if "error" in record:
            record = {"kind": "meshlet_bench_error", **env, "device": info["device"],
                      "driver": info["driver"], "scene": s, "grid": grid,
                      "camera": c, "variant": v, "repeat": rep, "size": list(size),
                      **record}
            print(f"[{k}/{count}] {_label(s, grid, c)} {v}: FAILED {record['error']}")
        else:
            print(f"[{k}/{count}] {_label(s, grid, c)} {v}: G-buffer "
                  f"{record['gbuffer_ms_median']:.3f} ms, frame "
                  f"{record['frame_ms_median']:.3f} ms ({record['wall_s']:.1f} s)",
                  flush=True)
        records.append(record)
        with jsonl.open("a") as f:
            f.write(json.dumps(record) + "\n")
    if device is not None:
        device.destroy()
    notes = []
    if stopped:
        notes = ["", f"**Stopped by --budget {args.budget:.0f} s after {len(records)} of "
                 f"{count} measurements** (repeats are the outer loop: the last one is "
                 "partial)."]
    text = report(records, unavailable, time.perf_counter() - t0, notes)
    print()
    print(text)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out} and {jsonl}")
    return 1 if any("error" in r for r in records) else 0


if __name__ == "__main__":
    sys.exit(main())
