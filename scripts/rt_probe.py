"""Probe ray casting on a machine's Vulkan device: builds, agreement and Mrays/s.

    python3 scripts/rt_probe.py [--rays N] [--repeats K] [--batch B] [--mesh icosphere]
                                [--validation] [--json OUT]

Builds the acceleration structures of the default courtyard (or a dense icosphere) with
compaction, casts N rays (half from inside the courtyard in all directions, half from
outside at its bounds) with every method the device has (ray queries and/or a ray-tracing
pipeline: NVIDIA drivers may lack ray queries), and reports:

- the build: BLAS/TLAS counts, bytes before and after compaction, build ms per phase;
- per method: the median, min and max Mrays/s over K timed casts after one warm-up (GPU
  timestamps around the traces, copies excluded) and the host's wall-clock Mrays/s;
- agreement: between the methods (bit-identical fraction), and with a CPU reference on the
  first 2000 rays with Embree (embreex) when installed, else on the first 300 with a numpy
  brute-force test of every triangle (some seconds): hit-or-miss agreement and t within 1e-4
  relative where both hit.

The last line printed is one JSON record (also written to OUT with --json).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rfw.scene import default_scene
from rfw.scene.model import Instance, Mesh, Scene
from vkext.accel import SceneAccel
from vkext.device import VkDevice
from vkext.raycast import METHODS, RAY_DTYPE, Raycaster

CHECKED = {"embree": 2000, "numpy": 300}  # rays compared with each CPU reference


def _scene(name: str) -> Scene:
    if name == "courtyard":
        return default_scene()
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=7)  # 327,680 triangles
    v = m.vertices.astype(np.float32)
    z = np.zeros((len(v), 4), np.float32)
    mesh = Mesh("icosphere", v, z[:, :3], z[:, :2], z, m.faces.astype(np.uint32).ravel())
    return Scene("icosphere", meshes=[mesh], instances=[Instance(0, np.identity(4, np.float32))])


def _world(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space triangles (T, 3, 3) float64 with (instance, primitive) of each."""
    tris, owner = [], []
    for k, inst in enumerate(scene.instances):
        m = scene.meshes[inst.mesh]
        f = np.asarray(m.indices, np.int64).reshape(-1, 3)
        if not len(f):
            continue
        t = np.asarray(inst.transform, np.float64)
        p = np.asarray(m.positions, np.float64) @ t[:3, :3].T + t[:3, 3]
        tris.append(p[f])
        owner.append(np.stack([np.full(len(f), k), np.arange(len(f))], axis=1))
    return np.concatenate(tris), np.concatenate(owner), np.concatenate(tris).reshape(-1, 3)


def _rays(scene: Scene, n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds()
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    half = n // 2
    o = rng.normal(size=(half, 3))
    o = c + o / np.linalg.norm(o, axis=1, keepdims=True) * 2 * r
    d = rng.uniform(lo, hi, (half, 3)) - o
    inner = rng.uniform(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo), (n - half, 3))
    rays = np.zeros(n, RAY_DTYPE)
    rays["origin"] = np.concatenate([o, inner])
    rays["direction"] = np.concatenate([d, rng.normal(size=(n - half, 3))])
    rays["tmax"] = np.inf
    return rays


def _reference(scene: Scene, rays: np.ndarray) -> tuple[np.ndarray, str]:
    """Closest t of the first rays on the CPU (inf on a miss), and which reference gave it."""
    tris, _, verts = _world(scene)
    o = rays["origin"].astype(np.float64)
    d = rays["direction"].astype(np.float64)
    try:
        from embreex import mesh_construction, rtcore_scene

        rays = rays[:CHECKED["embree"]]
        o, d = o[:len(rays)], d[:len(rays)]
        es = rtcore_scene.EmbreeScene()
        faces = np.arange(len(verts), dtype=np.int32).reshape(-1, 3)
        mesh_construction.TriangleMesh(es, verts.astype(np.float32), faces)
        r = es.run(o.astype(np.float32), d.astype(np.float32), output=1)
        return np.where(r["primID"] >= 0, r["tfar"], np.inf), "embree"
    except ImportError:
        pass
    # Moller-Trumbore against every triangle, a few rays at a time
    o, d = o[:CHECKED["numpy"]], d[:CHECKED["numpy"]]
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    best = np.full(len(o), np.inf)
    for i in range(0, len(o), 8):
        oo, dd = o[i:i + 8, None], d[i:i + 8, None]
        p = np.cross(dd, e2)
        det = np.einsum("rtk,tk->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = oo - v0
            u = np.einsum("rtk,rtk->rt", s, p) * inv
            q = np.cross(s, e1)
            v = np.einsum("rtk,rtk->rt", np.broadcast_to(dd, q.shape), q) * inv
            t = np.einsum("rtk,tk->rt", q, e2) * inv
            ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0)
        best[i:i + 8] = np.where(ok, t, np.inf).min(axis=1)
    return best, "numpy"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=1 << 20)
    ap.add_argument("--mesh", choices=("courtyard", "icosphere"), default="courtyard")
    ap.add_argument("--validation", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()

    dev = VkDevice(validation=args.validation, label="rt_probe")
    record: dict = {**dev.describe(), "scene": args.mesh, "rays": args.rays,
                    "batch": args.batch, "repeats": args.repeats}
    try:
        status = _probe(dev, args, record)
    finally:
        dev.destroy()
    line = json.dumps(record, default=str)
    print(line)
    if args.json:
        args.json.write_text(line + "\n")
    return status


def _probe(dev: VkDevice, args: argparse.Namespace, record: dict) -> int:
    record["ray_tracing"] = {e: e in dev.caps for e in (
        "VK_KHR_acceleration_structure", "VK_KHR_ray_query", "VK_KHR_ray_tracing_pipeline")}
    record["properties"] = {k: v for k, v in dev.extension_properties.items()
                            if "ray" in k or "acceleration" in k}
    print(f"{dev.name} ({dev.driver}): {record['ray_tracing']}")
    methods = [m for m, e in zip(METHODS, ("VK_KHR_ray_query", "VK_KHR_ray_tracing_pipeline"),
                                 strict=True) if e in dev.caps]
    if "VK_KHR_acceleration_structure" not in dev.caps or not methods:
        print("no ray tracing on this device")
        record["methods"] = {}
        return 1
    scene = _scene(args.mesh)
    rays = _rays(scene, args.rays)
    with SceneAccel(dev, scene, compact=True) as accel:
        record["build"] = accel.stats()
        print("build:", json.dumps(record["build"]))
        hits, record["methods"] = {}, {}
        for m in methods:
            rc = Raycaster(dev, m)
            try:
                hits[m] = rc.trace(accel, rays, batch=args.batch)  # warm-up
                gpu, wall = [], []
                for _ in range(args.repeats):
                    rc.trace(accel, rays, batch=args.batch)
                    gpu.append(rc.last.get("mrays_per_s", float("nan")))
                    wall.append(args.rays / rc.last["wall_ms"] / 1e3)
            finally:
                rc.destroy()
            rec = {"mrays_per_s_median": statistics.median(gpu), "min": min(gpu),
                   "max": max(gpu), "wall_mrays_per_s_median": statistics.median(wall),
                   "batches": rc.last["batches"],
                   "hit_fraction": float(np.isfinite(hits[m]["t"]).mean())}
            record["methods"][m] = rec
            print(f"{m:>12}: {rec['mrays_per_s_median']:.2f} Mrays/s (GPU, median of "
                  f"{args.repeats}; {rec['min']:.2f}..{rec['max']:.2f}), "
                  f"{rec['wall_mrays_per_s_median']:.2f} Mrays/s wall, "
                  f"{rec['hit_fraction']:.1%} hit")
    if len(hits) == 2:
        a, b = hits.values()
        same = float((a == b).mean())
        record["methods_identical"] = same
        print(f"ray_query vs ray_pipeline: {same:.4%} of rays bit-identical")
    ref, kind = _reference(scene, rays)
    record["reference"] = {"kind": kind, "rays": len(ref)}
    for m, h in hits.items():
        t = h["t"][:len(ref)]
        g, r = np.isfinite(t), np.isfinite(ref)
        both = g & r
        rel = np.abs(t[both] - ref[both]) / ref[both]
        agree = {"hit_or_miss": float((g == r).mean()),
                 "t_within_1e-4": float((rel <= 1e-4).mean()) if both.any() else 1.0,
                 "t_max_rel": float(rel.max(initial=0.0))}
        record["reference"][m] = agree
        print(f"{m:>12} vs {kind} ({len(ref)} rays): hit-or-miss {agree['hit_or_miss']:.4%}, "
              f"t within 1e-4 {agree['t_within_1e-4']:.4%}, max rel {agree['t_max_rel']:.2e}")
    if args.validation:
        record["validation_messages"] = len(dev.messages)
        for msg in dev.messages[:5]:
            print("validation:", msg.text[:300])
    return 0


if __name__ == "__main__":
    sys.exit(main())
