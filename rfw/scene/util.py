"""Shared geometry helpers for the loaders: normals, tangents, frames and colour conversion.

Everything here is vectorised numpy; loaders call it on whole meshes.
"""

from __future__ import annotations

import numpy as np


def _accumulate(indices: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """Sum per-corner ``values`` (T*3, C) into ``count`` vertices."""
    out = np.empty((count, values.shape[1]), np.float64)
    for c in range(values.shape[1]):
        # bincount beats np.add.at by an order of magnitude on large meshes
        out[:, c] = np.bincount(indices, weights=values[:, c], minlength=count)
    return out


def normalize(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """Unit vectors along the last axis; zero-length rows become ``fallback`` (default +Y).

    Parameters
    ----------
    v : (N, 3) array
    fallback : (3,) or (N, 3) array, optional
    """
    v = np.asarray(v, np.float64)
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = length[..., 0] > 1e-20
    out = np.divide(v, length, out=np.zeros_like(v), where=length > 1e-20)
    if fallback is None:
        fallback = np.array([0.0, 1.0, 0.0])
    fb = np.broadcast_to(np.asarray(fallback, np.float64), v.shape)
    out[~ok] = fb[~ok]
    return out


def compute_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals.

    Each triangle adds its unnormalised face normal (length = twice its area) to its three
    corners, so large faces dominate. Vertices used by no triangle, or only by degenerate
    ones, get +Y.

    Parameters
    ----------
    positions : (V, 3) array
    indices : (T*3,) integer array, counter-clockwise triangles

    Returns
    -------
    (V, 3) float32 array of unit normals
    """
    p = np.asarray(positions, np.float64)
    tri = np.asarray(indices, np.int64).reshape(-1, 3)
    if len(tri) == 0:
        return np.tile(np.float32([0, 1, 0]), (len(p), 1))
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    face = np.cross(b - a, c - a)
    acc = _accumulate(tri.ravel(), np.repeat(face, 3, axis=0), len(p))
    return normalize(acc).astype(np.float32)


def any_tangent(normals: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each normal (for meshes without usable UVs)."""
    n = normalize(normals)
    # cross with the axis least aligned with n: never degenerate
    axis = np.zeros_like(n)
    axis[np.arange(len(n)), np.argmin(np.abs(n), axis=1)] = 1.0
    return normalize(np.cross(axis, n))


def compute_tangents(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray | None,
                     indices: np.ndarray) -> np.ndarray:
    """Per-vertex tangents in glTF convention: xyz along +U, w the bitangent sign.

    Per-triangle accumulation in the spirit of MikkTSpace (Lengyel's method): each triangle's
    dP/du and dP/dv are summed at its corners, then the tangent is Gram-Schmidt orthogonalised
    against the normal. glTF's v runs down the image, so the bitangent ``cross(n, t) * w``
    follows -dP/dv; a mirrored mapping gives w = -1. Without UVs, or where the UVs are
    degenerate, any unit vector perpendicular to the normal is used with w = +1.

    Parameters
    ----------
    positions, normals : (V, 3) arrays
    uvs : (V, 2) array or None
    indices : (T*3,) integer array

    Returns
    -------
    (V, 4) float32 array
    """
    p = np.asarray(positions, np.float64)
    n = normalize(normals)
    count = len(p)
    fallback = any_tangent(n)
    out = np.ones((count, 4), np.float64)
    out[:, :3] = fallback
    tri = np.asarray(indices, np.int64).reshape(-1, 3)
    if uvs is None or len(tri) == 0:
        return out.astype(np.float32)
    uv = np.asarray(uvs, np.float64)
    i0, i1, i2 = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = p[i1] - p[i0], p[i2] - p[i0]
    d1, d2 = uv[i1] - uv[i0], uv[i2] - uv[i0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    r = np.zeros_like(det)
    r[ok] = 1.0 / det[ok]
    # sign(det) keeps mirrored triangles consistent; |det| weighting is area in uv space
    sdir = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r[:, None]  # dP/du
    tdir = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r[:, None]  # dP/dv
    # weight by the triangle's area so tiny slivers with huge dP/du do not dominate
    area = np.linalg.norm(np.cross(e1, e2), axis=1)
    su, sv = normalize(sdir, np.zeros(3)), normalize(tdir, np.zeros(3))
    su *= area[:, None]
    sv *= area[:, None]
    flat = tri.ravel()
    acc_u = _accumulate(flat, np.repeat(su, 3, axis=0), count)
    acc_v = _accumulate(flat, np.repeat(sv, 3, axis=0), count)
    t = acc_u - n * np.sum(n * acc_u, axis=1, keepdims=True)
    # scale-free test: the part of dP/du off the normal must be a real fraction of it
    size = np.linalg.norm(acc_u, axis=1)
    good = (size > 0.0) & (np.linalg.norm(t, axis=1) > 1e-6 * size)
    t = normalize(t, fallback)
    out[good, :3] = t[good]
    w = np.where(np.sum(np.cross(n, t) * -acc_v, axis=1) < 0.0, -1.0, 1.0)
    out[good, 3] = w[good]
    return out.astype(np.float32)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def check_mesh_arrays(positions: np.ndarray, indices: np.ndarray) -> str | None:
    """Why these arrays cannot form a mesh, or None when they can."""
    if len(indices) % 3:
        return f"{len(indices)} indices is not a whole number of triangles"
    if len(indices) and int(indices.max()) >= len(positions):
        return (f"index {int(indices.max())} out of range for {len(positions)} vertices")
    if not np.all(np.isfinite(positions)):
        return "positions contain NaN or infinity"
    return None
