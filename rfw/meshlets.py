"""Meshlets for mesh shading: meshoptimizer's clusterizer, its bounds, and GPU packing.

A meshlet is a small cluster of triangles (at most ``max_vertices`` vertices and
``max_triangles`` triangles) addressed through two shared arrays: ``vertices`` maps each
meshlet-local vertex to a mesh vertex, and ``triangles`` holds three 8-bit local indices per
triangle, each meshlet's run zero-padded to a multiple of 4 bytes so it can be read as
``uint`` words. Per meshlet we keep a bounding sphere and a normal cone for backface culling.

The work is done by meshoptimizer's C library (``meshopt_buildMeshlets``,
``meshopt_computeMeshletBounds``), called through ctypes from the extension module of the
PyPI package ``meshoptimizer`` (pinned, see ``MESHOPTIMIZER_PIN``; the package ships as an
sdist only, so installing it compiles the C++ sources). The cone test, as meshoptimizer
documents it for a perspective camera at ``camera``, culls a meshlet when::

    dot(normalize(cone_apex - camera), cone_axis) >= cone_cutoff

and with the 8-bit cone (``axis = cone_axis_s8 / 127``, ``cutoff = cone_cutoff_s8 / 127``)
the same test stays conservative: the 8-bit cutoff is rounded up by the axis error.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.machinery
import importlib.metadata
import importlib.util
import io
import zipfile
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .errors import warn
from .fileio import atomic_write

# the PyPI package bundles the C library 0.22 (MESHOPTIMIZER_VERSION 220 in its src/meshoptimizer.h)
MESHOPTIMIZER_PIN = "0.2.30a0"
MAX_VERTICES_LIMIT = 255  # kMeshletMaxVertices in clusterizer.cpp
MAX_TRIANGLES_LIMIT = 512  # kMeshletMaxTriangles
CACHE_FORMAT = 2  # bump when the cached arrays change meaning
# an entry: magic, sha256 of the payload, then the payload (an .npz of the arrays)
CACHE_MAGIC = b"RFWMLT2\n"
CACHE_SUFFIX = ".meshlets"


# ---------------------------------------------------------------------------------------------
# the C library


class _CMeshlet(ctypes.Structure):
    _fields_ = [
        ("vertex_offset", ctypes.c_uint),
        ("triangle_offset", ctypes.c_uint),
        ("vertex_count", ctypes.c_uint),
        ("triangle_count", ctypes.c_uint),
    ]


class _CBounds(ctypes.Structure):
    _fields_ = [
        ("center", ctypes.c_float * 3),
        ("radius", ctypes.c_float),
        ("cone_apex", ctypes.c_float * 3),
        ("cone_axis", ctypes.c_float * 3),
        ("cone_cutoff", ctypes.c_float),
        ("cone_axis_s8", ctypes.c_byte * 3),
        ("cone_cutoff_s8", ctypes.c_byte),
    ]


@functools.cache
def _library() -> ctypes.CDLL:
    """The meshoptimizer extension module loaded as a plain shared library, signatures set."""
    spec = importlib.util.find_spec("meshoptimizer")  # finds the package without running it
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            f"rfw.meshlets needs meshoptimizer=={MESHOPTIMIZER_PIN} (pip builds it from source: "
            "it needs a C++ compiler and the Python headers)"
        )
    version = importlib.metadata.version("meshoptimizer")
    if version != MESHOPTIMIZER_PIN:
        # the C signatures below are those of this version's header; others may differ
        raise ImportError(
            f"rfw.meshlets is written against meshoptimizer=={MESHOPTIMIZER_PIN}, found {version}"
        )
    candidates = [
        Path(folder) / f"_meshoptimizer{suffix}"
        for folder in spec.submodule_search_locations
        for suffix in importlib.machinery.EXTENSION_SUFFIXES
    ]
    path = next((p for p in candidates if p.is_file()), None)
    if path is None:
        raise ImportError(
            f"meshoptimizer {version} is installed but has no built extension in {spec.origin}"
        )
    lib = ctypes.CDLL(str(path))

    size_t, f32p, u32p, u8p = ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p
    lib.meshopt_buildMeshletsBound.argtypes = [size_t, size_t, size_t]
    lib.meshopt_buildMeshletsBound.restype = size_t
    # (meshlets, meshlet_vertices, meshlet_triangles, indices, index_count, vertex_positions,
    #  vertex_count, vertex_positions_stride, max_vertices, max_triangles, cone_weight)
    lib.meshopt_buildMeshlets.argtypes = [
        ctypes.c_void_p, u32p, u8p, u32p, size_t, f32p, size_t, size_t, size_t, size_t, ctypes.c_float
    ]  # fmt: skip
    lib.meshopt_buildMeshlets.restype = size_t
    # (meshlet_vertices, meshlet_triangles, triangle_count, vertex_positions, vertex_count, stride)
    lib.meshopt_computeMeshletBounds.argtypes = [u32p, u8p, size_t, f32p, size_t, size_t]
    lib.meshopt_computeMeshletBounds.restype = _CBounds
    return lib


def _ptr(array: np.ndarray) -> int:
    return array.ctypes.data


# ---------------------------------------------------------------------------------------------
# building


@dataclass
class MeshletBounds:
    """Per-meshlet culling data, as ``meshopt_Bounds`` fields stacked over meshlets."""

    center: np.ndarray  # (M, 3) float32, bounding sphere
    radius: np.ndarray  # (M,) float32
    cone_apex: np.ndarray  # (M, 3) float32
    cone_axis: np.ndarray  # (M, 3) float32, unit
    cone_cutoff: np.ndarray  # (M,) float32; 1 means "never cull"
    cone_axis_s8: np.ndarray  # (M, 3) int8, snorm: axis ~ s8 / 127
    cone_cutoff_s8: np.ndarray  # (M,) int8, rounded up so the 8-bit test stays conservative


@dataclass
class Meshlets:
    """Meshlets of one mesh in meshoptimizer's layout."""

    # (M, 4) uint32: vertex_offset, triangle_offset (in bytes), vertex_count, triangle_count
    meshlets: np.ndarray
    # (N,) uint32 indices into the mesh's vertex array
    vertices: np.ndarray
    # (B,) uint8, 3 local indices per triangle, each meshlet's run zero-padded to 4 bytes
    triangles: np.ndarray
    bounds: MeshletBounds

    def __len__(self) -> int:
        return len(self.meshlets)

    def triangle_indices(self) -> np.ndarray:
        """The mesh triangles, (T, 3) uint32, in meshlet order (for checks and debug draws)."""
        out = []
        for v_off, t_off, _, t_count in self.meshlets:
            local = self.triangles[t_off : t_off + 3 * t_count].astype(np.int64)
            out.append(self.vertices[v_off + local].reshape(-1, 3))
        return np.concatenate(out) if out else np.zeros((0, 3), np.uint32)


def _check_limits(max_vertices: int, max_triangles: int) -> None:
    # meshoptimizer asserts these, but release builds compile asserts out
    if not 3 <= max_vertices <= MAX_VERTICES_LIMIT:
        raise ValueError(f"max_vertices must be in [3, {MAX_VERTICES_LIMIT}], got {max_vertices}")
    if not 4 <= max_triangles <= MAX_TRIANGLES_LIMIT or max_triangles % 4:
        raise ValueError(
            f"max_triangles must be a multiple of 4 in [4, {MAX_TRIANGLES_LIMIT}], got {max_triangles}"
        )


def _as_mesh(positions: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions must be (V, 3), got {positions.shape}")
    indices = np.asarray(indices)
    if indices.size and (indices.min() < 0 or indices.max() >= len(positions)):
        raise ValueError(f"indices must lie in [0, {len(positions)})")
    indices = np.ascontiguousarray(indices, dtype=np.uint32).reshape(-1)
    if indices.size % 3:
        raise ValueError(f"index count must be a multiple of 3, got {indices.size}")
    return positions, indices


def build_meshlets(
    positions: np.ndarray,
    indices: np.ndarray,
    *,
    max_vertices: int = 64,
    max_triangles: int = 124,
    cone_weight: float = 0.25,
) -> Meshlets:
    """Split a triangle mesh into meshlets with ``meshopt_buildMeshlets`` and bound each one.

    Parameters
    ----------
    positions : (V, 3) float array
    indices : (T*3,) or (T, 3) integer array, counter-clockwise front faces
    max_vertices, max_triangles : per-meshlet limits; 64/124 suit NVIDIA's mesh shaders
        (max_triangles must be a multiple of 4: triangle runs are padded to 4 bytes)
    cone_weight : 0 favours compact clusters, towards 1 tighter normal cones (better culling)
    """
    _check_limits(max_vertices, max_triangles)
    positions, indices = _as_mesh(positions, indices)
    lib = _library()

    bound = lib.meshopt_buildMeshletsBound(indices.size, max_vertices, max_triangles)
    c_meshlets = (_CMeshlet * max(bound, 1))()
    vertices = np.zeros(max(bound, 1) * max_vertices, np.uint32)
    triangles = np.zeros(max(bound, 1) * max_triangles * 3, np.uint8)
    count = 0
    if indices.size:
        count = lib.meshopt_buildMeshlets(
            ctypes.addressof(c_meshlets), _ptr(vertices), _ptr(triangles), _ptr(indices), indices.size,
            _ptr(positions), len(positions), 12, max_vertices, max_triangles, float(cone_weight),
        )  # fmt: skip
    table = np.frombuffer(c_meshlets, dtype=np.uint32).reshape(-1, 4)[:count].copy()
    if count:
        # trim the worst-case allocations to what the last meshlet reaches
        v_off, t_off, v_count, t_count = (int(x) for x in table[-1])
        vertices = vertices[: v_off + v_count].copy()
        triangles = triangles[: t_off + ((3 * t_count + 3) & ~3)].copy()
    else:
        vertices, triangles = vertices[:0].copy(), triangles[:0].copy()
    return Meshlets(table, vertices, triangles, _bounds(lib, table, vertices, triangles, positions))


def _bounds(
    lib, table: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, positions: np.ndarray
) -> MeshletBounds:
    raw = (_CBounds * max(len(table), 1))()
    base_v, base_t, base_p = _ptr(vertices), _ptr(triangles), _ptr(positions)
    for i, (v_off, t_off, _, t_count) in enumerate(table.tolist()):
        raw[i] = lib.meshopt_computeMeshletBounds(
            base_v + 4 * v_off, base_t + t_off, t_count, base_p, len(positions), 12
        )
    record = np.dtype(
        [("center", "<f4", 3), ("radius", "<f4"), ("cone_apex", "<f4", 3), ("cone_axis", "<f4", 3),
         ("cone_cutoff", "<f4"), ("cone_axis_s8", "i1", 3), ("cone_cutoff_s8", "i1")]
    )  # fmt: skip
    assert record.itemsize == ctypes.sizeof(_CBounds)
    rows = np.frombuffer(raw, dtype=record)[: len(table)]
    return MeshletBounds(**{f.name: rows[f.name].copy() for f in fields(MeshletBounds)})


# ---------------------------------------------------------------------------------------------
# GPU layout


def pack_for_gpu(meshlets: Meshlets) -> dict[str, np.ndarray]:
    """The storage buffers a task/mesh shader pair reads, std430-friendly.

    - ``meshlets`` (M, 4) uint32: vertex_offset, triangle_offset in *words*, vertex_count,
      triangle_count
    - ``vertices`` (N,) uint32: mesh vertex index per meshlet-local vertex
    - ``triangles`` (W,) uint32: the 8-bit local indices, four per word, little-endian
      (``(word >> 8 * (i & 3)) & 0xff`` is byte ``i``)
    - ``spheres`` (M, 4) float32: center xyz, radius
    - ``cones`` (M,) uint32: int8 axis x, y, z and int8 cutoff, byte 0 first
    - ``cone_apex`` (M, 4) float32: apex xyz, w = 0 (pairs with the 8-bit axis and cutoff)
    """
    b = meshlets.bounds
    table = meshlets.meshlets.astype(np.uint32, copy=True)
    if len(meshlets.triangles) % 4 or np.any(table[:, 1] % 4):
        raise ValueError("triangle runs must start on 4-byte boundaries")
    table[:, 1] //= 4
    cone_bytes = np.concatenate([b.cone_axis_s8, b.cone_cutoff_s8[:, None]], axis=1)
    m = len(table)
    words = np.ascontiguousarray(meshlets.triangles, dtype=np.uint8).view("<u4")
    spheres = np.concatenate([b.center, b.radius[:, None]], axis=1).reshape(m, 4)
    cones = np.ascontiguousarray(cone_bytes, dtype=np.int8).view("<u4").reshape(m)
    apex = np.concatenate([b.cone_apex, np.zeros((m, 1), np.float32)], axis=1)
    return {
        "meshlets": table,
        "vertices": meshlets.vertices.astype(np.uint32, copy=True),
        "triangles": words.astype(np.uint32),
        "spheres": spheres.astype(np.float32),
        "cones": cones.astype(np.uint32),
        "cone_apex": apex.astype(np.float32),
    }


# ---------------------------------------------------------------------------------------------
# disk cache


def default_cache_dir() -> Path:
    """``$RFW_CACHE_MESHLETS`` if set, else ``~/.cache/rfw/meshlets``."""
    from . import env

    return env.get("RFW_CACHE_MESHLETS") or Path.home() / ".cache" / "rfw" / "meshlets"


def meshlet_cache_key(
    positions: np.ndarray,
    indices: np.ndarray,
    *,
    max_vertices: int,
    max_triangles: int,
    cone_weight: float,
) -> str:
    """sha256 over the mesh bytes, the parameters and the library version."""
    positions, indices = _as_mesh(positions, indices)
    h = hashlib.sha256()
    h.update(f"rfw.meshlets/{CACHE_FORMAT}/meshoptimizer {MESHOPTIMIZER_PIN}/".encode())
    h.update(
        f"{len(positions)}/{indices.size}/{max_vertices}/{max_triangles}/{float(cone_weight)!r}/".encode()
    )
    h.update(positions.tobytes())
    h.update(indices.tobytes())
    return h.hexdigest()


def cached_meshlets(
    positions: np.ndarray,
    indices: np.ndarray,
    *,
    max_vertices: int = 64,
    max_triangles: int = 124,
    cone_weight: float = 0.25,
    cache_dir: Path | str | None = None,
) -> Meshlets:
    """``build_meshlets`` through a content-addressed cache (written atomically). A damaged
    entry is rebuilt with one warning; a cache folder that cannot be written is skipped with
    one warning."""
    params = dict(max_vertices=max_vertices, max_triangles=max_triangles, cone_weight=cone_weight)
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = folder / f"{meshlet_cache_key(positions, indices, **params)}{CACHE_SUFFIX}"
    if path.is_file():
        found = _read_entry(path)
        if found is not None:
            return found
        warn(f"{path}: corrupt cache entry, rebuilt")
    result = build_meshlets(positions, indices, **params)
    try:
        atomic_write(path, lambda f: f.write(_encode_entry(result)))  # old or whole new
    except OSError as e:
        warn(f"{folder}: cannot write the meshlet cache ({e.strerror or e}); not cached")
    return result


def _encode_entry(m: Meshlets) -> bytes:
    arrays = {"meshlets": m.meshlets, "vertices": m.vertices, "triangles": m.triangles}
    arrays.update({f"bounds.{f.name}": getattr(m.bounds, f.name) for f in fields(MeshletBounds)})
    payload = io.BytesIO()
    np.savez(payload, **arrays)
    body = payload.getvalue()
    return CACHE_MAGIC + hashlib.sha256(body).digest() + body


def _read_entry(path: Path) -> Meshlets | None:
    """The cached meshlets, or None when the entry is damaged: the magic and a sha256 over
    the payload catch truncation and flipped bytes before numpy reads anything."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    head = len(CACHE_MAGIC) + 32
    body = data[head:]
    if len(data) < head or not data.startswith(CACHE_MAGIC) \
            or hashlib.sha256(body).digest() != data[len(CACHE_MAGIC):head]:
        return None
    try:
        with np.load(io.BytesIO(body), allow_pickle=False) as z:
            bounds = MeshletBounds(**{f.name: z[f"bounds.{f.name}"] for f in fields(MeshletBounds)})
            return Meshlets(z["meshlets"], z["vertices"], z["triangles"], bounds)
    except (KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None  # a checksummed entry of another layout: rebuilt like a damaged one
