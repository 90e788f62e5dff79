"""Meshes: each primitive as a ``Mesh`` (triangles; strips and fans become lists) or a stroke
(points and lines), Draco decoded, normals and tangents computed where the file has none;
and the geometry limit, checked from the accessors' counts before any is read."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pygltflib

from .. import limits
from ..model import Instance, Mesh, Scene
from ..util import compute_normals, compute_tangents, normalize
from .accessors import Accessors
from .file import GltfFile
from .materials import Materials

_MODES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP", 4: "TRIANGLES",
          5: "TRIANGLE_STRIP", 6: "TRIANGLE_FAN"}


def _index(value: Any, items: list) -> bool:
    """Whether ``value`` is a valid index into ``items`` (booleans are not)."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < len(items)


def check_geometry(file: GltfFile) -> None:
    """Refuse, before any accessor is read, a scene whose primitives would hold more
    than ``limits.MAX_GEOMETRY_BYTES``. Counts are the accessors' ``count``, with or
    without a bufferView (one without is ``count`` zeros: as large as one with), over
    the distinct primitives of the nodes the scene reaches. Malformed elements are left
    to the scene graph's ``build()``, which names them."""
    doc = file.doc
    nodes, meshes, scenes = doc.nodes or [], doc.meshes or [], doc.scenes or []
    if doc.scene is not None or scenes:
        k = 0 if doc.scene is None else doc.scene
        roots = list(scenes[k].nodes or []) if _index(k, scenes) else []
    else:
        roots = list(range(len(nodes)))  # build() shows every root: at worst more
    seen: set[int] = set()
    used: set[int] = set()
    while roots:
        n = roots.pop()
        if not _index(n, nodes) or n in seen:
            continue
        seen.add(n)
        if _index(nodes[n].mesh, meshes):
            used.add(nodes[n].mesh)
        roots.extend(nodes[n].children or [])
    vertices = indices = 0
    largest, name = -1, ""
    for m in sorted(used):
        for p, prim in enumerate(meshes[m].primitives or []):
            (v, vname), (i, iname) = _primitive_counts(doc, prim)
            vertices, indices = vertices + v, indices + i
            for cost, what in ((v * limits.VERTEX_BYTES, vname),
                               (i * limits.INDEX_BYTES, iname)):
                if cost > largest:
                    largest, name = cost, f"meshes[{m}].primitives[{p}]{what}"
    limits.check_geometry(vertices, indices, file=file.source, largest=name)


def _primitive_counts(doc: pygltflib.GLTF2,
                      prim: Any)  -> tuple[tuple[int, str], tuple[int, str]]:
    """(vertices, what holds them), (triangle corners, what holds them) of a primitive,
    from its accessors' counts (0 where one is malformed: build() says so)."""
    accessors = doc.accessors or []

    def count(index: Any, what: str) -> tuple[int, str]:
        if not _index(index, accessors):
            return 0, ""
        acc = accessors[index]
        n = acc.count
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            return 0, ""
        backed = "" if acc.bufferView is not None else " and no bufferView"
        return n, f", {what} accessors[{index}] with count {n:,}{backed}"

    mode = 4 if prim.mode is None else prim.mode
    if mode not in _MODES:
        return (0, ""), (0, "")  # build() says so
    position = getattr(prim.attributes, "POSITION", None) if prim.attributes else None
    v = count(position, "POSITION")
    i = count(prim.indices, "indices") if prim.indices is not None else v
    if mode in (5, 6):  # a strip or fan of n indices makes n - 2 triangles
        i = (3 * max(i[0] - 2, 0), i[1])
    elif mode in (2, 3):  # a loop or strip of n indices makes n (or n - 1) segments
        i = (2 * i[0], i[1])
    return v, i


class Meshes:
    """The primitives of ``file`` as ``scene.meshes`` and ``scene.strokes``, each made once
    however many nodes place it, and the instances that place them."""

    def __init__(self, file: GltfFile, accessors: Accessors, materials: Materials,
                 scene: Scene):
        self.file = file
        self.accessors = accessors
        self.materials = materials
        self.scene = scene
        # (mesh, primitive) -> (a stroke?, its index in scene.strokes or scene.meshes)
        self.primitives: dict[tuple[int, int], tuple[bool, int]] = {}

    def instance(self, node: Any, index: int, world: np.ndarray, *,
                 placed_by: int | None = None) -> None:
        mesh = self.file.item("meshes", node.mesh, f"nodes[{index}].mesh")
        prims = mesh.primitives or []
        if not prims:
            self.file.fail(f"meshes[{node.mesh}]", "has no primitives")
        if node.skin is not None:
            self.file.unread["skins"].append(f"nodes[{index}]")
        for p in range(len(prims)):
            key = (node.mesh, p)
            if key not in self.primitives:
                mesh_out = self.primitive(node.mesh, p)
                # points and lines are strokes, placed by stroke instances
                meshes = self.scene.meshes if mesh_out.topology == "triangle-list" \
                    else self.scene.strokes
                self.primitives[key] = (meshes is self.scene.strokes, len(meshes))
                meshes.append(mesh_out)
            stroke, k = self.primitives[key]
            instances = self.scene.stroke_instances if stroke else self.scene.instances
            instances.append(Instance(k, np.ascontiguousarray(world, np.float32),
                                      node.name or f"nodes[{index}]", placed_by))

    def primitive(self, mi: int, pi: int) -> Mesh:
        """The primitive as a Mesh: triangles, or a stroke (points or lines)."""
        mesh = self.file.doc.meshes[mi]
        prim = mesh.primitives[pi]
        where = f"meshes[{mi}].primitives[{pi}]"
        with self.file.element(where):
            attrs = {k: v for k, v in vars(prim.attributes).items() if v is not None} \
                if prim.attributes is not None else {}
            mode = self.file.integer(prim.mode, where, "mode", default=4)
            if mode not in _MODES:
                self.file.fail(where, f"mode {mode} is not a glTF primitive mode (0 to 6)")
            if prim.targets:
                self.file.unread["morphs"].append(where)
            if "POSITION" not in attrs:
                self.file.fail(where, "has no POSITION attribute")
            draco = (prim.extensions or {}).get("KHR_draco_mesh_compression")
            decoded = {} if draco is None else self.draco(draco, mode,
                                                          f"{where}.extensions."
                                                          "KHR_draco_mesh_compression")
            pos = decoded["POSITION"] if "POSITION" in decoded else \
                self.accessors.accessor(attrs["POSITION"], f"POSITION of {where}", ("VEC3",))
            n = len(pos)

            def attribute(name: str, types: tuple[str, ...]) -> np.ndarray | None:
                if name not in attrs:
                    return None
                a = decoded[name] if name in decoded else \
                    self.accessors.accessor(attrs[name], f"{name} of {where}", types)
                if len(a) != n:
                    self.file.fail(f"accessors[{attrs[name]}] ({name} of {where})",
                                   f"count {len(a)} differs from POSITION's {n}")
                return a

            normals = attribute("NORMAL", ("VEC3",))
            tangents = attribute("TANGENT", ("VEC4",))
            material = self.materials.material(prim.material, f"{where}.material")
            texcoord, uv_matrix, textured = self.materials.uv_sets.get(material, (0, None, ""))
            uvs = attribute(f"TEXCOORD_{texcoord}", ("VEC2",))
            if uvs is None and texcoord != 0:
                uvs = attribute("TEXCOORD_0", ("VEC2",))
            if uvs is None and textured:
                self.file.warn(f"{where}: has no TEXCOORD_{texcoord}, which the textures of "
                               f"{textured} use: they are sampled at (0, 0)")
            elif uvs is not None and uv_matrix is not None:
                # KHR_texture_transform is affine, so it may be applied per vertex
                uvs = uvs @ uv_matrix[:, :2].T + uv_matrix[:, 2]
            colors = attribute("COLOR_0", ("VEC3", "VEC4"))
            if colors is not None and mode > 3:
                material = self.materials.tint(material, colors, where)

            if "indices" in decoded:
                iwhere, idx = f"{where} (Draco)", decoded["indices"]
            elif prim.indices is not None:
                iwhere = f"accessors[{prim.indices}] (indices of {where})"
                idx = self.accessors.accessor(prim.indices, f"indices of {where}", ("SCALAR",),
                                              indices=True)
            else:
                iwhere, idx = f"{where} (non-indexed)", np.arange(n, dtype=np.int64)
            if len(idx) and int(idx.max()) >= n:
                self.file.fail(iwhere, f"index {int(idx.max())} out of range for {n} vertices "
                                       f"(POSITION count)")
            name = mesh.name or f"meshes[{mi}]"
            if len(mesh.primitives) > 1:
                name = f"{name}.{pi}"
            if mode <= 3:
                return self.stroke(name, mode, pos, normals, uvs, colors, idx, material,
                                   where, iwhere)
            idx = self.triangles(idx, mode, iwhere)

            if normals is None:
                normals = compute_normals(pos, idx).astype(np.float64)
            else:
                bad = np.linalg.norm(normals, axis=1) < 1e-12
                if bad.any():  # zero normals in the file: fill in computed ones
                    normals[bad] = compute_normals(pos, idx)[bad]
                normals = normalize(normals)
            if tangents is None:
                tangents = compute_tangents(pos, normals, uvs, idx)
            else:
                tangents[:, :3] = normalize(tangents[:, :3])
                tangents[:, 3] = np.where(tangents[:, 3] < 0, -1.0, 1.0)
            return Mesh(
                name=name,
                positions=np.ascontiguousarray(pos, np.float32),
                normals=np.ascontiguousarray(normals, np.float32),
                uvs=np.ascontiguousarray(np.zeros((n, 2)) if uvs is None else uvs, np.float32),
                tangents=np.ascontiguousarray(tangents, np.float32),
                indices=np.ascontiguousarray(idx, np.uint32),
                material=material,
            )

    def draco(self, ext: Any, mode: int, where: str) -> dict[str, np.ndarray]:
        """A KHR_draco_mesh_compression primitive's attributes (float64, by glTF name) and
        its triangle indices ("indices"), decoded from its buffer view."""
        if not isinstance(ext, dict) or not isinstance(ext.get("attributes"), dict):
            self.file.fail(where, "must be an object with bufferView and attributes")
        if mode != 4:
            self.file.fail(where, f"mode {mode}: Draco primitives must be TRIANGLES (4)")
        import DracoPy  # only needed for Draco-compressed scenes

        data, _, _ = self.accessors.view(ext.get("bufferView"), where)
        try:
            mesh = DracoPy.decode(bytes(data))
        except Exception as e:  # the decoder's errors have no common base
            self.file.fail(where, f"cannot decode the Draco data ({type(e).__name__}: {e})")
        faces = np.asarray(getattr(mesh, "faces", None) if mesh is not None else None)
        if faces is None or faces.ndim != 2 or faces.shape[1] != 3:
            self.file.fail(where, "the Draco data is not a triangle mesh")
        out = {"indices": faces.astype(np.int64).ravel()}
        for name, uid in ext["attributes"].items():
            found = mesh.get_attribute_by_unique_id(uid) \
                if isinstance(uid, int) and not isinstance(uid, bool) else None
            if found is None:
                self.file.fail(where, f"attributes.{name}: no Draco attribute has id "
                                      f"{json.dumps(uid)}")
            values = np.asarray(found["data"], np.float64)
            values = values.reshape(len(values), -1)
            if not np.all(np.isfinite(values)):
                self.file.fail(where, f"attributes.{name}: contains NaN or infinity")
            out[name] = values
        return out

    def stroke(self, name: str, mode: int, pos: np.ndarray, normals: np.ndarray | None,
               uvs: np.ndarray | None, colors: np.ndarray | None, idx: np.ndarray,
               material: int, where: str, iwhere: str) -> Mesh:
        """A POINTS, LINES, LINE_LOOP or LINE_STRIP primitive as a stroke: point-list or
        line-list indices, COLOR_0 per vertex (RGBA, white without). Its NORMAL is kept but
        not lit: points_lines draws every stroke unlit (glTF 2.0 section 3.7.2.1 asks that
        only of those without normals)."""
        n = len(pos)
        if mode == 1:
            if len(idx) % 2:
                self.file.fail(iwhere, f"{len(idx)} indices is not a whole number of lines")
        elif mode in (2, 3):
            # a strip joins each index to the next; a loop joins the last to the first too
            ends = np.append(idx[1:], idx[:1]) if mode == 2 and len(idx) > 2 else idx[1:]
            idx = np.stack([idx[:len(ends)], ends], axis=1).ravel() if len(idx) > 1 \
                else np.zeros(0, np.int64)
        m = self.scene.materials[material]
        if any(t is not None for t in (m.base_color_texture, m.emissive_texture)):
            self.file.unread["stroke_textures"].append(where)
        rgba = np.ones((n, 4))
        if colors is not None:
            rgba[:, :colors.shape[1]] = np.clip(colors, 0.0, 1.0)
        return Mesh(
            name=name,
            positions=np.ascontiguousarray(pos, np.float32),
            normals=np.ascontiguousarray(np.zeros((n, 3)) if normals is None
                                         else normalize(normals), np.float32),
            uvs=np.ascontiguousarray(np.zeros((n, 2)) if uvs is None else uvs, np.float32),
            tangents=np.zeros((n, 4), np.float32),
            indices=np.ascontiguousarray(idx, np.uint32),
            material=material,
            topology="point-list" if mode == 0 else "line-list",
            colors=np.ascontiguousarray(rgba, np.float32),
        )

    def triangles(self, idx: np.ndarray, mode: int, where: str) -> np.ndarray:
        """Triangle-list indices for TRIANGLES, TRIANGLE_STRIP or TRIANGLE_FAN."""
        if mode == 4:
            if len(idx) % 3:
                self.file.fail(where, f"{len(idx)} indices is not a whole number of triangles")
            return idx
        if len(idx) < 3:
            return np.zeros(0, np.int64)
        i = np.arange(len(idx) - 2)
        if mode == 5:
            # glTF 2.0 section 3.7.2.1: every other triangle flips to keep the winding
            odd = i % 2
            tri = np.stack([idx[i], idx[i + 1 + odd], idx[i + 2 - odd]], axis=1)
        else:
            tri = np.stack([idx[i + 1], idx[i + 2], np.full_like(i, idx[0])], axis=1)
        # strips stitch with repeated indices: drop the zero-area triangles they make
        keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
        return tri[keep].ravel()
