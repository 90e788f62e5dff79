"""The CPU reference for GPU ray casts: Embree, through embreex (what trimesh's
``trimesh.ray.ray_pyembree`` wraps), called directly for t, primitive and barycentrics.

Scenes are flattened to world-space triangles (float64 transforms, then float32, as Embree
takes them); ``owner`` maps each flattened triangle back to (instance, primitive).
"""

from __future__ import annotations

import numpy as np
import pytest

from rfw.scene.model import Scene

rtcore_scene = pytest.importorskip("embreex.rtcore_scene")
mesh_construction = pytest.importorskip("embreex.mesh_construction")

# the criterion for "rfw.raycast agrees with Embree"
HIT_AGREEMENT = 0.999
T_RTOL = 1e-4


def flatten(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space vertices, faces and, per face, (instance, primitive)."""
    verts, faces, owner = [], [], []
    base = 0
    for k, inst in enumerate(scene.instances):
        m = scene.meshes[inst.mesh]
        f = np.asarray(m.indices, np.int64).reshape(-1, 3)
        if not len(f):
            continue
        p = np.asarray(m.positions, np.float64)
        t = np.asarray(inst.transform, np.float64)
        verts.append(p @ t[:3, :3].T + t[:3, 3])
        faces.append(f + base)
        owner.append(np.stack([np.full(len(f), k), np.arange(len(f))], axis=1))
        base += len(p)
    return (np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32),
            np.concatenate(owner).astype(np.int32))


def embree_cast(vertices: np.ndarray, faces: np.ndarray, origins: np.ndarray,
                directions: np.ndarray) -> dict[str, np.ndarray]:
    """Closest hits from t = 0: ``t`` (inf on a miss), ``primitive`` (-1), ``u``, ``v``."""
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, np.ascontiguousarray(vertices, np.float32),
                                   np.ascontiguousarray(faces, np.int32))
    r = scene.run(np.ascontiguousarray(origins, np.float32),
                  np.ascontiguousarray(directions, np.float32), output=1)
    hit = r["primID"] >= 0
    return {"t": np.where(hit, r["tfar"], np.inf).astype(np.float32),
            "primitive": np.where(hit, r["primID"], -1).astype(np.int32),
            "u": r["u"], "v": r["v"]}


def agreement(gpu_t: np.ndarray, ref_t: np.ndarray) -> tuple[float, float, int]:
    """(fraction agreeing on hit or miss, largest relative t difference where both hit,
    rays where both hit)."""
    g, r = np.isfinite(gpu_t), np.isfinite(ref_t)
    both = g & r
    rel = np.abs(gpu_t[both] - ref_t[both]) / np.maximum(np.abs(ref_t[both]), 1e-30)
    return float((g == r).mean()), float(rel.max(initial=0.0)), int(both.sum())
