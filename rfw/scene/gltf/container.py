"""The file's bytes to its checked pygltflib document: the GLB container (header, chunks, the
binary chunk kept), the JSON, the asset version and the extensions this loader implements."""

from __future__ import annotations

import json
import struct

import pygltflib

from ..gltf_json import ShapeError, decode_json, reject_constant
from ..model import SceneError
from .file import GltfFile

# extensions whose absence would change the result, but which this loader implements
SUPPORTED_EXTENSIONS = frozenset({
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_specular",  # specularFactor; its texture and colour are warned as unread
    "KHR_mesh_quantization",  # integer positions / normals: any component type is read
    "EXT_texture_webp",  # Pillow decodes WebP
    "KHR_texture_transform",  # applied to the primitive's texture coordinates
    "KHR_draco_mesh_compression",  # decoded by DracoPy
})

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = b"JSON"
_CHUNK_BIN = b"BIN\x00"


def read_document(file: GltfFile) -> memoryview | None:
    """Read and decode ``file``: sets ``file.doc``; returns the GLB binary chunk (None for a
    .gltf, or a GLB without one)."""
    try:
        data = file.path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"{file.source}: file not found") from None
    except OSError as e:
        raise SceneError(f"{file.source}: cannot read: {e.strerror or e}") from None
    if data[:4] != _GLB_MAGIC and file.path.suffix.lower() == ".glb":
        # not read as JSON: a .glb that lacks the magic is some other file
        file.fail("GLB", f"not a GLB file: it starts with {data[:4]!r}, not b'glTF'")
    text, glb_bin = split_glb(file, data) if data[:4] == _GLB_MAGIC else (data, None)
    try:
        raw = json.loads(bytes(text).decode("utf-8-sig"), parse_constant=reject_constant)
    except UnicodeDecodeError:
        file.fail("JSON", "not UTF-8 text (is this a glTF file?)")
    except (json.JSONDecodeError, ValueError, RecursionError) as e:
        file.fail("JSON", f"malformed: {e}")
    if not isinstance(raw, dict):
        file.fail("JSON", "the top level must be an object")
    _check_version(file, raw)
    try:
        file.doc = decode_json(raw, pygltflib.GLTF2, "gltf")
    except ShapeError as e:
        raise SceneError(f"{file.source}: {e}") from None
    except RecursionError:
        file.fail("JSON", "nested too deeply")
    _check_extensions(file)
    return glb_bin


def split_glb(file: GltfFile, data: bytes) -> tuple[memoryview, memoryview | None]:
    """The JSON chunk and the BIN chunk (None when there is none) of a GLB file."""
    if len(data) < 12:
        file.fail("GLB", f"truncated: the 12-byte header is {len(data)} bytes")
    _, version, length = struct.unpack_from("<4sII", data)
    if version != 2:
        file.fail("GLB", f"container version {version} (expected 2)")
    if length > len(data):
        file.fail("GLB", f"truncated: the header says {length} bytes, the file has "
                         f"{len(data)}")
    view = memoryview(data)[:length]
    offset, chunk, json_chunk, bin_chunk = 12, 0, None, None
    while offset < length:
        if offset + 8 > length:
            file.fail("GLB", f"truncated chunk header at byte {offset}")
        size, kind = struct.unpack_from("<I4s", view, offset)
        offset += 8
        if offset + size > length:
            file.fail("GLB", f"chunk {chunk} ({kind.decode('latin-1')!r}) needs {size} "
                             f"bytes, {length - offset} are left")
        body = view[offset:offset + size]
        if chunk == 0:
            if kind != _CHUNK_JSON:
                file.fail("GLB", "the first chunk is not JSON")
            json_chunk = body
        elif chunk == 1 and kind == _CHUNK_BIN:
            bin_chunk = body
        offset = _next_chunk(view, offset + size, length)
        chunk += 1
    if json_chunk is None:
        file.fail("GLB", "no JSON chunk")
    return json_chunk, bin_chunk


def _next_chunk(view: memoryview, offset: int, length: int) -> int:
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


def _check_version(file: GltfFile, raw: dict) -> None:
    asset = raw.get("asset")
    version = asset.get("version") if isinstance(asset, dict) else None
    if not isinstance(version, str):
        file.fail("asset", "no asset.version (is this a glTF 2.0 file?)")
    if version.split(".")[0] != "2":
        file.fail("asset", f"glTF version {version!r} is not supported (only 2.x)")


def _check_extensions(file: GltfFile) -> None:
    used = [e for e in file.doc.extensionsUsed or [] if e not in SUPPORTED_EXTENSIONS
            and e not in (file.doc.extensionsRequired or [])]
    if used:
        # optional by definition, but the scene may look different without them
        file.warn(f"extensionsUsed: {', '.join(used)} ignored")
    required = file.doc.extensionsRequired or []
    missing = [e for e in required if e not in SUPPORTED_EXTENSIONS]
    if missing:
        file.fail("extensionsRequired", f"{', '.join(missing)} "
                  f"{'is' if len(missing) == 1 else 'are'} not supported (supported: "
                  f"{', '.join(sorted(SUPPORTED_EXTENSIONS))})")
