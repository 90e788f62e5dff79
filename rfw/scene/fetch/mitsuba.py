"""Mitsuba 2/3 XML scenes (PLY and OBJ shapes) as an rfw ``Scene``, Z up turned to Y up."""

from __future__ import annotations

import contextlib
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..model import Instance, Material, Mesh, Scene, SceneError
from ..util import compute_normals, compute_tangents, normalize, srgb_to_linear

# Mitsuba (Z up) to glTF (Y up): (x, y, z) -> (x, z, -y)
Z_UP_TO_Y_UP = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])

# sRGB display colours for Sionna's ITU radio materials; others get one from a palette
ITU_COLORS = {
    "marble": (0.80, 0.78, 0.72), "concrete": (0.55, 0.55, 0.53), "brick": (0.62, 0.30, 0.22),
    "wood": (0.52, 0.36, 0.22), "metal": (0.42, 0.45, 0.50), "glass": (0.55, 0.68, 0.74),
    "plasterboard": (0.86, 0.85, 0.80), "ceiling_board": (0.88, 0.88, 0.86),
    "chipboard": (0.70, 0.58, 0.42), "floorboard": (0.60, 0.45, 0.30),
    "very_dry_ground": (0.60, 0.52, 0.40), "medium_dry_ground": (0.50, 0.44, 0.33),
    "wet_ground": (0.36, 0.32, 0.25),
}
PALETTE = [(0.80, 0.45, 0.35), (0.40, 0.60, 0.75), (0.55, 0.70, 0.40), (0.85, 0.75, 0.45),
           (0.65, 0.50, 0.75), (0.45, 0.70, 0.65)]


def _floats(text: str | None, n: int, where: str) -> list[float]:
    values = [float(v) for v in re.split(r"[,\s]+", (text or "").strip()) if v]
    if len(values) == 1 and n > 1:
        values *= n
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise SceneError(f"{where}: expected {n} numbers, got {text!r}")
    return values


def _xyz(el: Any, where: str, default: float) -> list[float]:
    if el.get("value") is not None:
        return _floats(el.get("value"), 3, where)
    return [float(el.get(k, default)) for k in "xyz"]


def _transform(el: Any, where: str) -> np.ndarray:
    """A Mitsuba ``<transform>``: each operation applies after the ones before it."""
    m = np.identity(4)
    for op in el:
        t = np.identity(4)
        tag = op.tag
        if tag == "matrix":
            t = np.array(_floats(op.get("value"), 16, f"{where} <matrix>")).reshape(4, 4)
        elif tag == "translate":
            t[:3, 3] = _xyz(op, f"{where} <translate>", 0.0)
        elif tag == "scale":
            t[[0, 1, 2], [0, 1, 2]] = _xyz(op, f"{where} <scale>", 1.0)
        elif tag == "rotate":
            axis = normalize(np.array([_xyz(op, f"{where} <rotate>", 0.0)]))[0]
            a = math.radians(float(op.get("angle", 0.0)))
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]],
                          [-axis[1], axis[0], 0]])
            t[:3, :3] = np.identity(3) + math.sin(a) * k + (1 - math.cos(a)) * (k @ k)
        elif tag == "lookat":
            eye = np.array(_floats(op.get("origin"), 3, f"{where} <lookat>"))
            target = np.array(_floats(op.get("target"), 3, f"{where} <lookat>"))
            up = np.array(_floats(op.get("up", "0 1 0"), 3, f"{where} <lookat>"))
            d = normalize((target - eye)[None])[0]
            left = normalize(np.cross(up, d)[None])[0]
            t[:3, 0], t[:3, 1], t[:3, 2], t[:3, 3] = left, np.cross(d, left), d, eye
        else:
            raise SceneError(f"{where}: transform operation <{tag}> is not supported")
        m = t @ m
    return m


def _bsdf_color(bsdf: Any, index: int) -> tuple[float, float, float]:
    for el in bsdf.iter():
        if el.tag in ("rgb", "spectrum") and el.get("name") in ("reflectance", "color",
                                                                 "base_color"):
            with contextlib.suppress(SceneError, ValueError):
                rgb = _floats(el.get("value"), 3, "rgb")
                return tuple(min(max(c, 0.0), 1.0) for c in rgb)  # type: ignore[return-value]
    for el in bsdf.iter("string"):
        if el.get("name") == "type" and el.get("value") in ITU_COLORS:
            return ITU_COLORS[el.get("value")]
    return PALETTE[index % len(PALETTE)]


def load_mitsuba(path: Path) -> Scene:
    """A Mitsuba 2/3 XML scene of PLY or OBJ shapes as an rfw ``Scene`` (Y up).

    Shapes: ``ply`` and ``obj`` (through trimesh), with ``to_world`` transforms,
    ``face_normals`` (flat shading: vertices are split per triangle) and ``flip_normals``.
    Materials: one per BSDF id (shapes sharing a BSDF share it); the colour is the BSDF's
    reflectance if it has one, else a fixed colour per ITU radio material type (Sionna),
    else one from a palette. Everything is double-sided, as Mitsuba shapes are.
    """
    import xml.etree.ElementTree as ET

    import trimesh

    source = str(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise SceneError(f"{source}: cannot read the XML: {e}") from None
    if root.tag != "scene":
        raise SceneError(f"{source}: the root element is <{root.tag}>, not <scene>")
    folder = path.absolute().parent.resolve()
    scene = Scene(name=path.stem, materials=[], source=source)
    by_id: dict[str, int] = {}

    def material(bsdf: Any, key: str) -> int:
        if key not in by_id:
            inner = bsdf
            while inner.get("type") in ("twosided", "mask", "bumpmap") and \
                    inner.find("bsdf") is not None:
                inner = inner.find("bsdf")
            color = _bsdf_color(inner, len(by_id))
            base = (*map(float, srgb_to_linear(np.array(color))), 1.0)
            kind = next((el.get("value") for el in inner.iter("string")
                         if el.get("name") == "type"), None)
            metal = kind == "metal" or inner.get("type") == "conductor"
            by_id[key] = len(scene.materials)
            scene.materials.append(Material(name=key, base_color=base,
                                            metallic=0.5 if metal else 0.0,
                                            roughness=0.45 if metal else 0.9,
                                            double_sided=True))
        return by_id[key]

    bsdfs = {el.get("id"): el for el in root.findall("bsdf") if el.get("id")}
    default = None
    for k, shape in enumerate(root.findall("shape")):
        sid = shape.get("id") or f"shape {k}"
        where = f"{source}: shape {sid!r}"
        kind = shape.get("type")
        if kind not in ("ply", "obj"):
            raise SceneError(f"{where}: type {kind!r} is not supported (ply and obj are)")
        strings = {el.get("name"): el.get("value") for el in shape.findall("string")}
        bools = {el.get("name"): (el.get("value") or "").lower() == "true"
                 for el in shape.findall("boolean")}
        rel = strings.get("filename")
        if not rel:
            raise SceneError(f"{where}: no filename")
        file = (folder / rel).resolve()
        if not file.is_relative_to(folder):
            raise SceneError(f"{where}: {rel} lies outside the scene's folder")
        if not file.is_file():
            raise SceneError(f"{where}: {rel} not found")
        try:
            geom = trimesh.load(file, file_type=kind, process=False, force="mesh")
        except Exception as e:  # trimesh's parsers raise anything
            raise SceneError(f"{where}: cannot read {rel} ({type(e).__name__}: {e})") from None
        faces = np.asarray(getattr(geom, "faces", np.zeros((0, 3))), np.int64)
        if len(faces) == 0:
            raise SceneError(f"{where}: {rel} holds no triangles")
        positions = np.asarray(geom.vertices, np.float64)
        if faces.min() < 0 or faces.max() >= len(positions) or \
                not np.all(np.isfinite(positions)):
            raise SceneError(f"{where}: {rel} has out-of-range indices or non-finite positions")
        if bools.get("flip_normals"):
            faces = faces[:, ::-1]
        if bools.get("face_normals"):
            positions = positions[faces.ravel()]
            faces = np.arange(len(positions)).reshape(-1, 3)
        indices = faces.ravel()
        normals = compute_normals(positions, indices).astype(np.float64)
        ref = shape.find("ref")
        inline = shape.find("bsdf")
        if inline is not None:
            mat = material(inline, inline.get("id") or f"{sid} bsdf")
        elif ref is not None:
            if ref.get("id") not in bsdfs:
                raise SceneError(f"{where}: refers to bsdf {ref.get('id')!r}, which the scene "
                                 "does not define")
            mat = material(bsdfs[ref.get("id")], ref.get("id"))
        else:
            if default is None:
                default = len(scene.materials)
                scene.materials.append(Material(name="default", base_color=(0.5, 0.5, 0.5, 1.0),
                                                roughness=0.9, double_sided=True))
            mat = default
        to_world = np.identity(4)
        for el in shape.findall("transform"):
            if el.get("name") == "to_world":
                to_world = _transform(el, where)
        scene.meshes.append(Mesh(
            name=sid.removeprefix("mesh-"),
            positions=np.ascontiguousarray(positions, np.float32),
            normals=np.ascontiguousarray(normals, np.float32),
            uvs=np.zeros((len(positions), 2), np.float32),
            tangents=compute_tangents(positions, normals, None, indices),
            indices=np.ascontiguousarray(indices, np.uint32),
            material=mat))
        scene.instances.append(Instance(len(scene.meshes) - 1,
                                        np.ascontiguousarray(Z_UP_TO_Y_UP @ to_world,
                                                             np.float32),
                                        sid.removeprefix("mesh-")))
    if not scene.instances:
        raise SceneError(f"{source}: no shapes")
    return scene
