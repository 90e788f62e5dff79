"""Write the glTF agreement scene, ``tests/data/agreement/still_life.gltf`` (with its
``.bin`` and ``checker.png``), which rfw's path tracer and Mitsuba 3 render alike.

    python scripts/make_still_life.py [--out tests/data/agreement]

A textured floor, a gold sphere and one box mesh placed twice (a tall box, and a small one
that is the child of a turned node, mirrored by a negative scale), lit by a
KHR_lights_punctual point light and a directional one, seen by a perspective camera. Every
material is one of the two that both renderers share exactly (``rfw.truth.mitsuba``): pure
Lambert (KHR_materials_specular's ``specularFactor`` 0) or a metal (``metallicFactor`` 1).
The floor's base colour is an 8x8 sRGB texture sampled nearest and repeated twice across
it: a checker whose light squares fade in red along u and dark squares in green along v,
so a texture read flipped or turned does not match. Computed, never random: every run
writes the same bytes.
"""

from __future__ import annotations

import argparse
import io
import json
import math
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
NEAREST, LINEAR_MIPMAP_LINEAR, REPEAT = 9728, 9987, 10497
FLOAT, UINT16 = 5126, 5123
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def checker() -> np.ndarray:
    """(8, 8, 4) uint8 sRGB: light squares fade in red along u (columns), dark ones in
    green along v (rows)."""
    i, j = np.meshgrid(np.arange(8), np.arange(8), indexing="ij")
    light = np.stack([255 - 20 * j, 0 * j + 215, 0 * j + 170], -1)
    dark = np.stack([0 * i + 40, 50 + 20 * i, 0 * i + 110], -1)
    rgb = np.where(((i + j) % 2 == 0)[..., None], light, dark)
    return np.concatenate([rgb, np.full((8, 8, 1), 255)], -1).astype(np.uint8)


def floor() -> tuple[np.ndarray, ...]:
    """A 6 m square at y = 0 facing up, uv 0..2 across it (the texture repeats twice)."""
    p = np.array([[-3, 0, 3], [3, 0, 3], [3, 0, -3], [-3, 0, -3]], np.float32)
    n = np.tile(np.array([0, 1, 0], np.float32), (4, 1))
    uv = np.array([[0, 2], [2, 2], [2, 0], [0, 0]], np.float32)
    return p, n, uv, np.array([0, 1, 2, 0, 2, 3], np.uint16)


def cube() -> tuple[np.ndarray, ...]:
    """The unit cube about the origin, flat faces wound counter-clockwise seen from outside."""
    p, n, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            u, v = np.zeros(3), np.zeros(3)
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 1.0, 1.0
            if sign < 0:
                u, v = v, u  # keep u x v along the outward normal
            base = len(p)
            for s, t in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p.append(0.5 * normal + (s - 0.5) * u + (t - 0.5) * v)
                n.append(normal)
                uv.append((s, 1 - t))
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return (np.array(p, np.float32), np.array(n, np.float32), np.array(uv, np.float32),
            np.array(idx, np.uint16))


def sphere(radius: float, segments: int = 40, rings: int = 20) -> tuple[np.ndarray, ...]:
    """A UV sphere about the origin with its analytic normals, wound outward; the poles'
    zero-area triangles are left out."""
    theta, phi = np.meshgrid(np.linspace(0.0, math.pi, rings + 1),
                             np.linspace(0.0, 2 * math.pi, segments + 1), indexing="ij")
    n = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)],
                 -1).reshape(-1, 3)
    uv = np.stack([phi / (2 * math.pi), theta / math.pi], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(segments), np.arange(rings))
    a = (j * (segments + 1) + i).ravel()
    b, c, d = a + 1, a + segments + 2, a + segments + 1
    ring = j.ravel()
    # from +Y down: a and b on one ring, d and c below; a, d, c is counter-clockwise outside
    tri = np.concatenate([np.stack([a, d, c], 1)[ring < rings - 1],
                          np.stack([a, c, b], 1)[ring > 0]])
    return (np.float32(radius) * n.astype(np.float32), n.astype(np.float32),
            uv.astype(np.float32), tri.astype(np.uint16).ravel())


def look_rotation(forward, up=(0.0, 1.0, 0.0)) -> list[float]:
    """The unit quaternion (x, y, z, w) that turns -Z onto ``forward`` with +Y toward
    ``up``: how a glTF camera or light node is aimed."""
    f = np.asarray(forward, np.float64)
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.stack([s, u, -f], 1)  # columns: the node's +X, +Y, +Z in the world
    w = math.sqrt(max(0.0, 1.0 + np.trace(m))) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
    return [round(float(c), 7) for c in (x, y, z, w)]


def yaw(degrees: float) -> list[float]:
    """The quaternion of a turn about +Y."""
    h = math.radians(degrees) / 2
    return [0.0, round(math.sin(h), 7), 0.0, round(math.cos(h), 7)]


class Buffer:
    """One binary buffer: each array a 4-byte aligned bufferView and its accessor."""

    def __init__(self):
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, a: np.ndarray, kind: str, target: int) -> int:
        while len(self.data) % 4:
            self.data += b"\0"
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes,
                           "target": target})
        self.data += a.tobytes()
        acc = {"bufferView": len(self.views) - 1, "count": len(a), "type": kind,
               "componentType": UINT16 if a.dtype == np.uint16 else FLOAT}
        if kind == "VEC3" and target == ARRAY_BUFFER:
            acc["min"] = [float(v) for v in a.min(0)]
            acc["max"] = [float(v) for v in a.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def primitive(self, p, n, uv, idx, material: int) -> dict:
        return {"attributes": {"POSITION": self.add(p, "VEC3", ARRAY_BUFFER),
                               "NORMAL": self.add(n, "VEC3", ARRAY_BUFFER),
                               "TEXCOORD_0": self.add(uv, "VEC2", ARRAY_BUFFER)},
                "indices": self.add(idx, "SCALAR", ELEMENT_ARRAY_BUFFER), "material": material}


def lambert(name: str, rgb, texture: int | None = None) -> dict:
    pbr = {"baseColorFactor": [*rgb, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}
    if texture is not None:
        pbr["baseColorTexture"] = {"index": texture}
    return {"name": name, "pbrMetallicRoughness": pbr,
            "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}}


def document(buf: Buffer) -> dict:
    materials = [
        lambert("floor", [0.9, 0.9, 0.9], texture=0),
        lambert("teal", [0.12, 0.42, 0.45]),
        {"name": "gold", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.78, 0.34, 1.0],
                                                  "metallicFactor": 1.0,
                                                  "roughnessFactor": 0.35}},
    ]
    meshes = [{"name": "floor", "primitives": [buf.primitive(*floor(), 0)]},
              {"name": "box", "primitives": [buf.primitive(*cube(), 1)]},
              {"name": "sphere", "primitives": [buf.primitive(*sphere(0.5), 2)]}]
    sun = [-0.45, -0.8, -0.4]
    nodes = [
        {"name": "floor", "mesh": 0},
        {"name": "tall box", "mesh": 1, "translation": [-0.85, 0.6, -0.55], "rotation": yaw(25.0),
         "scale": [0.5, 1.2, 0.5]},
        {"name": "tray", "translation": [-0.25, 0.0, 0.95], "rotation": yaw(-30.0),
         "children": [4]},
        {"name": "gold sphere", "mesh": 2, "translation": [0.65, 0.5, 0.05]},
        # mirrored: the winding of its triangles flips in the world
        {"name": "small box", "mesh": 1, "translation": [0.0, 0.2, 0.0],
         "scale": [-0.4, 0.4, 0.4]},
        {"name": "lamp", "translation": [1.3, 2.2, 1.6],
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "sun", "rotation": look_rotation(sun),
         "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"name": "camera", "camera": 0, "translation": [0.35, 1.7, 4.0],
         "rotation": look_rotation(np.subtract([0.0, 0.45, 0.0], [0.35, 1.7, 4.0]))},
    ]
    return {
        "asset": {"version": "2.0", "generator": "rfw scripts/make_still_life.py"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_specular"],
        "scene": 0, "scenes": [{"name": "still life", "nodes": [0, 1, 2, 3, 5, 6, 7]}],
        "nodes": nodes, "meshes": meshes, "materials": materials,
        "textures": [{"name": "checker", "source": 0, "sampler": 0}],
        "images": [{"name": "checker", "uri": "checker.png", "mimeType": "image/png"}],
        "samplers": [{"magFilter": NEAREST, "minFilter": LINEAR_MIPMAP_LINEAR, "wrapS": REPEAT,
                      "wrapT": REPEAT}],
        "cameras": [{"name": "front", "type": "perspective",
                     "perspective": {"yfov": round(math.radians(45.0), 7), "znear": 0.05,
                                     "zfar": 50.0, "aspectRatio": 1.0}}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"name": "lamp", "type": "point", "color": [1.0, 0.9, 0.75], "intensity": 6.0},
            {"name": "sun", "type": "directional", "color": [0.9, 0.95, 1.0],
             "intensity": 1.5}]}},
        "buffers": [{"uri": "still_life.bin", "byteLength": len(buf.data)}],
        "bufferViews": buf.views, "accessors": buf.accessors,
    }


def write(out: Path) -> list[Path]:
    """Write the three files into ``out``; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    buf = Buffer()
    doc = document(buf)
    png = io.BytesIO()
    Image.fromarray(checker(), "RGBA").save(png, format="PNG", optimize=False)
    files = {"still_life.gltf": (json.dumps(doc, indent=1) + "\n").encode(),
             "still_life.bin": bytes(buf.data), "checker.png": png.getvalue()}
    for name, data in files.items():
        (out / name).write_bytes(data)
    return [out / name for name in files]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "agreement")
    args = ap.parse_args(argv)
    for path in write(args.out):
        print(f"wrote {path} ({path.stat().st_size:,} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
