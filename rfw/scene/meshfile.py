"""OBJ, PLY, STL, OFF (whatever trimesh reads as triangle meshes) to a ``Scene``.

Each trimesh geometry becomes one ``Mesh`` and each scene-graph node using it one
``Instance``. Materials: trimesh's PBR materials map field by field; simple (OBJ/MTL)
materials give a base colour, a roughness from the specular exponent and the diffuse map;
vertex or face colours, which the model cannot carry per vertex, are averaged into the base
colour. Textures are only read from the file's folder (trimesh's resolver enforces it).

These formats say nothing about which side of a triangle is its front: a mesh that is not a
closed surface wound outward (``sides.closed_outward``) gets a double-sided material, so a
triangle seen from behind is drawn (``sides.with_back_faces``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from .model import Instance, Material, Mesh, Scene, SceneError, Texture
from .sides import closed_outward
from .util import compute_normals, compute_tangents, normalize, srgb_to_linear

# trimesh formats that are not triangle meshes, or are handled elsewhere
_NOT_MESHES = {"gltf", "glb", "dxf", "svg", "xyz", "zip", "bz2", "tar.bz2", "tar.gz",
               "stl_ascii", "dict", "dict64", "json"}


def mesh_suffixes() -> frozenset[str]:
    """File suffixes (with the dot, lower case) this loader accepts."""
    return frozenset("." + f for f in trimesh.available_formats() if f not in _NOT_MESHES)


def load_meshfile(path: str | Path) -> Scene:
    """Load a mesh file through trimesh.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        When the file is missing, unreadable or holds no triangles; the message names it.
    """
    path = Path(path)
    source = str(path)
    if not path.exists():
        raise SceneError(f"{source}: file not found")
    if not path.is_file():
        raise SceneError(f"{source}: not a file")
    try:
        loaded = trimesh.load(path, force=None)
    except Exception as e:  # trimesh's parsers raise anything from KeyError to struct.error
        raise SceneError(f"{source}: cannot read it as a mesh "
                         f"({type(e).__name__}: {e})".replace("\n", " ")) from None
    return _Converter(source, path.stem).convert(loaded)


def _file_normals(geom: trimesh.Trimesh) -> np.ndarray | None:
    """The normals the file gave, where trimesh kept them; None otherwise."""
    # trimesh computes missing normals on access (angle-weighted, and noisily without
    # scipy); only take the ones it holds, and compute the rest like the glTF loader does
    try:
        if "vertex_normals" in geom._cache:
            return np.array(geom.vertex_normals, np.float64)
    except Exception:  # a trimesh without that private cache: compute
        pass
    return None


class _Converter:
    def __init__(self, source: str, name: str):
        self.source = source
        self.scene = Scene(name=name, materials=[], source=source)
        self.meshes: dict[str, int] = {}
        self.materials: dict[int, int] = {}
        self.textures: dict[tuple[int, bool], int] = {}
        self.default: int | None = None
        self.two_sided: dict[int, int] = {}  # material -> its double-sided copy
        self.keep: list[Any] = []  # keeps id()-keyed objects alive while converting

    def convert(self, loaded: Any) -> Scene:
        if isinstance(loaded, (trimesh.Trimesh, trimesh.PointCloud)):
            items = [("mesh", np.identity(4), loaded.metadata.get("name") or "mesh", loaded)]
        elif isinstance(loaded, trimesh.Scene):
            items = []
            for node in loaded.graph.nodes_geometry:
                transform, gname = loaded.graph[node]
                items.append((node, transform, gname, loaded.geometry.get(gname)))
        else:
            raise SceneError(f"{self.source}: trimesh read a {type(loaded).__name__}, not a "
                             "triangle mesh")
        skipped = set()
        strokes: dict[str, int] = {}
        for node, transform, gname, geom in items:
            # what trimesh reads as a point cloud (a PLY or OBJ of vertices only); a Trimesh
            # left without faces (its NaN corners dropped, an OFF of 0 faces) is refused
            points = isinstance(geom, trimesh.PointCloud) and len(geom.vertices) > 0
            if not points and (not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0):
                skipped.add(type(geom).__name__)
                continue
            known, meshes = (strokes, self.scene.strokes) if points else \
                (self.meshes, self.scene.meshes)
            if gname not in known:
                mesh = self.points(gname, geom) if points else self.mesh(gname, geom)
                if mesh is None:
                    continue
                known[gname] = len(meshes)
                meshes.append(mesh)
            t = np.asarray(transform, np.float64)
            if t.shape != (4, 4) or not np.all(np.isfinite(t)):
                raise SceneError(f"{self.source}: node {node!r}: transform is not a finite "
                                 "4x4 matrix")
            placed = self.scene.stroke_instances if points else self.scene.instances
            placed.append(Instance(known[gname], np.ascontiguousarray(t, np.float32),
                                   str(node)))
        if not self.scene.instances and not self.scene.stroke_instances:
            what = f" (only {', '.join(sorted(skipped))})" if skipped else ""
            raise SceneError(f"{self.source}: no triangles or points found{what}")
        return self.scene.drawable()  # zero-scale nodes: skipped with a warning

    def mesh(self, name: str, geom: trimesh.Trimesh) -> Mesh | None:
        positions = np.asarray(geom.vertices, np.float64)
        faces = np.asarray(geom.faces, np.int64)
        if not np.all(np.isfinite(positions)):
            raise SceneError(f"{self.source}: geometry {name!r}: positions contain NaN or "
                             "infinity")
        if faces.min() < 0 or faces.max() >= len(positions):
            raise SceneError(f"{self.source}: geometry {name!r}: face index out of range for "
                             f"{len(positions)} vertices")
        indices = faces.ravel()
        normals = _file_normals(geom)
        if normals is None or normals.shape != positions.shape:
            normals = compute_normals(positions, indices)
        bad = np.linalg.norm(normals, axis=1) < 1e-12
        if bad.any():
            normals[bad] = compute_normals(positions, indices)[bad]
        normals = normalize(normals)
        uvs = None
        visual = geom.visual
        uv = getattr(visual, "uv", None) if visual is not None else None
        if uv is not None:
            uv = np.asarray(uv, np.float64)
            if uv.shape == (len(positions), 2) and np.all(np.isfinite(uv)):
                # trimesh keeps OBJ's v-up; the model's images are top row first (glTF)
                uvs = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])
        tangents = compute_tangents(positions, normals, uvs, indices)
        material = self.material(name, visual)
        if not closed_outward(positions, faces):
            material = self.double_sided(material)
        return Mesh(
            name=str(name),
            positions=np.ascontiguousarray(positions, np.float32),
            normals=np.ascontiguousarray(normals, np.float32),
            uvs=np.ascontiguousarray(np.zeros((len(positions), 2)) if uvs is None else uvs,
                                     np.float32),
            tangents=np.ascontiguousarray(tangents, np.float32),
            indices=np.ascontiguousarray(indices, np.uint32),
            material=material,
        )

    # -- materials -------------------------------------------------------------------------

    def points(self, name: str, geom: trimesh.PointCloud) -> Mesh | None:
        """A point cloud as a stroke (point-list), its colours per vertex: the file's bytes
        taken as sRGB, as triangle meshes' colours are; white without any."""
        pos = np.asarray(geom.vertices, np.float64)
        if not np.all(np.isfinite(pos)):
            raise SceneError(f"{self.source}: {name}: a point position is NaN or infinite")
        n = len(pos)
        rgba = np.ones((n, 4))
        colors = np.asarray(getattr(geom, "colors", ()), np.float64)
        if colors.shape == (n, 4):
            rgba[:, :3] = srgb_to_linear(colors[:, :3] / 255.0)
            rgba[:, 3] = colors[:, 3] / 255.0
        if self.default is None:
            self.default = self.add(Material(name="default"))
        return Mesh(name=name, positions=np.ascontiguousarray(pos, np.float32),
                    normals=np.zeros((n, 3), np.float32), uvs=np.zeros((n, 2), np.float32),
                    tangents=np.zeros((n, 4), np.float32),
                    indices=np.arange(n, dtype=np.uint32), material=self.default,
                    topology="point-list", colors=np.ascontiguousarray(rgba, np.float32))

    def material(self, name: str, visual: Any) -> int:
        mat = getattr(visual, "material", None)
        if mat is not None:
            key = id(mat)
            if key not in self.materials:
                self.keep.append(mat)
                self.materials[key] = self.add(self.from_trimesh(mat, name))
            return self.materials[key]
        kind = getattr(visual, "kind", None)
        if kind in ("vertex", "face"):
            colors = visual.vertex_colors if kind == "vertex" else visual.face_colors
            rgba = np.asarray(colors, np.float64).reshape(-1, 4).mean(axis=0) / 255.0
            base = (*map(float, srgb_to_linear(rgba[:3])), float(rgba[3]))
            out = Material(name=f"{name} colours", base_color=base)
            if base[3] < 1.0:
                out.alpha_mode = "BLEND"
            return self.add(out)
        if self.default is None:
            self.default = self.add(Material(name="default"))
        return self.default

    def double_sided(self, index: int) -> int:
        """``index``, or a double-sided copy of it (one per material)."""
        mat = self.scene.materials[index]
        if mat.double_sided:
            return index
        if index not in self.two_sided:
            self.two_sided[index] = self.add(replace(mat, double_sided=True))
        return self.two_sided[index]

    def add(self, material: Material) -> int:
        self.scene.materials.append(material)
        return len(self.scene.materials) - 1

    def from_trimesh(self, mat: Any, name: str) -> Material:
        pbr = trimesh.visual.material.PBRMaterial
        out = Material(name=getattr(mat, "name", None) or f"{name} material")
        if isinstance(mat, pbr):
            if mat.baseColorFactor is not None:
                # trimesh stores glTF's linear factor as uint8
                out.base_color = tuple(float(c) / 255.0 for c in mat.baseColorFactor)
            out.metallic = 1.0 if mat.metallicFactor is None else float(mat.metallicFactor)
            out.roughness = 1.0 if mat.roughnessFactor is None else float(mat.roughnessFactor)
            if mat.emissiveFactor is not None:
                out.emissive = tuple(float(c) for c in np.asarray(mat.emissiveFactor)[:3])
            out.base_color_texture = self.texture(mat.baseColorTexture, True, name)
            out.metallic_roughness_texture = self.texture(mat.metallicRoughnessTexture, False,
                                                          name)
            out.normal_texture = self.texture(mat.normalTexture, False, name)
            out.occlusion_texture = self.texture(mat.occlusionTexture, False, name)
            out.emissive_texture = self.texture(mat.emissiveTexture, True, name)
            if mat.alphaMode in ("OPAQUE", "MASK", "BLEND"):
                out.alpha_mode = mat.alphaMode
            if mat.alphaCutoff is not None:
                out.alpha_cutoff = float(mat.alphaCutoff)
            out.double_sided = bool(mat.doubleSided)
            return out
        diffuse = getattr(mat, "diffuse", None)
        if diffuse is not None:
            rgba = np.asarray(diffuse, np.float64).reshape(-1)[:4] / 255.0
            out.base_color = (*map(float, srgb_to_linear(rgba[:3])), float(rgba[3]))
        gloss = getattr(mat, "glossiness", None)
        if gloss is not None:
            # trimesh's own Blinn-Phong exponent to roughness conversion
            out.roughness = float((2.0 / (max(float(gloss), 0.0) + 2.0)) ** 0.25)
        out.base_color_texture = self.texture(getattr(mat, "image", None), True, name)
        return out

    def texture(self, image: Any, srgb: bool, name: str) -> int | None:
        if image is None:
            return None
        key = (id(image), srgb)
        if key not in self.textures:
            try:
                pixels = np.ascontiguousarray(np.asarray(image.convert("RGBA"), np.uint8))
            except Exception as e:  # a texture trimesh found but PIL cannot decode
                raise SceneError(f"{self.source}: texture of {name!r} cannot be decoded "
                                 f"({type(e).__name__}: {e})") from None
            self.keep.append(image)
            self.textures[key] = len(self.scene.textures)
            tname = getattr(image, "filename", None) or f"{name} texture"
            self.scene.textures.append(Texture(name=Path(str(tname)).name, pixels=pixels,
                                               srgb=srgb))
        return self.textures[key]
