"""Double-sided materials as geometry: every pass and backend draws single-sided.

Pipelines cull back faces (the shadow map front faces), and no shader turns a normal to the
viewer, so a double-sided material (glTF ``doubleSided``; every mesh file that is not a
closed, outward-wound surface) would vanish where it is seen from behind. ``with_back_faces``
gives each of its meshes a second copy of its triangles, wound the other way, with normals
and tangent handedness reversed: exactly one of each pair faces any viewer, so culling keeps
one and depth never sees two, identical on every backend and pass (rasterised, meshlet,
ray-traced). The cost is twice the vertices and triangles of those meshes.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .model import Mesh, Scene


def with_back_faces(scene: Scene) -> Scene:
    """``scene`` with the back faces of its double-sided materials' meshes added; those
    materials come back single-sided, so a second call changes nothing. ``scene`` itself
    when none is double-sided."""
    two = {k for k, m in enumerate(scene.materials) if m.double_sided}
    if not any(m.material in two for m in scene.meshes):
        return scene
    meshes = [back_faced(m) if m.material in two else m for m in scene.meshes]
    materials = [replace(m, double_sided=False) if k in two else m
                 for k, m in enumerate(scene.materials)]
    return replace(scene, meshes=meshes, materials=materials)


def back_faced(mesh: Mesh) -> Mesh:
    """``mesh`` and its back side: the vertices again with normals reversed, the triangles
    again with two corners swapped (clockwise seen from the front)."""
    n = len(mesh.positions)
    tangents = mesh.tangents.astype(np.float32, copy=True)
    # the bitangent cross(n, t) * w must keep pointing along +v, so w flips with n
    tangents[:, 3] *= -1.0
    front = mesh.indices.astype(np.uint32, copy=False)
    back = front.reshape(-1, 3)[:, [0, 2, 1]] + np.uint32(n)
    # np.concatenate makes new, contiguous arrays
    return replace(
        mesh,
        positions=np.concatenate([mesh.positions, mesh.positions]),
        normals=np.concatenate([mesh.normals, -mesh.normals]),
        uvs=np.concatenate([mesh.uvs, mesh.uvs]),
        tangents=np.concatenate([mesh.tangents, tangents]),
        indices=np.concatenate([front, back.ravel()]))


def closed_outward(positions: np.ndarray, faces: np.ndarray) -> bool:
    """True when ``faces`` (T, 3) close a surface wound consistently with its front outside
    (positive volume): seen from outside, single-sided drawing then shows all of it.
    Vertices at the same position count as one (UV seams split them in files)."""
    if len(faces) == 0:
        return False
    _, same = np.unique(np.asarray(positions), axis=0, return_inverse=True)
    f = same.reshape(-1)[np.asarray(faces, np.int64)]
    n = int(f.max()) + 1
    edges = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    if np.any(edges[:, 0] == edges[:, 1]):
        return False  # a degenerate triangle: no orientation to trust
    forward = np.sort(edges[:, 0] * n + edges[:, 1])
    reverse = np.sort(edges[:, 1] * n + edges[:, 0])
    # each directed edge once, and its twin once: closed, manifold, consistently wound
    if np.any(forward[1:] == forward[:-1]) or not np.array_equal(forward, reverse):
        return False
    p = np.asarray(positions, np.float64)[np.asarray(faces, np.int64)]
    volume = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0
    return volume > 0.0
