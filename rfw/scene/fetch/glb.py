"""Writing GLB: an rfw ``Scene`` as one binary glTF, a ``.gltf`` packed into one GLB, and the
check that a GLB read back matches its source."""

from __future__ import annotations

import hashlib
import io
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ..gltf import read_uri, split_glb
from ..model import Scene, SceneError
from ..util import normalize

GENERATOR = "rfw scenes fetch"


_MAG = {"nearest": 9728, "linear": 9729}
_MIN = {("nearest", "nearest"): 9984, ("linear", "nearest"): 9985,
        ("nearest", "linear"): 9986, ("linear", "linear"): 9987}
_WRAP = {"repeat": 10497, "clamp-to-edge": 33071, "mirror-repeat": 33648}


def _pad(data: bytearray, align: int, fill: bytes = b"\0") -> None:
    data += fill * (-len(data) % align)


def glb_bytes(doc: dict[str, Any], blob: bytes | bytearray) -> bytes:
    """A GLB container around a glTF JSON document and its binary chunk."""
    text = bytearray(json.dumps(doc, separators=(",", ":"), allow_nan=False).encode())
    _pad(text, 4, b" ")
    chunks = struct.pack("<I4s", len(text), b"JSON") + bytes(text)
    if blob:
        body = bytearray(blob)
        _pad(body, 4)
        chunks += struct.pack("<I4s", len(body), b"BIN\0") + bytes(body)
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def _frame(position: np.ndarray, forward: np.ndarray, up: np.ndarray) -> np.ndarray:
    """A node matrix whose local -Z is ``forward`` and +Y leans to ``up``."""
    z = -normalize(np.asarray(forward, np.float64)[None])[0]
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross([1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 0.0, 1.0], z)
    x = normalize(x[None])[0]
    y = np.cross(z, x)
    m = np.identity(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, position
    return m


def _matrix(m: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(m, np.float64).T.ravel()]  # column-major


def scene_to_glb(scene: Scene, *, copyright: str | None = None) -> bytes:
    """Write an rfw ``Scene`` as one GLB.

    Each mesh becomes a glTF mesh of one primitive (POSITION with bounds, NORMAL, TEXCOORD_0
    when it has UVs or a textured material, TANGENT when its material has a normal map,
    16- or 32-bit indices), each instance a node with its matrix, each material a
    metallic-roughness material (emissive above 1 through KHR_materials_emissive_strength),
    each distinct image a PNG inside the binary chunk; cameras and KHR_lights_punctual
    lights become nodes too. ``load_gltf`` reads the result back to the same ``Scene``.
    """
    blob = bytearray()
    views: list[dict] = []
    accessors: list[dict] = []
    used: set[str] = set()

    def view(data: bytes, target: int | None = None) -> int:
        _pad(blob, 4)
        v = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        blob.extend(data)
        views.append(v)
        return len(views) - 1

    def accessor(array: np.ndarray, ctype: int, kind: str, target: int,
                 bounds: bool = False) -> int:
        a = np.ascontiguousarray(array)
        acc = {"bufferView": view(a.tobytes(), target), "componentType": ctype,
               "count": len(a), "type": kind}
        if bounds:
            acc["min"] = [float(v) for v in a.min(axis=0)]
            acc["max"] = [float(v) for v in a.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    images: list[dict] = []
    image_index: dict[bytes, int] = {}
    samplers: list[dict] = []
    textures: list[dict] = []
    texture_index: dict[int, int] = {}

    def texture(index: int | None) -> dict | None:
        if index is None:
            return None
        if index not in texture_index:
            tex = scene.textures[index]
            px = np.ascontiguousarray(tex.pixels, np.uint8)
            key = hashlib.sha256(px.tobytes() + str(px.shape).encode()).digest()
            if key not in image_index:
                image_index[key] = len(images)
                images.append({"bufferView": view(_png(px)), "mimeType": "image/png",
                               "name": tex.name})
            sampler = {"magFilter": _MAG[tex.mag_filter],
                       "minFilter": _MIN[(tex.min_filter, tex.mipmap_filter)],
                       "wrapS": _WRAP[tex.address_u], "wrapT": _WRAP[tex.address_v]}
            if sampler not in samplers:
                samplers.append(sampler)
            texture_index[index] = len(textures)
            textures.append({"source": image_index[key], "sampler": samplers.index(sampler),
                             "name": tex.name})
        return {"index": texture_index[index]}

    materials = []
    for m in scene.materials:
        pbr: dict[str, Any] = {"baseColorFactor": [float(c) for c in m.base_color],
                               "metallicFactor": float(m.metallic),
                               "roughnessFactor": float(m.roughness)}
        out: dict[str, Any] = {"name": m.name, "pbrMetallicRoughness": pbr}
        if (t := texture(m.base_color_texture)) is not None:
            pbr["baseColorTexture"] = t
        if (t := texture(m.metallic_roughness_texture)) is not None:
            pbr["metallicRoughnessTexture"] = t
        if (t := texture(m.normal_texture)) is not None:
            out["normalTexture"] = {**t, "scale": float(m.normal_scale)}
        if (t := texture(m.occlusion_texture)) is not None:
            out["occlusionTexture"] = {**t, "strength": float(m.occlusion_strength)}
        if (t := texture(m.emissive_texture)) is not None:
            out["emissiveTexture"] = t
        emissive = [float(c) for c in m.emissive]
        if any(emissive):
            peak = max(emissive)
            if peak > 1.0:
                out["extensions"] = {"KHR_materials_emissive_strength":
                                     {"emissiveStrength": peak}}
                used.add("KHR_materials_emissive_strength")
                emissive = [c / peak for c in emissive]
            out["emissiveFactor"] = emissive
        if m.alpha_mode != "OPAQUE":
            out["alphaMode"] = m.alpha_mode
        if m.alpha_mode == "MASK":
            out["alphaCutoff"] = float(m.alpha_cutoff)
        if m.double_sided:
            out["doubleSided"] = True
        materials.append(out)

    meshes = []
    for mesh in scene.meshes:
        mat = scene.materials[mesh.material]
        textured = any(i is not None for i in (
            mat.base_color_texture, mat.metallic_roughness_texture, mat.normal_texture,
            mat.occlusion_texture, mat.emissive_texture))
        attrs = {"POSITION": accessor(mesh.positions.astype(np.float32), 5126, "VEC3", 34962,
                                      bounds=True),
                 "NORMAL": accessor(mesh.normals.astype(np.float32), 5126, "VEC3", 34962)}
        if textured or np.any(mesh.uvs):
            attrs["TEXCOORD_0"] = accessor(mesh.uvs.astype(np.float32), 5126, "VEC2", 34962)
        if mat.normal_texture is not None:
            attrs["TANGENT"] = accessor(mesh.tangents.astype(np.float32), 5126, "VEC4", 34962)
        small = len(mesh.positions) <= 65535
        idx = mesh.indices.astype(np.uint16 if small else np.uint32)
        prim = {"attributes": attrs,
                "indices": accessor(idx, 5123 if small else 5125, "SCALAR", 34963),
                "material": mesh.material, "mode": 4}
        meshes.append({"name": mesh.name, "primitives": [prim]})

    nodes: list[dict] = []
    for inst in scene.instances:
        node: dict[str, Any] = {"mesh": inst.mesh}
        if inst.name:
            node["name"] = inst.name
        if not np.allclose(inst.transform, np.identity(4), rtol=0, atol=0):
            node["matrix"] = _matrix(inst.transform)
        nodes.append(node)
    cameras = []
    for cam in scene.cameras:
        cameras.append({"type": "perspective", "name": cam.name or f"camera {len(cameras)}",
                        "perspective": {"yfov": float(cam.yfov), "znear": float(cam.znear),
                                        "zfar": float(cam.zfar)}})
        world = np.linalg.inv(cam.view().astype(np.float64))
        nodes.append({"camera": len(cameras) - 1, "matrix": _matrix(world)})
    lights = []
    for li in scene.lights:
        light: dict[str, Any] = {"type": li.kind, "color": [float(c) for c in li.color],
                                 "intensity": float(li.intensity)}
        if li.name:
            light["name"] = li.name
        if li.range is not None:
            light["range"] = float(li.range)
        if li.kind == "spot":
            light["spot"] = {"innerConeAngle": float(li.inner_cone),
                             "outerConeAngle": float(li.outer_cone)}
        lights.append(light)
        world = _frame(np.asarray(li.position, np.float64), np.asarray(li.direction),
                       np.array([0.0, 1.0, 0.0]))
        nodes.append({"matrix": _matrix(world),
                      "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
    asset: dict[str, Any] = {"version": "2.0", "generator": GENERATOR}
    if copyright:
        asset["copyright"] = copyright
    doc: dict[str, Any] = {"asset": asset, "scene": 0,
                           "scenes": [{"name": scene.name, "nodes": list(range(len(nodes)))}],
                           "nodes": nodes, "meshes": meshes, "materials": materials,
                           "accessors": accessors, "bufferViews": views}
    if textures:
        doc.update(textures=textures, images=images, samplers=samplers)
    if cameras:
        doc["cameras"] = cameras
    if lights:
        doc["extensions"] = {"KHR_lights_punctual": {"lights": lights}}
        used.add("KHR_lights_punctual")
    if used:
        doc["extensionsUsed"] = sorted(used)
    _pad(blob, 4)
    doc["buffers"] = [{"byteLength": len(blob)}]
    return glb_bytes(doc, blob)


def _png(pixels: np.ndarray) -> bytes:
    from PIL import Image

    img = Image.fromarray(pixels, "RGBA")
    if bool(np.all(pixels[..., 3] == 255)):
        img = img.convert("RGB")
    out = io.BytesIO()
    img.save(out, format="PNG")
    return out.getvalue()


def _mime(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    raise SceneError("an image is neither PNG, JPEG nor WebP")


def pack_gltf(path: Path) -> bytes:
    """A ``.gltf`` (external or data-URI buffers and images) as one self-contained GLB.

    The JSON is kept as it is, extensions and extras included; only ``buffers`` becomes
    the one binary chunk and images with a ``uri`` point at buffer views. A ``.glb`` that
    references nothing outside itself is returned unchanged.
    """
    data = path.read_bytes()
    if data[:4] == b"glTF":
        text, _ = split_glb(data, path)
        doc = json.loads(text.decode("utf-8-sig"))
        external = [b for b in doc.get("buffers", []) + doc.get("images", []) if "uri" in b]
        if external:
            raise SceneError(f"{path}: a GLB with external references is not packed")
        return data
    doc = json.loads(data.decode("utf-8-sig"))
    blob = bytearray()
    offsets = []
    for i, buf in enumerate(doc.get("buffers", [])):
        if "uri" not in buf:
            raise SceneError(f"{path}: buffers[{i}] has no uri")
        raw = read_uri(path, buf["uri"], f"buffers[{i}]")  # only the scene's folder
        length = int(buf["byteLength"])
        if len(raw) < length:
            raise SceneError(f"{path}: buffers[{i}] is shorter than its byteLength")
        _pad(blob, 8)
        offsets.append(len(blob))
        blob.extend(raw[:length])
    for bv in doc.get("bufferViews", []):
        bv["byteOffset"] = int(bv.get("byteOffset", 0)) + offsets[bv["buffer"]]
        bv["buffer"] = 0
    for i, img in enumerate(doc.get("images", [])):
        if "uri" not in img:
            continue
        raw = read_uri(path, img["uri"], f"images[{i}]")
        _pad(blob, 8)
        doc.setdefault("bufferViews", []).append(
            {"buffer": 0, "byteOffset": len(blob), "byteLength": len(raw)})
        blob.extend(raw)
        img["bufferView"] = len(doc["bufferViews"]) - 1
        img["mimeType"] = img.get("mimeType") or _mime(raw)
        if "name" not in img:
            img["name"] = img["uri"] if not img["uri"].startswith("data:") else f"images[{i}]"
        del img["uri"]
    _pad(blob, 4)
    if blob:
        doc["buffers"] = [{"byteLength": len(blob)}]
    else:
        doc.pop("buffers", None)
    return glb_bytes(doc, blob)


# ---------------------------------------------------------------------------------------------
# checking a GLB against its source


def compare_scenes(ref: Scene, out: Scene) -> list[str]:
    """What differs between a source scene and the scene read back from its GLB."""
    problems = []
    for what, a, b in (("triangles", ref.triangle_count, out.triangle_count),
                       ("instances", len(ref.instances), len(out.instances))):
        if a != b:
            problems.append(f"{what}: {a} in the source, {b} in the GLB")
    if problems:
        return problems
    seen_mesh: set[tuple[int, int]] = set()
    seen_mat: set[tuple[int, int]] = set()
    for k, (ia, ib) in enumerate(zip(ref.instances, out.instances, strict=True)):
        if not np.allclose(ia.transform, ib.transform, rtol=1e-6, atol=1e-5):
            problems.append(f"instance {k} ({ia.name}): transform differs")
        if (ia.mesh, ib.mesh) in seen_mesh:
            continue
        seen_mesh.add((ia.mesh, ib.mesh))
        ma, mb = ref.meshes[ia.mesh], out.meshes[ib.mesh]
        where = f"mesh {ma.name!r}"
        if ma.positions.shape != mb.positions.shape or not np.array_equal(ma.indices,
                                                                           mb.indices):
            problems.append(f"{where}: vertices or indices differ")
            continue
        if not np.allclose(ma.positions, mb.positions, rtol=1e-6, atol=1e-6):
            problems.append(f"{where}: positions differ")
        if not np.allclose(ma.normals, mb.normals, atol=1e-4):
            problems.append(f"{where}: normals differ")
        if not np.allclose(ma.uvs, mb.uvs, atol=1e-6):
            problems.append(f"{where}: uvs differ")
        if (ma.material, mb.material) not in seen_mat:
            seen_mat.add((ma.material, mb.material))
            problems += _compare_materials(ref, out, ma.material, mb.material)
    return problems[:10]


def _compare_materials(ref: Scene, out: Scene, a: int, b: int) -> list[str]:
    ma, mb = ref.materials[a], out.materials[b]
    where = f"material {ma.name!r}"
    problems = []
    for f in ("base_color", "metallic", "roughness", "emissive", "normal_scale",
              "occlusion_strength", "alpha_cutoff"):
        if not np.allclose(getattr(ma, f), getattr(mb, f), atol=1e-6):
            problems.append(f"{where}: {f} {getattr(ma, f)} became {getattr(mb, f)}")
    for f in ("alpha_mode", "double_sided"):
        if getattr(ma, f) != getattr(mb, f):
            problems.append(f"{where}: {f} {getattr(ma, f)} became {getattr(mb, f)}")
    for f in ("base_color_texture", "metallic_roughness_texture", "normal_texture",
              "occlusion_texture", "emissive_texture"):
        ta, tb = getattr(ma, f), getattr(mb, f)
        if (ta is None) != (tb is None):
            problems.append(f"{where}: {f} {'lost' if tb is None else 'appeared'}")
        elif ta is not None:
            xa, xb = ref.textures[ta], out.textures[tb]
            if not np.array_equal(xa.pixels, xb.pixels):
                problems.append(f"{where}: {f} pixels differ")
            for s in ("srgb", "mag_filter", "min_filter", "mipmap_filter", "address_u",
                      "address_v"):
                if getattr(xa, s) != getattr(xb, s):
                    problems.append(f"{where}: {f} {s} differs")
    return problems
