"""glTF 2.0 (.gltf with external or embedded data, and .glb) to a ``Scene``.

The JSON is decoded into pygltflib's document classes, every value type-checked; every
index, offset, length and stride is validated before a read, so a malformed file raises a
``SceneError`` naming the file and the element ("scene.gltf: accessors[3] (POSITION of
meshes[0].primitives[1]): needs 4800 bytes, bufferViews[2] has 1200") rather than an
IndexError or a read past a buffer. External files are only read from the scene's folder.

What is read: the node hierarchy (TRS or matrix), the chosen scene, every triangle primitive
(strips and fans become lists), indexed or not, any accessor component type (normalised or
not, strided, sparse), POSITION / NORMAL / TANGENT / TEXCOORD_0, metallic-roughness
materials with their five textures and samplers, perspective cameras and
KHR_lights_punctual. Normals and tangents are computed where the file has none.

Not read: skins and morph targets (meshes appear in their bind pose), animations,
TEXCOORD_1 (textures using it are sampled with TEXCOORD_0 and a warning is issued), vertex
colours. Orthographic cameras are approximated by a narrow perspective camera (warning).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import math
import re
import struct
import urllib.parse
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path, PureWindowsPath
from typing import Any, NoReturn

import numpy as np
import pygltflib

from ..errors import warn as warn_once
from . import limits
from .gltf_json import ShapeError, decode_json, reject_constant
from .model import (
    WORLD_LIMIT,
    Camera,
    Instance,
    Light,
    Material,
    Mesh,
    Scene,
    SceneError,
    Texture,
)
from .util import compute_normals, compute_tangents, normalize

# extensions whose absence would change the result, but which this loader implements
SUPPORTED_EXTENSIONS = frozenset({
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_mesh_quantization",  # integer positions / normals: any component type is read
    "EXT_texture_webp",  # Pillow decodes WebP
    "KHR_texture_transform",  # applied to the primitive's texture coordinates
    "KHR_draco_mesh_compression",  # decoded by DracoPy
})


class SceneWarning(UserWarning):
    """Something in a scene file that is not drawn as the file means it (a skin, a point
    primitive). Each is also one ``rfw: warning:`` line on stderr; as a Python warning it is
    ignored unless a caller asks for it (``warnings.catch_warnings``, ``pytest.warns``), so
    the line is not said twice."""


warnings.filterwarnings("ignore", category=SceneWarning)

# componentType -> (numpy dtype, bytes)
_COMPONENTS = {
    5120: ("i1", 1), 5121: ("u1", 1), 5122: ("<i2", 2), 5123: ("<u2", 2), 5125: ("<u4", 4),
    5126: ("<f4", 4),
}
_COMPONENT_NAMES = {5120: "BYTE", 5121: "UNSIGNED_BYTE", 5122: "SHORT", 5123: "UNSIGNED_SHORT",
                    5125: "UNSIGNED_INT", 5126: "FLOAT"}
# normalised integers: value / max, signed ones clamped at -1 (glTF 2.0 section 3.11)
_NORMALIZE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_TYPES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_INDEX_COMPONENTS = (5121, 5123, 5125)
_MODES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP", 4: "TRIANGLES",
          5: "TRIANGLE_STRIP", 6: "TRIANGLE_FAN"}

# samplers in WebGPU terms; the model cannot say "no mipmaps", so the non-mipmapped glTF
# minification filters pick nearest mip selection, the closest to sampling one level
_MAG_FILTERS = {9728: "nearest", 9729: "linear"}
_MIN_FILTERS = {
    9728: ("nearest", "nearest"), 9729: ("linear", "nearest"),
    9984: ("nearest", "nearest"), 9985: ("linear", "nearest"),
    9986: ("nearest", "linear"), 9987: ("linear", "linear"),
}
_WRAPS = {33071: "clamp-to-edge", 33648: "mirror-repeat", 10497: "repeat"}

# what load() reads past, and how its warning says so
_UNREAD = {
    "stroke_textures": "textures of points and lines not read: drawn with the material's "
                       "base colour and emissive factors",
    "skins": "skins not read: skinned meshes are drawn unposed, by their nodes' transforms",
    "morphs": "morph targets not read: meshes are drawn with their base shape",
    "animations": "animations not read: the scene is drawn as the file poses it",
}

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = b"JSON"
_CHUNK_BIN = b"BIN\x00"
_URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
# accessors without a bufferView are allocated from ``count`` alone: cap what a file can ask
_MAX_UNBACKED = 1 << 26


def load_gltf(path: str | Path) -> Scene:
    """Load a ``.gltf`` or ``.glb`` file.

    Parameters
    ----------
    path : str or Path
        The file; external buffers and images are read relative to its folder and must lie
        inside it.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        For anything unreadable, malformed or unsupported, naming the file and the element.
    """
    return _Loader(Path(path)).load()


def split_glb(data: bytes, path: str | Path) -> tuple[bytes, bytes | None]:
    """The JSON and binary chunks of a GLB file, checked as ``load_gltf`` checks them.

    Parameters
    ----------
    data : bytes
        The whole file.
    path : str or Path
        The file, named in errors.

    Returns
    -------
    (bytes, bytes or None)
        The JSON chunk (not decoded), and the binary chunk, or None when there is none.

    Raises
    ------
    SceneError
        For a truncated or malformed container, naming the file.
    """
    loader = _Loader(Path(path))
    text = loader.split_glb(data)
    return bytes(text), None if loader.glb_bin is None else bytes(loader.glb_bin)


def read_uri(path: str | Path, uri: str, where: str) -> bytes:
    """The bytes a ``uri`` of the glTF file ``path`` names, by ``load_gltf``'s rules.

    Parameters
    ----------
    path : str or Path
        The glTF file; relative URIs are resolved against its folder.
    uri : str
        A ``data:`` URI, or a relative path that must resolve (symlinks followed) inside
        that folder; other schemes and absolute paths are refused.
    where : str
        The element that holds the URI (``"buffers[0]"``), named in errors.

    Raises
    ------
    SceneError
        For a refused, missing or unreadable URI, naming the file and ``where``.
    """
    return _Loader(Path(path)).read_uri(uri, where)


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _index(value: Any, items: list) -> bool:
    """Whether ``value`` is a valid index into ``items`` (booleans are not)."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < len(items)


def _finite32(a: Any) -> bool:
    """True when every value lies within the world renderers can hold in float32 (no NaN,
    no infinity, nothing beyond ``WORLD_LIMIT``)."""
    a = np.asarray(a, np.float64)
    return bool(np.all(np.isfinite(a)) and np.all(np.abs(a) <= WORLD_LIMIT))


# ---------------------------------------------------------------------------------------------


class _Loader:
    def __init__(self, path: Path):
        self.path = path
        self.source = str(path)
        self.folder = path.absolute().parent
        self.root = self.folder.resolve()
        self.glb_bin: memoryview | None = None
        self.buffers: dict[int, memoryview] = {}
        self.images: dict[int, np.ndarray] = {}
        # one decode per distinct image, however many images, textures or materials name it
        self.decoded: dict[bytes, np.ndarray] = {}
        self.texels = 0  # of the distinct images decoded so far (limits.MAX_TEXELS)
        self.textures: dict[tuple[int, bool], int | None] = {}
        self.materials: dict[int, int] = {}
        # (mesh, primitive) -> (a stroke?, its index in scene.strokes or scene.meshes)
        self.primitives: dict[tuple[int, int], tuple[bool, int]] = {}
        # what the file holds that is not drawn as it means, said in one line each after
        # build(): kind -> the elements (first few named)
        self.unread: dict[str, list[str]] = {k: [] for k in _UNREAD}
        self.tinted: dict[tuple[int, tuple[float, ...]], int] = {}
        # per scene material with textures: (TEXCOORD set, KHR_texture_transform 2x3 or None,
        # the file's material it comes from)
        self.uv_sets: dict[int, tuple[int, np.ndarray | None, str]] = {}
        self.texture_uses: list[tuple[str, int, np.ndarray | None]] = []
        self.default_material: int | None = None
        self.warned: set[str] = set()
        self.scene = Scene(name=path.stem, materials=[], source=self.source)

    # -- errors --------------------------------------------------------------------------

    def fail(self, where: str, message: str) -> NoReturn:
        raise SceneError(f"{self.source}: {where}: {message}".replace("\n", " "))

    def warn(self, message: str) -> None:
        if message not in self.warned:
            self.warned.add(message)
            line = f"{self.source}: {message}"
            warn_once(line)
            # as well, for callers that collect them (the fetch cache's notes)
            warnings.warn(line, SceneWarning, stacklevel=4)

    def skipped(self, where: str, message: str) -> None:
        """A valid but unusable element (a zero-scale node's camera): one warning line."""
        warn_once(f"{self.source}: {where}: {message}")

    @contextmanager
    def element(self, where: str) -> Iterator[None]:
        """Last line of defence: any unexpected error inside names the element."""
        try:
            yield
        except SceneError:
            raise
        except (ArithmeticError, AttributeError, LookupError, MemoryError, TypeError,
                ValueError, struct.error) as e:
            self.fail(where, f"malformed ({type(e).__name__}: {e})")

    def item(self, kind: str, index: Any, where: str) -> Any:
        items = getattr(self.doc, kind) or []
        if isinstance(index, bool) or not isinstance(index, int):
            self.fail(where, f"expected an index into {kind}, got {json.dumps(index)}")
        if not 0 <= index < len(items):
            self.fail(where, f"refers to {kind}[{index}], but the file has {len(items)} "
                             f"{kind}")
        return items[index]

    def integer(self, value: Any, where: str, name: str, *, default: int | None = None,
                minimum: int = 0) -> int:
        if value is None:
            if default is None:
                self.fail(where, f"{name} is required")
            return default
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            self.fail(where, f"{name} must be an integer >= {minimum}, got {json.dumps(value)}")
        return value

    def number(self, value: Any, where: str, name: str, default: float) -> float:
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value) or abs(value) > _FLOAT32_MAX:
            # renderers take every number as float32: larger ones would become infinity
            self.fail(where, f"{name} must be a finite number (float32), got "
                             f"{json.dumps(value)}")
        return float(value)

    def numbers(self, value: Any, n: int, where: str, name: str,
                default: tuple[float, ...]) -> tuple[float, ...]:
        if value is None:
            return default
        if not isinstance(value, list) or len(value) != n:
            self.fail(where, f"{name} must be {n} numbers, got {json.dumps(value)[:60]}")
        return tuple(self.number(v, where, name, 0.0) for v in value)

    # -- container ------------------------------------------------------------------------

    def load(self) -> Scene:
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            raise SceneError(f"{self.source}: file not found") from None
        except OSError as e:
            raise SceneError(f"{self.source}: cannot read: {e.strerror or e}") from None
        if data[:4] != _GLB_MAGIC and self.path.suffix.lower() == ".glb":
            # not read as JSON: a .glb that lacks the magic is some other file
            self.fail("GLB", f"not a GLB file: it starts with {data[:4]!r}, not b'glTF'")
        text = self.split_glb(data) if data[:4] == _GLB_MAGIC else data
        try:
            raw = json.loads(bytes(text).decode("utf-8-sig"), parse_constant=reject_constant)
        except UnicodeDecodeError:
            self.fail("JSON", "not UTF-8 text (is this a glTF file?)")
        except (json.JSONDecodeError, ValueError, RecursionError) as e:
            self.fail("JSON", f"malformed: {e}")
        if not isinstance(raw, dict):
            self.fail("JSON", "the top level must be an object")
        self.check_version(raw)
        try:
            self.doc: pygltflib.GLTF2 = decode_json(raw, pygltflib.GLTF2, "gltf")
        except ShapeError as e:
            raise SceneError(f"{self.source}: {e}") from None
        except RecursionError:
            self.fail("JSON", "nested too deeply")
        self.check_extensions()
        self.check_geometry()  # before any accessor is read
        self.build()
        self.say_unread()
        # zero-scale nodes are valid glTF: skipped with a warning that names them
        return self.scene.drawable()

    def split_glb(self, data: bytes) -> memoryview:
        """The JSON chunk; keeps the BIN chunk in ``self.glb_bin``."""
        if len(data) < 12:
            self.fail("GLB", f"truncated: the 12-byte header is {len(data)} bytes")
        _, version, length = struct.unpack_from("<4sII", data)
        if version != 2:
            self.fail("GLB", f"container version {version} (expected 2)")
        if length > len(data):
            self.fail("GLB", f"truncated: the header says {length} bytes, the file has "
                             f"{len(data)}")
        view = memoryview(data)[:length]
        offset, chunk, json_chunk = 12, 0, None
        while offset < length:
            if offset + 8 > length:
                self.fail("GLB", f"truncated chunk header at byte {offset}")
            size, kind = struct.unpack_from("<I4s", view, offset)
            offset += 8
            if offset + size > length:
                self.fail("GLB", f"chunk {chunk} ({kind.decode('latin-1')!r}) needs {size} "
                                 f"bytes, {length - offset} are left")
            body = view[offset:offset + size]
            if chunk == 0:
                if kind != _CHUNK_JSON:
                    self.fail("GLB", "the first chunk is not JSON")
                json_chunk = body
            elif chunk == 1 and kind == _CHUNK_BIN:
                self.glb_bin = body
            offset = self.next_chunk(view, offset + size, length)
            chunk += 1
        if json_chunk is None:
            self.fail("GLB", "no JSON chunk")
        return json_chunk

    @staticmethod
    def next_chunk(view: memoryview, offset: int, length: int) -> int:
        """Where the next chunk starts: chunk lengths include their padding, but some
        writers leave it out; take the aligned offset when only that finds a chunk."""
        aligned = offset + (-offset % 4)
        if aligned == offset or aligned + 8 > length:
            return offset
        known = (_CHUNK_JSON, _CHUNK_BIN)
        if bytes(view[offset + 4:offset + 8]) not in known \
                and bytes(view[aligned + 4:aligned + 8]) in known:
            return aligned
        return offset

    def check_version(self, raw: dict) -> None:
        asset = raw.get("asset")
        version = asset.get("version") if isinstance(asset, dict) else None
        if not isinstance(version, str):
            self.fail("asset", "no asset.version (is this a glTF 2.0 file?)")
        if version.split(".")[0] != "2":
            self.fail("asset", f"glTF version {version!r} is not supported (only 2.x)")

    def check_extensions(self) -> None:
        used = [e for e in self.doc.extensionsUsed or [] if e not in SUPPORTED_EXTENSIONS
                and e not in (self.doc.extensionsRequired or [])]
        if used:
            # optional by definition, but the scene may look different without them
            self.warn(f"extensionsUsed: {', '.join(used)} ignored")
        required = self.doc.extensionsRequired or []
        missing = [e for e in required if e not in SUPPORTED_EXTENSIONS]
        if missing:
            self.fail("extensionsRequired", f"{', '.join(missing)} "
                      f"{'is' if len(missing) == 1 else 'are'} not supported (supported: "
                      f"{', '.join(sorted(SUPPORTED_EXTENSIONS))})")

    def say_unread(self) -> None:
        """One warning line per kind of thing read past."""
        if self.doc.animations:
            self.unread["animations"].append("animations")
        for kind, message in _UNREAD.items():
            where = self.unread[kind]
            if where:
                more = f" and {len(where) - 1} more" if len(where) > 1 else ""
                self.warn(f"{where[0]}{more}: {message}")

    # -- bytes ----------------------------------------------------------------------------

    def read_uri(self, uri: str, where: str) -> bytes:
        """A data: URI, or a file inside the scene's folder."""
        if uri.startswith("data:"):
            header, comma, payload = uri.partition(",")
            if not comma:
                self.fail(where, "malformed data URI (no comma)")
            if header.endswith(";base64"):
                try:
                    return base64.b64decode(payload, validate=True)
                except (binascii.Error, ValueError) as e:
                    self.fail(where, f"data URI is not valid base64 ({e})")
            return urllib.parse.unquote_to_bytes(payload)
        shown = uri if len(uri) < 80 else uri[:77] + "..."
        if _URI_SCHEME.match(uri):
            self.fail(where, f"uri '{shown}' is not a relative path (only files in the "
                             "scene's folder are read)")
        rel = urllib.parse.unquote(uri)
        if not rel or "\x00" in rel or rel.startswith(("/", "\\")) \
                or PureWindowsPath(rel).is_absolute() or PureWindowsPath(rel).drive:
            self.fail(where, f"uri '{shown}' is not a relative path (only files in the "
                             "scene's folder are read)")
        try:
            target = (self.folder / rel).resolve()
        except (OSError, RuntimeError) as e:  # symlink loops
            self.fail(where, f"uri '{shown}' cannot be resolved ({e})")
        # resolve() follows symlinks, so a link pointing out of the folder is caught too
        if not target.is_relative_to(self.root):
            self.fail(where, f"uri '{shown}' points outside the scene's folder")
        try:
            return target.read_bytes()
        except FileNotFoundError:
            self.fail(where, f"file '{shown}' not found")
        except OSError as e:
            self.fail(where, f"cannot read '{shown}': {e.strerror or e}")

    def buffer(self, index: int, where: str) -> memoryview:
        if index in self.buffers:
            return self.buffers[index]
        buf = self.item("buffers", index, where)
        where = f"buffers[{index}]"
        length = self.integer(buf.byteLength, where, "byteLength", minimum=1)
        if buf.uri is None:
            if self.glb_bin is None:
                self.fail(where, "has no uri and the file has no GLB binary chunk")
            if index != 0:
                self.fail(where, "has no uri, but only buffers[0] can be the GLB binary chunk")
            data, name = self.glb_bin, "the GLB binary chunk"
        else:
            data, name = memoryview(self.read_uri(buf.uri, where)), f"'{buf.uri}'"
            if buf.uri.startswith("data:"):
                name = "its data URI"
        if len(data) < length:
            self.fail(where, f"truncated: {name} has {len(data)} bytes, byteLength says "
                             f"{length}")
        self.buffers[index] = data[:length]  # reads past byteLength are refused too
        return self.buffers[index]

    def view(self, index: Any, where: str) -> tuple[memoryview, int | None, str]:
        """(bytes, byteStride, name) of a buffer view."""
        view = self.item("bufferViews", index, where)
        name = f"bufferViews[{index}]"
        vwhere = f"{name} (used by {where})"
        data = self.buffer(self.integer(view.buffer, vwhere, "buffer"), vwhere)
        offset = self.integer(view.byteOffset, vwhere, "byteOffset", default=0)
        length = self.integer(view.byteLength, vwhere, "byteLength", minimum=1)
        if offset + length > len(data):
            self.fail(vwhere, f"bytes {offset}..{offset + length} lie outside "
                              f"buffers[{view.buffer}] ({len(data)} bytes)")
        stride = view.byteStride
        if stride is not None:
            stride = self.integer(stride, vwhere, "byteStride", minimum=1)
            if stride > 252:
                self.fail(vwhere, f"byteStride {stride} exceeds glTF's limit of 252")
        return data[offset:offset + length], stride, name

    def accessor(self, index: Any, what: str, types: tuple[str, ...], *,
                 indices: bool = False) -> np.ndarray:
        """Read an accessor as float64 (count, components), or int64 (count,) for indices."""
        acc = self.item("accessors", index, what)
        where = f"accessors[{index}] ({what})"
        with self.element(where):
            ctype = acc.componentType
            if ctype not in _COMPONENTS:
                self.fail(where, f"componentType {json.dumps(ctype)} is not a glTF component "
                                 "type")
            if indices and ctype not in _INDEX_COMPONENTS:
                self.fail(where, f"indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or "
                                 f"UNSIGNED_INT, got {_COMPONENT_NAMES[ctype]}")
            if acc.type not in types:
                self.fail(where, f"type is {json.dumps(acc.type)}, expected "
                                 f"{' or '.join(types)}")
            count = self.integer(acc.count, where, "count", minimum=1)
            ncomp = _TYPES[acc.type]
            dtype, size = _COMPONENTS[ctype]
            elem = ncomp * size
            if acc.bufferView is None:
                if count > _MAX_UNBACKED:
                    self.fail(where, f"count {count} without a bufferView is implausibly large")
                raw = np.zeros((count, ncomp), dtype)
            else:
                data, stride, vname = self.view(acc.bufferView, where)
                offset = self.integer(acc.byteOffset, where, "byteOffset", default=0)
                stride = elem if stride is None else stride
                if stride < elem:
                    self.fail(where, f"{vname} has byteStride {stride}, smaller than one "
                                     f"{acc.type} of {_COMPONENT_NAMES[ctype]} ({elem} bytes)")
                need = offset + stride * (count - 1) + elem
                if need > len(data):
                    self.fail(where, f"needs {need} bytes, {vname} has {len(data)}")
                raw = np.ndarray((count, ncomp), dtype, buffer=data, offset=offset,
                                 strides=(stride, size)).copy()
            if acc.sparse is not None:
                self.sparse(acc.sparse, raw, where)
            if indices:
                return raw[:, 0].astype(np.int64)
            if acc.normalized:
                if ctype not in _NORMALIZE:
                    self.fail(where, f"normalized is only allowed for byte and short "
                                     f"components, not {_COMPONENT_NAMES[ctype]}")
                out = np.maximum(raw.astype(np.float64) / _NORMALIZE[ctype], -1.0)
            else:
                out = raw.astype(np.float64)
            if not np.all(np.isfinite(out)):
                self.fail(where, "contains NaN or infinity")
            return out

    def sparse(self, sparse: Any, raw: np.ndarray, where: str) -> None:
        """Apply a sparse substitution to ``raw`` in place."""
        swhere = f"{where}.sparse"
        count = self.integer(sparse.count, swhere, "count", minimum=1)
        if count > len(raw):
            self.fail(swhere, f"count {count} exceeds the accessor's count {len(raw)}")
        if sparse.indices is None or sparse.values is None:
            self.fail(swhere, "needs both indices and values")
        ctype = sparse.indices.componentType
        if ctype not in _INDEX_COMPONENTS:
            self.fail(swhere, f"indices.componentType {json.dumps(ctype)} must be "
                              "UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT")
        idtype, isize = _COMPONENTS[ctype]
        data, _, vname = self.view(sparse.indices.bufferView, f"{swhere}.indices")
        offset = self.integer(sparse.indices.byteOffset, swhere, "indices.byteOffset",
                              default=0)
        if offset + count * isize > len(data):
            self.fail(swhere, f"indices need {offset + count * isize} bytes, {vname} has "
                              f"{len(data)}")
        idx = np.frombuffer(data, idtype, count, offset).astype(np.int64)
        if idx.max() >= len(raw):
            self.fail(swhere, f"index {int(idx.max())} out of range for count {len(raw)}")
        data, _, vname = self.view(sparse.values.bufferView, f"{swhere}.values")
        offset = self.integer(sparse.values.byteOffset, swhere, "values.byteOffset", default=0)
        nbytes = count * raw.shape[1] * raw.dtype.itemsize
        if offset + nbytes > len(data):
            self.fail(swhere, f"values need {offset + nbytes} bytes, {vname} has {len(data)}")
        values = np.frombuffer(data, raw.dtype, count * raw.shape[1], offset)
        raw[idx] = values.reshape(count, raw.shape[1])

    def check_geometry(self) -> None:
        """Refuse, before any accessor is read, a scene whose primitives would hold more
        than ``limits.MAX_GEOMETRY_BYTES``. Counts are the accessors' ``count``, with or
        without a bufferView (one without is ``count`` zeros: as large as one with), over
        the distinct primitives of the nodes the scene reaches. Malformed elements are left
        to ``build()``, which names them."""
        doc = self.doc
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
                (v, vname), (i, iname) = self.primitive_counts(prim)
                vertices, indices = vertices + v, indices + i
                for cost, what in ((v * limits.VERTEX_BYTES, vname),
                                   (i * limits.INDEX_BYTES, iname)):
                    if cost > largest:
                        largest, name = cost, f"meshes[{m}].primitives[{p}]{what}"
        limits.check_geometry(vertices, indices, file=self.source, largest=name)

    def primitive_counts(self, prim: Any) -> tuple[tuple[int, str], tuple[int, str]]:
        """(vertices, what holds them), (triangle corners, what holds them) of a primitive,
        from its accessors' counts (0 where one is malformed: build() says so)."""
        accessors = self.doc.accessors or []

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

    # -- scene graph ----------------------------------------------------------------------

    def build(self) -> None:
        doc = self.doc
        scenes = doc.scenes or []
        if doc.scene is not None:
            roots = self.item("scenes", doc.scene, "scene").nodes or []
            where = f"scenes[{doc.scene}]"
        elif scenes:
            roots, where = scenes[0].nodes or [], "scenes[0]"
        else:
            # no scenes: show every root node rather than nothing
            children = {c for n in doc.nodes or [] for c in n.children or []}
            roots = [i for i in range(len(doc.nodes or [])) if i not in children]
            where = "nodes"
        stack = [(self.item("nodes", r, f"{where}.nodes[{k}]"), r, np.identity(4))
                 for k, r in enumerate(roots)][::-1]
        seen: set[int] = set()
        open_zfar: list[int] = []
        while stack:
            node, index, parent = stack.pop()
            nwhere = f"nodes[{index}]"
            if index in seen:
                self.fail(nwhere, "reached twice (the node hierarchy has a cycle or a node "
                                  "with two parents)")
            seen.add(index)
            with self.element(nwhere):
                world = parent @ self.local(node, nwhere)
                if node.mesh is not None:
                    self.instance(node, index, world)
                if node.camera is not None:
                    cam, infinite = self.camera(node.camera, nwhere, world)
                    if infinite:
                        open_zfar.append(len(self.scene.cameras))
                    if cam is not None:
                        self.scene.cameras.append(cam)
                ext = (node.extensions or {}).get("KHR_lights_punctual")
                if ext is not None:
                    self.light(ext, nwhere, world)
                for k, c in reversed(list(enumerate(node.children or []))):
                    stack.append((self.item("nodes", c, f"{nwhere}.children[{k}]"), c, world))
        if not self.scene.materials:
            self.scene.materials.append(Material())
        if open_zfar:
            # glTF's infinite far plane: far enough for the whole scene
            far = 500.0
            if self.scene.instances:
                lo, hi = self.scene.bounds()
                far = max(far, 10.0 * float(np.linalg.norm(hi - lo)))
            for i in open_zfar:
                self.scene.cameras[i].zfar = far

    def local(self, node: Any, where: str) -> np.ndarray:
        if node.matrix is not None:
            m = self.numbers(node.matrix, 16, where, "matrix", ())
            return np.array(m, np.float64).reshape(4, 4).T  # glTF stores column-major
        t = self.numbers(node.translation, 3, where, "translation", (0.0, 0.0, 0.0))
        q = self.numbers(node.rotation, 4, where, "rotation", (0.0, 0.0, 0.0, 1.0))
        s = self.numbers(node.scale, 3, where, "scale", (1.0, 1.0, 1.0))
        qn = math.sqrt(sum(c * c for c in q))
        if qn < 1e-12:
            self.fail(where, "rotation is a zero quaternion")
        x, y, z, w = (c / qn for c in q)
        r = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        m = np.identity(4)
        m[:3, :3] = r * np.array(s)[None, :]  # T @ R @ S
        m[:3, 3] = t
        return m

    def instance(self, node: Any, index: int, world: np.ndarray) -> None:
        mesh = self.item("meshes", node.mesh, f"nodes[{index}].mesh")
        prims = mesh.primitives or []
        if not prims:
            self.fail(f"meshes[{node.mesh}]", "has no primitives")
        if node.skin is not None:
            self.unread["skins"].append(f"nodes[{index}]")
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
                                      node.name or f"nodes[{index}]"))

    # -- geometry -------------------------------------------------------------------------

    def primitive(self, mi: int, pi: int) -> Mesh:
        """The primitive as a Mesh: triangles, or a stroke (points or lines)."""
        mesh = self.doc.meshes[mi]
        prim = mesh.primitives[pi]
        where = f"meshes[{mi}].primitives[{pi}]"
        with self.element(where):
            attrs = {k: v for k, v in vars(prim.attributes).items() if v is not None} \
                if prim.attributes is not None else {}
            mode = self.integer(prim.mode, where, "mode", default=4)
            if mode not in _MODES:
                self.fail(where, f"mode {mode} is not a glTF primitive mode (0 to 6)")
            if prim.targets:
                self.unread["morphs"].append(where)
            if "POSITION" not in attrs:
                self.fail(where, "has no POSITION attribute")
            draco = (prim.extensions or {}).get("KHR_draco_mesh_compression")
            decoded = {} if draco is None else self.draco(draco, mode,
                                                          f"{where}.extensions."
                                                          "KHR_draco_mesh_compression")
            pos = decoded["POSITION"] if "POSITION" in decoded else \
                self.accessor(attrs["POSITION"], f"POSITION of {where}", ("VEC3",))
            n = len(pos)

            def attribute(name: str, types: tuple[str, ...]) -> np.ndarray | None:
                if name not in attrs:
                    return None
                a = decoded[name] if name in decoded else \
                    self.accessor(attrs[name], f"{name} of {where}", types)
                if len(a) != n:
                    self.fail(f"accessors[{attrs[name]}] ({name} of {where})",
                              f"count {len(a)} differs from POSITION's {n}")
                return a

            normals = attribute("NORMAL", ("VEC3",))
            tangents = attribute("TANGENT", ("VEC4",))
            material = self.material(prim.material, f"{where}.material")
            texcoord, uv_matrix, textured = self.uv_sets.get(material, (0, None, ""))
            uvs = attribute(f"TEXCOORD_{texcoord}", ("VEC2",))
            if uvs is None and texcoord != 0:
                uvs = attribute("TEXCOORD_0", ("VEC2",))
            if uvs is None and textured:
                self.warn(f"{where}: has no TEXCOORD_{texcoord}, which the textures of "
                          f"{textured} use: they are sampled at (0, 0)")
            elif uvs is not None and uv_matrix is not None:
                # KHR_texture_transform is affine, so it may be applied per vertex
                uvs = uvs @ uv_matrix[:, :2].T + uv_matrix[:, 2]
            colors = attribute("COLOR_0", ("VEC3", "VEC4"))
            if colors is not None and mode > 3:
                material = self.tint(material, colors, where)

            if "indices" in decoded:
                iwhere, idx = f"{where} (Draco)", decoded["indices"]
            elif prim.indices is not None:
                iwhere = f"accessors[{prim.indices}] (indices of {where})"
                idx = self.accessor(prim.indices, f"indices of {where}", ("SCALAR",),
                                    indices=True)
            else:
                iwhere, idx = f"{where} (non-indexed)", np.arange(n, dtype=np.int64)
            if len(idx) and int(idx.max()) >= n:
                self.fail(iwhere, f"index {int(idx.max())} out of range for {n} vertices "
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
            self.fail(where, "must be an object with bufferView and attributes")
        if mode != 4:
            self.fail(where, f"mode {mode}: Draco primitives must be TRIANGLES (4)")
        import DracoPy  # only needed for Draco-compressed scenes

        data, _, _ = self.view(ext.get("bufferView"), where)
        try:
            mesh = DracoPy.decode(bytes(data))
        except Exception as e:  # the decoder's errors have no common base
            self.fail(where, f"cannot decode the Draco data ({type(e).__name__}: {e})")
        faces = np.asarray(getattr(mesh, "faces", None) if mesh is not None else None)
        if faces is None or faces.ndim != 2 or faces.shape[1] != 3:
            self.fail(where, "the Draco data is not a triangle mesh")
        out = {"indices": faces.astype(np.int64).ravel()}
        for name, uid in ext["attributes"].items():
            found = mesh.get_attribute_by_unique_id(uid) \
                if isinstance(uid, int) and not isinstance(uid, bool) else None
            if found is None:
                self.fail(where, f"attributes.{name}: no Draco attribute has id "
                                 f"{json.dumps(uid)}")
            values = np.asarray(found["data"], np.float64)
            values = values.reshape(len(values), -1)
            if not np.all(np.isfinite(values)):
                self.fail(where, f"attributes.{name}: contains NaN or infinity")
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
                self.fail(iwhere, f"{len(idx)} indices is not a whole number of lines")
        elif mode in (2, 3):
            # a strip joins each index to the next; a loop joins the last to the first too
            ends = np.append(idx[1:], idx[:1]) if mode == 2 and len(idx) > 2 else idx[1:]
            idx = np.stack([idx[:len(ends)], ends], axis=1).ravel() if len(idx) > 1 \
                else np.zeros(0, np.int64)
        m = self.scene.materials[material]
        if any(t is not None for t in (m.base_color_texture, m.emissive_texture)):
            self.unread["stroke_textures"].append(where)
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
                self.fail(where, f"{len(idx)} indices is not a whole number of triangles")
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

    # -- materials and textures -----------------------------------------------------------

    def material(self, index: Any, where: str) -> int:
        if index is None:
            if self.default_material is None:
                # glTF's default material: the metallic-roughness defaults
                self.default_material = len(self.scene.materials)
                self.scene.materials.append(Material(name="default", metallic=1.0))
            return self.default_material
        if index in self.materials:
            return self.materials[index]
        m = self.item("materials", index, where)
        mwhere = f"materials[{index}]"
        self.texture_uses = []
        with self.element(mwhere):
            pbr = m.pbrMetallicRoughness or pygltflib.PbrMetallicRoughness()
            out = Material(name=m.name or mwhere)
            out.base_color = self.numbers(pbr.baseColorFactor, 4, mwhere, "baseColorFactor",
                                          (1.0, 1.0, 1.0, 1.0))
            out.metallic = self.number(pbr.metallicFactor, mwhere, "metallicFactor", 1.0)
            out.roughness = self.number(pbr.roughnessFactor, mwhere, "roughnessFactor", 1.0)
            emissive = self.numbers(m.emissiveFactor, 3, mwhere, "emissiveFactor",
                                    (0.0, 0.0, 0.0))
            strength = (m.extensions or {}).get("KHR_materials_emissive_strength")
            if isinstance(strength, dict):
                k = self.number(strength.get("emissiveStrength"), mwhere,
                                "KHR_materials_emissive_strength.emissiveStrength", 1.0)
                emissive = tuple(c * k for c in emissive)
            out.emissive = emissive
            out.base_color_texture = self.texture_info(pbr.baseColorTexture, True,
                                                       f"{mwhere}.baseColorTexture")
            out.metallic_roughness_texture = self.texture_info(
                pbr.metallicRoughnessTexture, False, f"{mwhere}.metallicRoughnessTexture")
            out.normal_texture = self.texture_info(m.normalTexture, False,
                                                   f"{mwhere}.normalTexture")
            if m.normalTexture is not None:
                out.normal_scale = self.number(m.normalTexture.scale, mwhere,
                                               "normalTexture.scale", 1.0)
            out.occlusion_texture = self.texture_info(m.occlusionTexture, False,
                                                      f"{mwhere}.occlusionTexture")
            if m.occlusionTexture is not None:
                out.occlusion_strength = self.number(m.occlusionTexture.strength, mwhere,
                                                     "occlusionTexture.strength", 1.0)
            out.emissive_texture = self.texture_info(m.emissiveTexture, True,
                                                     f"{mwhere}.emissiveTexture")
            mode = m.alphaMode if m.alphaMode is not None else "OPAQUE"
            if mode not in ("OPAQUE", "MASK", "BLEND"):
                self.fail(mwhere, f"alphaMode {json.dumps(mode)} must be OPAQUE, MASK or BLEND")
            out.alpha_mode = mode
            out.alpha_cutoff = self.number(m.alphaCutoff, mwhere, "alphaCutoff", 0.5)
            out.double_sided = bool(m.doubleSided)
        self.materials[index] = k = len(self.scene.materials)
        self.scene.materials.append(out)
        if self.texture_uses:
            self.uv_sets[k] = (*self.uv_set(mwhere), mwhere)
        return k

    def uv_set(self, mwhere: str) -> tuple[int, np.ndarray | None]:
        """The one TEXCOORD set and transform the material's textures are sampled with: the
        model has one per vertex, so where they differ the first texture's wins (warned)."""
        first, texcoord, matrix = self.texture_uses[0]
        for where, t, m in self.texture_uses[1:]:
            same = (m is None and matrix is None) or (
                m is not None and matrix is not None and np.allclose(m, matrix))
            if t != texcoord or not same:
                self.warn(f"{where} uses other texture coordinates than {first} (TEXCOORD or "
                          f"KHR_texture_transform); only one set per material is read, "
                          f"{first}'s")
        return texcoord, matrix

    def tint(self, material: int, colors: np.ndarray, where: str) -> int:
        """``material`` times a primitive's COLOR_0, which the model cannot carry per vertex:
        its mean (exact for one colour), warned where the colours vary."""
        rgba = np.ones((len(colors), 4))
        rgba[:, :colors.shape[1]] = np.clip(colors, 0.0, 1.0)
        mean = rgba.mean(axis=0)
        if np.abs(rgba - mean).max() > 1.0 / 255.0:
            self.warn(f"{where}: COLOR_0 varies per vertex; drawn with its mean "
                      "(vertex colours are not interpolated)")
        if np.all(np.abs(mean - 1.0) <= 0.5 / 255.0):
            return material  # white: the material as it is
        key = (material, tuple(np.round(mean, 6)))
        if key not in self.tinted:
            base = self.scene.materials[material]
            color = tuple(float(c * m) for c, m in zip(base.base_color, mean, strict=True))
            self.tinted[key] = len(self.scene.materials)
            self.scene.materials.append(replace(base, name=f"{base.name} (COLOR_0)",
                                                base_color=color))
            if material in self.uv_sets:
                self.uv_sets[self.tinted[key]] = self.uv_sets[material]
        return self.tinted[key]

    def texture_info(self, info: Any, srgb: bool, where: str) -> int | None:
        if info is None:
            return None
        if info.index is None:
            self.fail(where, "has no index")
        texcoord = self.integer(info.texCoord, where, "texCoord", default=0)
        ext = (info.extensions or {}).get("KHR_texture_transform")
        matrix = None
        if ext is not None:
            texcoord, matrix = self.texture_transform(ext, texcoord,
                                                      f"{where}.extensions.KHR_texture_transform")
        if texcoord > 1:
            self.warn(f"{where} uses TEXCOORD_{texcoord}; only TEXCOORD_0 and TEXCOORD_1 are "
                      "read (TEXCOORD_0 is used)")
            texcoord = 0
        out = self.texture(info.index, srgb, where)
        if out is not None:
            self.texture_uses.append((where, texcoord, matrix))
        return out

    def texture_transform(self, ext: Any, texcoord: int,
                          where: str) -> tuple[int, np.ndarray | None]:
        """KHR_texture_transform's texCoord and its matrix T * R * S (2x3), None for the
        identity."""
        if not isinstance(ext, dict):
            self.fail(where, "must be an object")
        ox, oy = self.numbers(ext.get("offset"), 2, where, "offset", (0.0, 0.0))
        sx, sy = self.numbers(ext.get("scale"), 2, where, "scale", (1.0, 1.0))
        r = self.number(ext.get("rotation"), where, "rotation", 0.0)
        texcoord = self.integer(ext.get("texCoord"), where, "texCoord", default=texcoord)
        c, s_ = math.cos(r), math.sin(r)
        # the extension's matrices: translation, then rotation (clockwise in uv), then scale
        m = np.array([[c * sx, s_ * sy, ox], [-s_ * sx, c * sy, oy]])
        if np.array_equal(m, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]):
            return texcoord, None
        return texcoord, m

    def texture(self, index: Any, srgb: bool, where: str) -> int | None:
        key = (index, srgb)
        if key in self.textures:
            return self.textures[key]
        tex = self.item("textures", index, where)
        twhere = f"textures[{index}]"
        source = tex.source
        webp = (tex.extensions or {}).get("EXT_texture_webp")
        if isinstance(webp, dict) and webp.get("source") is not None:
            source = webp["source"]
        if source is None:
            self.warn(f"{twhere} has no source this loader can decode; {where} is dropped")
            self.textures[key] = None
            return None
        pixels = self.image(source, f"{twhere}.source")
        sampler = self.sampler(tex.sampler, f"{twhere}.sampler")
        image = self.doc.images[source]
        name = tex.name or image.name or (image.uri if image.uri and
                                          not image.uri.startswith("data:") else twhere)
        self.textures[key] = len(self.scene.textures)
        self.scene.textures.append(Texture(name=name, pixels=pixels, srgb=srgb, **sampler))
        return self.textures[key]

    def sampler(self, index: Any, where: str) -> dict[str, str]:
        if index is None:
            return {}  # glTF: undefined sampler = repeat and auto filtering
        s = self.item("samplers", index, where)
        swhere = f"samplers[{index}]"
        out = {}
        if s.magFilter is not None:
            if s.magFilter not in _MAG_FILTERS:
                self.fail(swhere, f"magFilter {json.dumps(s.magFilter)} is not 9728 or 9729")
            out["mag_filter"] = _MAG_FILTERS[s.magFilter]
        if s.minFilter is not None:
            if s.minFilter not in _MIN_FILTERS:
                self.fail(swhere, f"minFilter {json.dumps(s.minFilter)} is not a glTF filter")
            out["min_filter"], out["mipmap_filter"] = _MIN_FILTERS[s.minFilter]
        for key, value in (("address_u", s.wrapS), ("address_v", s.wrapT)):
            if value is None:
                continue
            if value not in _WRAPS:
                name = "wrapS" if key == "address_u" else "wrapT"
                self.fail(swhere, f"{name} {json.dumps(value)} is not 33071, 33648 or 10497")
            out[key] = _WRAPS[value]
        return out

    def image(self, index: Any, where: str) -> np.ndarray:
        if index in self.images:
            return self.images[index]
        img = self.item("images", index, where)
        iwhere = f"images[{index}]"
        if img.uri is not None:
            data = self.read_uri(img.uri, iwhere)
        elif img.bufferView is not None:
            data = bytes(self.view(img.bufferView, iwhere)[0])
        else:
            self.fail(iwhere, "has neither uri nor bufferView")
        key = hashlib.sha256(data).digest()  # the same bytes under another name or index
        if key not in self.decoded:
            self.decoded[key] = self.decode(data, iwhere)
        self.images[index] = self.decoded[key]
        return self.images[index]

    def decode(self, data: bytes, where: str) -> np.ndarray:
        """RGBA8 pixels of an encoded image; its size is checked against the limits
        (``limits.check_image``) from the header, before the pixels are decoded."""
        from PIL import Image, UnidentifiedImageError  # only needed for textured scenes

        try:
            with limits.pillow_unbounded():  # sizes are checked here, with the file named
                im = Image.open(io.BytesIO(data))
        except UnidentifiedImageError:
            self.fail(where, "cannot decode the image: not a format Pillow reads "
                             f"({len(data)} bytes starting {bytes(data[:8])!r})")
        except (OSError, ValueError, SyntaxError) as e:
            self.fail(where, f"cannot decode the image ({type(e).__name__}: {e})")
        with im:
            self.texels = limits.check_image(*im.size, self.texels, file=self.source,
                                             where=where)
            try:
                im.load()
                if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                    # 16-bit greyscale: keep the high byte rather than clipping
                    grey = (np.asarray(im, np.uint32) >> 8).astype(np.uint8)
                    im = Image.fromarray(grey, "L")
                rgba = _rgba(im)
            except (OSError, ValueError, SyntaxError, MemoryError) as e:
                self.fail(where, f"cannot decode the image ({type(e).__name__}: {e})")
        return np.ascontiguousarray(rgba)

    # -- cameras and lights ---------------------------------------------------------------

    def camera(self, index: Any, where: str,
               world: np.ndarray) -> tuple[Camera | None, bool]:
        cam = self.item("cameras", index, f"{where}.camera")
        cwhere = f"cameras[{index}]"
        eye = world[:3, 3]
        forward = normalize((world[:3, :3] @ [0.0, 0.0, -1.0])[None])[0]
        up = normalize((world[:3, :3] @ [0.0, 1.0, 0.0])[None])[0]
        if not _finite32(world) or abs(float(forward @ up)) > 0.999:
            # a zero scale is valid glTF: the camera sees nothing, so it is left out
            self.skipped(where, f"{cwhere} skipped: its transform is degenerate")
            return None, False
        name = cam.name or cwhere
        if cam.type == "orthographic" or (cam.type is None and cam.orthographic is not None):
            o = cam.orthographic
            if o is None:
                self.fail(cwhere, "type is orthographic but there is no orthographic object")
            ymag = self.number(o.ymag, cwhere, "ymag", 1.0)
            znear = max(self.number(o.znear, cwhere, "znear", 0.01), 1e-3)
            zfar = self.number(o.zfar, cwhere, "zfar", 500.0)
            # the model is perspective only: a camera far back with a narrow field of view
            # sees about what the orthographic one sees around its target
            self.warn(f"{cwhere} is orthographic; approximated by a perspective camera")
            back = max(10.0 * abs(ymag), 10.0)
            yfov = 2.0 * math.atan(abs(ymag) / back) if ymag else math.radians(5.0)
            pos = eye - forward * back
            if not _finite32(pos) or not _finite32(zfar + back):
                self.skipped(where, f"{cwhere} skipped: it lies beyond {WORLD_LIMIT:g}")
                return None, False
            return Camera(tuple(map(float, pos)), tuple(map(float, eye)),
                          tuple(map(float, up)), yfov, znear, zfar + back, name), False
        if cam.type not in ("perspective", None) or cam.perspective is None:
            self.fail(cwhere, f"type {json.dumps(cam.type)} needs a perspective object")
        p = cam.perspective
        yfov = self.number(p.yfov, cwhere, "perspective.yfov", 0.0)
        if not 0.0 < yfov < math.pi:
            self.fail(cwhere, f"perspective.yfov {yfov} must lie in (0, pi)")
        znear = self.number(p.znear, cwhere, "perspective.znear", 0.0)
        if znear <= 0:
            self.fail(cwhere, "perspective.znear must be > 0")
        zfar = p.zfar
        if zfar is not None:
            zfar = self.number(zfar, cwhere, "perspective.zfar", 0.0)
            if zfar <= znear:
                self.fail(cwhere, f"perspective.zfar {zfar} must exceed znear {znear}")
        target = eye + forward
        if not _finite32(target):
            self.skipped(where, f"{cwhere} skipped: it lies beyond {WORLD_LIMIT:g}")
            return None, False
        return Camera(tuple(map(float, eye)), tuple(map(float, target)), tuple(map(float, up)),
                      yfov, znear, 500.0 if zfar is None else zfar, name), zfar is None

    def light(self, ext: Any, where: str, world: np.ndarray) -> None:
        lwhere = f"{where}.extensions.KHR_lights_punctual"
        if not isinstance(ext, dict):
            self.fail(lwhere, "must be an object")
        top = (self.doc.extensions or {}).get("KHR_lights_punctual")
        lights = top.get("lights") if isinstance(top, dict) else None
        if not isinstance(lights, list):
            self.fail(lwhere, "refers to a light, but the file has no KHR_lights_punctual "
                              "lights array")
        index = ext.get("light")
        if isinstance(index, bool) or not isinstance(index, int) \
                or not 0 <= index < len(lights):
            self.fail(lwhere, f"light {json.dumps(index)} is not an index into the "
                              f"{len(lights)} KHR_lights_punctual lights")
        src = lights[index]
        swhere = f"extensions.KHR_lights_punctual.lights[{index}]"
        if not isinstance(src, dict):
            self.fail(swhere, "must be an object")
        kind = src.get("type")
        if kind not in ("directional", "point", "spot"):
            self.fail(swhere, f"type {json.dumps(kind)} must be directional, point or spot")
        light = Light(kind=kind, name=src.get("name") if isinstance(src.get("name"), str)
                      else swhere)
        light.color = self.numbers(src.get("color"), 3, swhere, "color", (1.0, 1.0, 1.0))
        light.intensity = self.number(src.get("intensity"), swhere, "intensity", 1.0)
        if src.get("range") is not None:
            light.range = self.number(src.get("range"), swhere, "range", 0.0)
            if light.range <= 0:
                self.fail(swhere, "range must be > 0")
        if kind == "spot":
            spot = src.get("spot")
            if not isinstance(spot, dict):
                self.fail(swhere, "a spot light needs a spot object")
            light.inner_cone = self.number(spot.get("innerConeAngle"), swhere,
                                           "spot.innerConeAngle", 0.0)
            light.outer_cone = self.number(spot.get("outerConeAngle"), swhere,
                                           "spot.outerConeAngle", math.pi / 4)
            if not 0.0 <= light.inner_cone < light.outer_cone <= math.pi / 2:
                self.fail(swhere, "spot cone angles need 0 <= inner < outer <= pi/2")
        light.position = tuple(map(float, world[:3, 3]))
        direction = world[:3, :3] @ [0.0, 0.0, -1.0]
        if not _finite32(world) or np.linalg.norm(direction) < 1e-12:
            # a zero scale is valid glTF: such a light has no direction, so it is left out
            self.skipped(where, f"{swhere} skipped: its transform is degenerate")
            return
        light.direction = tuple(map(float, normalize(direction[None])[0]))
        self.scene.lights.append(light)


# rows converted at a time: the whole image converted at once held the decoded image, its
# RGBA copy in Pillow and the array at once (2.8 GB for a 16384x16384 RGB PNG, not 1.8)
_RGBA_BAND_TEXELS = 1 << 22


def _rgba(im: Any) -> np.ndarray:
    """A loaded Pillow image as an (H, W, 4) uint8 array, converted band by band."""
    w, h = im.size
    out = np.empty((h, w, 4), np.uint8)
    step = max(1, _RGBA_BAND_TEXELS // max(w, 1))
    for y in range(0, h, step):
        band = im.crop((0, y, w, min(y + step, h))).convert("RGBA")
        out[y:y + band.size[1]] = np.asarray(band)
    return out
