"""Ray tracing on Vulkan against CPU ray tracers, and ray-traced shadows against shadow maps.

Per scene (the embedded courtyard, and the fetched ``dragon``/``city`` where present):

1. **BVH builds**: ``vkext.accel.SceneAccel`` with ``prefer=fast_trace`` and ``fast_build``,
   compacted: BLAS and TLAS build times (GPU timestamps) and BLAS bytes before and after
   compaction; Embree, Open3D and Mitsuba scene builds beside them (host clock).
2. **Rays**: primary rays (one per pixel of the scene's camera), shadow rays toward the sun
   from the primary hits, and AO rays (cosine-weighted, radius 2% of the scene's diagonal)
   from the same points. Mrays/s of the GPU by ray query and by ray-tracing pipeline
   (``vkext.raycast``: closest hit; the GPU time of the trace alone, copies excluded), of
   Embree (embreex), Open3D ``RaycastingScene`` and Mitsuba 3 ``llvm_ad_rgb`` (closest hit
   for primary rays, occlusion queries for shadow and AO rays; host clock, all cores).
3. **Persistent ray scene**: ``rfw.RayScene.from_scene`` built once, then ``cast`` of the
   primary rays: wall time per cast (upload, trace, readback and the host's checks: what a
   caller waits for) and the trace alone (GPU timestamps), against the one-shot
   ``rfw.raycast`` (which builds the scene every call) and Embree on one thread and on all
   CPU cores (one process per core, each with its own BVH, hits into shared memory), all in
   the same run; hit-or-miss agreement with Embree beside them. Each ray placement
   (``staged``: copies on the GPU; ``mapped``: the trace reads and writes host-visible
   memory; ``rays mapped`` or ``hits mapped``: one stream so; ``host``: both, the rays in
   host-cached rather than device-local host-visible memory) casts into new arrays and
   into reused ``out=`` arrays in the batches ``vkext.raycast.batch_rays`` picks (the
   default: one batch unless measured overlap pays), then, into ``out=``, forced into one
   submit and into ``OVERLAP_PARTS`` overlapped batches (the old default), and a second
   table says where each cast's wall time went (``Raycaster.last``: the host's upload,
   submit, wait and readback, the rest, and the GPU's copies and trace).
4. **Shadows in the frame**: ``configs/rt_shadows.toml`` with the shadow map, ray-query and
   ray-pipeline shadows (sun only, so the images are comparable): the GPU ms of the shadow
   pass and the share of pixels within 8/255 of the shadow-map image.

A device without ray queries (NVIDIA's drivers at the time of writing) skips the ray-query
rows with a note. Medians over ``--repeats``. Markdown to stdout and ``--out``.

    .venv/bin/python benchmarks/bench_rt.py --size 640x360 --out out/bench_rt.md
    .venv/bin/python benchmarks/bench_rt.py --size 1280x720 --sections cast --scenes ''

``--sections`` picks among ``builds``, ``rays``, ``cast`` and ``frame`` (default: all).
"""

from __future__ import annotations

import argparse
import itertools
import json
import multiprocessing
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from rfw.config import apply_overrides, load_config  # noqa: E402
from rfw.scene import default_scene, load_scene  # noqa: E402
from rfw.scene.fetch import default_cache  # noqa: E402

CONFIG = ROOT / "configs" / "rt_shadows.toml"
METHODS = ("ray_query", "ray_pipeline")
PEERS = ("embree", "open3d", "mitsuba")
SECTIONS = ("builds", "rays", "cast", "frame")


# ---------------------------------------------------------------------------------------------
# scenes and rays


def find_scenes(names: list[str], dirs: list[Path]) -> dict[str, object]:
    out = {"courtyard": default_scene()}
    for name in names:
        for d in dirs:
            glb, npz = d / f"{name}.glb", d / f"{name}.npz"
            if glb.is_file():
                out[name] = load_scene(glb)
                break
            if npz.is_file():  # the compact form benchmarks/bench_meshlets.py exports
                from bench_meshlets import load_npz

                out[name] = load_npz(npz)
                break
    return out


def flatten(scene) -> tuple[np.ndarray, np.ndarray]:
    """World-space vertices and faces of every instance."""
    verts, faces, base = [], [], 0
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        f = np.asarray(m.indices, np.int64).reshape(-1, 3)
        if not len(f):
            continue
        t = np.asarray(inst.transform, np.float64)
        verts.append(np.asarray(m.positions, np.float64) @ t[:3, :3].T + t[:3, 3])
        faces.append(f + base)
        base += len(m.positions)
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32)


def primary_rays(scene, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    cam = scene.default_camera()
    w, h = size
    inv = np.linalg.inv(cam.projection(w / h).astype(np.float64) @ cam.view())
    y, x = np.mgrid[0:h, 0:w]
    ndc = np.stack([(x + 0.5) / w * 2 - 1, 1 - (y + 0.5) / h * 2, np.ones((h, w)),
                    np.ones((h, w))]).reshape(4, -1)
    far = inv @ ndc
    far = (far[:3] / far[3]).T
    o = np.broadcast_to(np.asarray(cam.position, np.float64), far.shape)
    d = far - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32)


def secondary_rays(scene, v, f, o, d, t, prim, seed=1):
    """Shadow rays toward the sun and AO rays from the primary hits (one each per hit)."""
    hit = np.isfinite(t)
    p = o[hit] + d[hit] * t[hit, None]
    tri = v[f[prim[hit]]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
    n = np.where((n * d[hit]).sum(1, keepdims=True) > 0, -n, n)
    lo, hi = v.min(0), v.max(0)
    diag = float(np.linalg.norm(hi - lo))
    origin = (p + n * 1e-4 * diag).astype(np.float32)
    sun = next((li for li in scene.lights if li.kind == "directional"), None)
    to_sun = -np.asarray(sun.direction if sun else (-0.3, -1.0, -0.2), np.float64)
    to_sun /= np.linalg.norm(to_sun)
    shadow_d = np.broadcast_to(to_sun, origin.shape).astype(np.float32)
    rng = np.random.default_rng(seed)
    u = rng.random((len(p), 2))
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    a = np.where(np.abs(n[:, :1]) > 0.5, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    tt = np.cross(n, a)
    tt /= np.linalg.norm(tt, axis=1, keepdims=True)
    b = np.cross(n, tt)
    ao_d = (tt * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None]
            + n * np.sqrt(1 - u[:, :1])).astype(np.float32)
    return {"shadow": (origin, shadow_d, 2 * diag), "ao": (origin, ao_d, 0.02 * diag)}


def ray_array(o, d, tmax):
    from vkext.raycast import RAY_DTYPE

    rays = np.zeros(len(o), RAY_DTYPE)
    rays["origin"], rays["direction"], rays["tmax"] = o, d, tmax
    return rays


# ---------------------------------------------------------------------------------------------
# CPU peers: (build seconds, {kind: (rays, seconds)}), or an error string


def embree_peer(v, f, batches):
    from embreex import mesh_construction, rtcore_scene

    t0 = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, v, f)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # commits the BVH
    build = time.perf_counter() - t0
    out = {}
    for kind, (o, d, tmax) in batches.items():
        t0 = time.perf_counter()
        if kind == "primary":
            scene.run(o, d, output=1)
        else:
            scene.run(o, d, dists=np.full(len(o), tmax, np.float32), query="OCCLUDED")
        out[kind] = time.perf_counter() - t0
    return build, out


def open3d_peer(v, f, batches):
    import open3d as o3d

    t0 = time.perf_counter()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f.astype(np.uint32)))
    scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 0, 0, 0, 1]], np.float32)))
    build = time.perf_counter() - t0
    out = {}
    for kind, (o, d, tmax) in batches.items():
        rays = o3d.core.Tensor(np.concatenate([o, d], axis=1))
        t0 = time.perf_counter()
        if kind == "primary":
            scene.cast_rays(rays)
        else:
            scene.test_occlusions(rays, tnear=0.0, tfar=float(tmax))
        out[kind] = time.perf_counter() - t0
    return build, out


def mitsuba_peer(v, f, batches):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    t0 = time.perf_counter()
    mesh = mi.Mesh("bench", len(v), len(f))
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(v.ravel())
    params["faces"] = mi.UInt32(f.astype(np.uint32).ravel())
    params.update()
    scene = mi.load_dict({"type": "scene", "mesh": mesh})
    build = time.perf_counter() - t0
    out = {}
    for kind, (o, d, tmax) in batches.items():
        ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, k]) for k in range(3))),
                       mi.Vector3f(*(mi.Float(d[:, k]) for k in range(3))))
        if kind != "primary":
            ray.maxt = mi.Float(np.full(len(o), tmax, np.float32))
        dr.eval(ray)
        t0 = time.perf_counter()
        res = scene.ray_intersect(ray).t if kind == "primary" else scene.ray_test(ray)
        dr.eval(res)
        dr.sync_thread()
        out[kind] = time.perf_counter() - t0
    return build, out


# ---------------------------------------------------------------------------------------------
# the GPU


def gpu_builds(device, scene, repeats):
    from vkext.accel import SceneAccel

    rows = []
    for prefer in ("fast_trace", "fast_build"):
        stats = []
        for _ in range(repeats):
            with SceneAccel(device, scene, prefer=prefer, compact=True) as acc:
                stats.append(acc.stats())
        ms = {k: statistics.median(s["build_ms"].get(k, 0.0) for s in stats)
              for k in ("blas", "compact", "tlas")}
        rows.append({"prefer": prefer, **ms, "timer": stats[0]["timer"],
                     "blas_bytes_built": stats[0]["blas_bytes_built"],
                     "blas_bytes": stats[0]["blas_bytes"], "tlas_bytes": stats[0]["tlas_bytes"],
                     "triangles": stats[0]["instance_triangles"]})
    return rows


def gpu_rays(device, scene, batches, repeats, notes):
    from vkext.accel import SceneAccel
    from vkext.device import VkMissingFeatureError
    from vkext.raycast import Raycaster

    out = {}
    with SceneAccel(device, scene, prefer="fast_trace") as acc:
        for method in METHODS:
            try:
                rc = Raycaster(device, method)
            except VkMissingFeatureError as e:
                notes.add(f"{method}: skipped on {device.name} ({e})")
                continue
            try:
                for kind, (o, d, tmax) in batches.items():
                    rays = ray_array(o, d, tmax)
                    rc.trace(acc, rays)  # warm-up
                    ms = []
                    for _ in range(repeats):
                        rc.trace(acc, rays)
                        ms.append(rc.last.get("gpu_ms", rc.last["wall_ms"]))
                    out[(method, kind)] = (len(rays), statistics.median(ms) / 1e3)
            finally:
                rc.destroy()
    return out


def frame_shadows(device, scene, size, frames, notes):
    from vkext.backend import render_vk

    rows, ref = [], None
    for method in ("shadow_map", *METHODS):
        # no AO (the same for all three), only the sun casts shadows (as with the map)
        cfg = apply_overrides(load_config(CONFIG), [
            f"size={size[0]}x{size[1]}", f"shadows={method}", "ao=ssao", "ssao.enabled=false",
            "rt_shadows.point_lights=false"])
        cfg = replace(cfg, frames=frames)
        try:
            res = render_vk(cfg, scene=scene, device=device)
        except Exception as e:  # a missing capability: the error names pass and extension
            notes.add(f"frame with shadows={method}: {str(e).splitlines()[0]}")
            continue
        passes = {p["name"]: p["gpu_ms"] for p in res.timings["passes"]}
        img = res.images["tonemap.ldr"].astype(int)
        if ref is None:
            ref = img
        same = float((np.abs(img - ref)[..., :3].max(axis=2) <= 8).mean())
        shadow_ms = passes.get("shadow") if method == "shadow_map" else passes.get("rt_shadows")
        rows.append({"shadows": method, "shadow_pass_ms": shadow_ms,
                     "accel_ms": passes.get("accel"), "frame_ms": res.timings["gpu_ms_total"],
                     "within_8": same})
    return rows



# ---------------------------------------------------------------------------------------------
# the persistent ray scene against Embree on every core


_EMBREE: dict = {}  # in each worker process: its Embree scene, the rays, the shared hits


def _embree_worker_init(v, f, o, d, hits_name) -> None:
    from multiprocessing import shared_memory

    from embreex import mesh_construction, rtcore_scene

    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, v, f)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # commits the BVH
    shm = shared_memory.SharedMemory(name=hits_name)
    _EMBREE.update(scene=scene, o=o, d=d, shm=shm,
                   t=np.ndarray(len(o), np.float32, buffer=shm.buf))


def _embree_worker_cast(part: tuple[int, int]) -> None:
    a, b = part
    r = _EMBREE["scene"].run(_EMBREE["o"][a:b], _EMBREE["d"][a:b], output=1)
    _EMBREE["t"][a:b] = np.where(r["primID"] >= 0, r["tfar"], np.inf)


def embree_all_cores(v, f, o, d, repeats, workers=None):
    """Seconds per cast of (o, d) by Embree on ``workers`` processes (default: every core),
    median of ``repeats``, and the hit distances. Workers are spawned (this process has
    Vulkan's and the copy pool's threads, which a fork would not carry) and each builds its
    own BVH, untimed; each cast hands out 4 chunks per worker, the hits go to shared
    memory."""
    from multiprocessing import shared_memory

    workers = workers or os.cpu_count() or 1
    n = len(o)
    shm = shared_memory.SharedMemory(create=True, size=max(4 * n, 1))
    cuts = np.linspace(0, n, 4 * workers + 1).astype(int)
    parts = [(int(a), int(b)) for a, b in itertools.pairwise(cuts) if b > a]
    times = []
    try:
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(workers, initializer=_embree_worker_init,
                      initargs=(v, f, o, d, shm.name)) as pool:
            pool.map(_embree_worker_cast, parts)  # warm-up: every worker has its BVH
            for _ in range(repeats):
                t0 = time.perf_counter()
                pool.map(_embree_worker_cast, parts)
                times.append(time.perf_counter() - t0)
        t = np.ndarray(n, np.float32, buffer=shm.buf).copy()
    finally:
        shm.close()
        shm.unlink()
    return statistics.median(times), workers, t


def embree_one_thread(v, f, o, d, repeats):
    from embreex import mesh_construction, rtcore_scene

    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, v, f)
    scene.run(o[:1], d[:1])
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        scene.run(o, d, output=1)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


# where a cast's wall time goes (Raycaster.last, summed over its batches): the host's parts,
# then the GPU's (timestamps); "other" is the wall time outside them (checks, result arrays)
HOST_PARTS = ("upload_ms", "submit_ms", "wait_ms", "readback_ms")
GPU_PARTS = ("gpu_upload_ms", "gpu_ms", "gpu_readback_ms")
# the old default's overlap: a cast in this many batches (vkext.raycast.OVERLAP_PARTS)
OVERLAP_PARTS = 4
# RFW_RAYCAST_MAPPED per placement (vkext.raycast.mapped_streams)
PLACEMENTS = {"staged": "0", "mapped": "1", "rays mapped": "rays", "hits mapped": "hits",
              "host": "host"}


def _casts(rs, o, d, repeats, out=None):
    """Median wall seconds and median parts (ms) of ``repeats`` casts after a warm-up."""
    rs.cast(o, d, out=out)  # warm-up: the buffers grow to the batch once
    walls, parts, hits = [], [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        hits = rs.cast(o, d, out=out)
        walls.append(time.perf_counter() - t0)
        parts.append(rs.last)
    for w, p in zip(walls, parts, strict=True):  # per cast, so that the parts add up
        p["other_ms"] = w * 1e3 - sum(p[k] for k in HOST_PARTS)
    med = {k: statistics.median(p[k] for p in parts) for k in (*HOST_PARTS, "other_ms",
                                                                 *GPU_PARTS)
           if all(k in p for p in parts)}
    return statistics.median(walls), med, hits, parts[-1]["batches"]


def _forced(rs, o, d, repeats, out, parts):
    """:func:`_casts` into ``out`` with the rays in ``parts`` batches whatever
    ``vkext.raycast.batch_rays`` would choose: 1 (one submit, no overlap of the host's
    copies with the GPU's work) or ``OVERLAP_PARTS`` (the overlap of the old default, at
    least ``OVERLAP_MIN`` rays a batch), the same-run baselines for the default's choice."""
    from vkext.raycast import OVERLAP_MIN, caster

    def forced(n, batch, **_):
        return n if parts == 1 else min(n, max(OVERLAP_MIN, -(-n // parts)))

    saved = caster.batch_rays  # what Raycaster.cast calls
    caster.batch_rays = forced
    try:
        return _casts(rs, o, d, repeats, out=out)
    finally:
        caster.batch_rays = saved


def ray_scene_casts(device, scene, o, d, ref_t, repeats, notes):
    """Per method and ray placement (staged through copies, or mapped: the trace reads and
    writes host-visible memory, for both streams or one, or both with the rays in
    host-cached memory; RFW_RAYCAST_MAPPED picks it): RayScene build, then casts (wall:
    what the caller waits for, and its parts; GPU: the trace alone), casts into reused
    ``out=`` arrays, forced into one batch and into overlapped ones, and the one-shot
    rfw.raycast's wall; hit-or-miss agreement with
    Embree's ``ref_t``. Every placement's hits must equal the first one's bit for bit."""
    import rfw
    from rfw.errors import RfwError

    rows, first = [], None
    for method, placement in itertools.product(METHODS, PLACEMENTS):
        t0 = time.perf_counter()
        saved = os.environ.get("RFW_RAYCAST_MAPPED")
        os.environ["RFW_RAYCAST_MAPPED"] = PLACEMENTS[placement]
        try:
            rs = rfw.RayScene.from_scene(scene, device=device, method=method)
        except RfwError as e:  # the device lacks the method: say so
            notes.add(f"RayScene {method}: skipped on {device.name} ({e})")
            continue
        finally:
            if saved is None:
                del os.environ["RFW_RAYCAST_MAPPED"]
            else:
                os.environ["RFW_RAYCAST_MAPPED"] = saved
        build = time.perf_counter() - t0
        with rs:
            try:
                wall, parts, hits, batches = _casts(rs, o, d, repeats)
                out = {k: np.empty_like(v) for k, v in hits.items()}
                wall_out, parts_out, hits_out, _ = _casts(rs, o, d, repeats, out=out)
                wall_one, parts_one, hits_one, one_batches = _forced(rs, o, d, repeats, out,
                                                                     1)
                wall_over, parts_over, hits_over, over_batches = _forced(
                    rs, o, d, repeats, out, OVERLAP_PARTS)
            except RfwError as e:  # e.g. no room for mapped buffers: say so, go on
                notes.add(f"RayScene {method} {placement}: failed on {device.name} ({e})")
                continue
            memory = rs._scene.buffers.memory()
        notes.add(f"RayScene {placement} on {device.name}: rays in "
                  f"{memory.get('rays')}, hits in {memory.get('hits')}")
        first = first or hits
        for got in (hits, hits_out, hits_one, hits_over):
            if any(not np.array_equal(got[k], first[k]) for k in first):
                notes.add(f"RayScene {method} {placement}: hits differ from the first caster's")
        one_shot = None
        if placement == "staged":
            t0 = time.perf_counter()
            rfw.raycast(origins=o, directions=d, scene=scene, device=device, method=method)
            one_shot = time.perf_counter() - t0
        agree = float((np.isfinite(hits["t"]) == np.isfinite(ref_t)).mean())
        rows.append({"method": method, "placement": placement, "rays": len(o),
                     "build_s": build, "batches": batches, "wall_s": wall,
                     "wall_out_s": wall_out, "parts_ms": parts, "parts_out_ms": parts_out,
                     "wall_one_s": wall_one, "parts_one_ms": parts_one,
                     "one_batches": one_batches, "wall_over_s": wall_over,
                     "parts_over_ms": parts_over, "over_batches": over_batches,
                     "gpu_s": parts["gpu_ms"] / 1e3 if "gpu_ms" in parts else None,
                     "one_shot_s": one_shot, "agreement": agree})
    return rows


def cast_lines(rows, embree, n):
    """The report's tables: rays/s and the ratio to Embree on all cores, then where the
    wall time of each cast goes."""
    all_s, workers, one_s = embree["all_cores_s"], embree["workers"], embree["one_thread_s"]
    lines = [f"Persistent ray scene, {n:,} primary rays (ratio: Embree on all {workers} cores "
             "/ this, >1 is faster than Embree):", "",
             "| caster | ms | Mrays/s | x Embree (all cores) | hit-or-miss = Embree |",
             "| --- | ---: | ---: | ---: | ---: |"]

    def row(name, sec, agree="-"):
        lines.append(f"| {name} | {sec * 1e3:.2f} | {n / sec / 1e6:.1f} | {all_s / sec:.2f} | "
                     f"{agree} |")

    for r in rows:
        name = f"RayScene.cast {r['method']} {r['placement']}"
        row(f"{name} (wall: upload + trace + readback)", r["wall_s"], f"{r['agreement']:.5f}")
        row(f"{name} (wall, into reused out= arrays)", r["wall_out_s"])
        row(f"{name} (wall, out=, all rays in one submit)", r["wall_one_s"])
        row(f"{name} (wall, out=, overlapped: {r['over_batches']} batches)", r["wall_over_s"])
        if r["gpu_s"]:
            row(f"{name} (trace only, GPU timestamps)", r["gpu_s"])
        if r["one_shot_s"]:
            row(f"rfw.raycast {r['method']} (one shot: builds every call)", r["one_shot_s"])
    row(f"Embree, {workers} processes (embreex)", all_s)
    row("Embree, 1 thread (embreex)", one_s)
    builds = ", ".join(f"{r['method']} {r['placement']} {r['build_s'] * 1e3:.0f} ms"
                       for r in rows)
    lines += ["", f"RayScene builds (once per scene, not in the casts): {builds}.", ""]
    return lines + breakdown_lines(rows)


def breakdown_lines(rows):
    """Where each cast's wall time goes (ms, medians): host parts summed over the batches
    (they overlap the GPU's), the rest of the wall time, and the GPU's parts."""
    if not rows:
        return []
    lines = ["Where the wall time of a cast goes (ms, medians; host parts summed over the "
             "batches, which overlap the GPU's work; other = checks and result arrays):", "",
             "| caster | batches | wall | host: upload | submit | wait | readback | other "
             "| GPU: copy in | trace | copy out |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        for label, batches, wall, parts in (
                ("", r["batches"], r["wall_s"], r["parts_ms"]),
                (", out=", r["batches"], r["wall_out_s"], r["parts_out_ms"]),
                (", out=, one submit", r["one_batches"], r["wall_one_s"], r["parts_one_ms"]),
                (", out=, overlapped", r["over_batches"], r["wall_over_s"],
                 r["parts_over_ms"])):
            cells = [fmt(parts.get(k)) for k in (*HOST_PARTS, "other_ms", *GPU_PARTS)]
            lines.append(f"| {r['method']} {r['placement']}{label} | {batches} | "
                         f"{wall * 1e3:.2f} | " + " | ".join(cells) + " |")
    return [*lines, ""]


# ---------------------------------------------------------------------------------------------
# the report


def fmt(x, spec=".2f"):
    return "-" if x is None else format(x, spec)


def section_lines(builds, gpu, peers, batches, casts, embree, frame, n):
    """The tables of one scene, for the sections that ran."""
    lines = []
    if builds or peers:
        lines += ["| BVH build | BLAS ms | compact ms | TLAS ms | BLAS bytes built | "
                  "compacted | TLAS bytes |", "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for b in builds:
            lines.append(f"| GPU {b['prefer']} ({b['timer']}) | {fmt(b['blas'])} | "
                         f"{fmt(b['compact'])} | {fmt(b['tlas'])} | {b['blas_bytes_built']:,}"
                         f" | {b['blas_bytes']:,} | {b['tlas_bytes']:,} |")
        for peer, (build, _) in peers.items():
            lines.append(f"| {peer} (host) | {build * 1e3:.2f} | - | - | - | - | - |")
        lines.append("")
    if gpu or peers:
        kinds = list(batches)
        lines += ["| Mrays/s | " + " | ".join(f"{k} ({len(batches[k][0]):,})"
                                             for k in kinds) + " |",
                  "| --- |" + " ---: |" * len(kinds)]
        for m in METHODS:
            if any((m, k) in gpu for k in kinds):
                lines.append(f"| GPU {m} | " + " | ".join(
                    fmt(gpu[(m, k)][0] / gpu[(m, k)][1] / 1e6) if (m, k) in gpu else "-"
                    for k in kinds) + " |")
        for peer, (_, times) in peers.items():
            lines.append(f"| {peer} | " + " | ".join(
                fmt(len(batches[k][0]) / times[k] / 1e6) for k in kinds) + " |")
        lines.append("")
    if casts or embree:
        lines += cast_lines(casts, embree, n)
    if frame:
        lines += ["| shadows (sun) | shadow pass ms | accel ms | frame ms | "
                  "pixels within 8/255 of the shadow map |", "| --- | ---: | ---: | ---: | ---: |"]
        for row in frame:
            lines.append(f"| {row['shadows']} | {fmt(row['shadow_pass_ms'], '.3f')} | "
                         f"{fmt(row['accel_ms'], '.3f')} | {fmt(row['frame_ms'], '.3f')} | "
                         f"{row['within_8']:.4f} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="640x360", help="primary rays and frames: WxH")
    ap.add_argument("--scenes", default="dragon,city", help="fetched scenes to add if present")
    ap.add_argument("--scene-dir", action="append", type=Path, default=[],
                    help="folders with <name>.glb or .npz (default: .scenes, the fetch cache)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--peers", default=",".join(PEERS), help="CPU peers to run ('' for none)")
    ap.add_argument("--sections", default=",".join(SECTIONS),
                    help=f"what to measure, of {','.join(SECTIONS)}")
    ap.add_argument("--out", type=Path, help="also write the report here (and .json beside it)")
    args = ap.parse_args(argv)
    sections = {x for x in args.sections.split(",") if x}
    if sections - set(SECTIONS):
        ap.error(f"--sections: unknown {', '.join(sorted(sections - set(SECTIONS)))}")
    size = tuple(int(s) for s in args.size.lower().split("x"))
    dirs = args.scene_dir or [ROOT / ".scenes", default_cache()]
    scenes = find_scenes([s for s in args.scenes.split(",") if s], dirs)

    from rfw.bench.runner import environment
    from vkext import VkDevice

    env = environment()  # the commit (RFW_COMMIT on a GPU machine) and the host's CPU
    device = VkDevice()
    notes: set[str] = set()
    lines = [f"# Ray tracing on {device.name} ({device.driver_name})", "",
             f"{size[0]}x{size[1]} primary rays, medians of {args.repeats}; "
             "GPU times from timestamps (trace only), CPU peers on the host clock.", "",
             f"rfw {env['rfw_commit']} (from {env['rfw_commit_source']}); driver "
             f"{device.driver}; host {env['cpu']}, {env['cpus']} CPUs.", ""]
    record = {"device": device.describe(), "environment": env, "size": size, "scenes": {}}
    try:
        for name, scene in scenes.items():
            v, f = flatten(scene)
            print(f"{name}: {len(f):,} triangles", file=sys.stderr)
            o, d = primary_rays(scene, size)
            from embreex import mesh_construction, rtcore_scene

            es = rtcore_scene.EmbreeScene()
            mesh_construction.TriangleMesh(es, v, f)
            r = es.run(o, d, output=1)
            t = np.where(r["primID"] >= 0, r["tfar"], np.inf).astype(np.float32)
            batches = {"primary": (o, d, 1e30),
                       **secondary_rays(scene, v, f, o, d, t, r["primID"])}
            builds = gpu_builds(device, scene, args.repeats) if "builds" in sections else []
            gpu = gpu_rays(device, scene, batches, args.repeats, notes) \
                if "rays" in sections else {}
            peers = {}
            for peer in [p for p in args.peers.split(",") if p and "rays" in sections]:
                try:
                    peers[peer] = globals()[f"{peer}_peer"](v, f, batches)
                except Exception as e:  # not installed, or failing here: say so
                    notes.add(f"{peer}: {type(e).__name__}: {str(e).splitlines()[0][:120]}")
            casts, embree = [], {}
            if "cast" in sections:
                casts = ray_scene_casts(device, scene, o, d, t, args.repeats, notes)
                all_s, workers, all_t = embree_all_cores(v, f, o, d, args.repeats)
                if not np.array_equal(all_t, t):  # the chunks must give the one-call answer
                    notes.add(f"{name}: Embree on {workers} processes differs from one call")
                embree = {"all_cores_s": all_s, "workers": workers,
                          "one_thread_s": embree_one_thread(v, f, o, d, args.repeats)}
            frame = frame_shadows(device, scene, size, args.frames, notes) \
                if "frame" in sections else []
            record["scenes"][name] = {"triangles": len(f), "builds": builds,
                                      "rays": {f"{m}/{k}": v_ for (m, k), v_ in gpu.items()},
                                      "peers": peers, "frame": frame, "ray_scene": casts,
                                      "embree_primary": embree}

            lines += [f"## {name}: {len(f):,} triangles, {len(scene.instances)} instances", ""]
            lines += section_lines(builds, gpu, peers, batches, casts, embree, frame, len(o))
            lines.append("")
    finally:
        device.destroy()
    if notes:
        lines += ["Notes:", "", *(f"- {n}" for n in sorted(notes)), ""]
    lines.append("GPU shadow and AO rays are closest-hit casts (vkext.raycast); the CPU peers "
                 "answer occlusion queries for them, which may stop at the first hit.")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
        args.out.with_suffix(".json").write_text(json.dumps(record, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
