"""Accessors, and the buffer views and buffers under them: every index, offset, length and
stride checked before a read; values as float64 (normalised, sparse applied) or int64
indices."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .file import GltfFile

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
# accessors without a bufferView are allocated from ``count`` alone: cap what a file can ask
_MAX_UNBACKED = 1 << 26


class Accessors:
    """The accessors of ``file``; ``glb_bin`` is the GLB binary chunk (``buffers[0]`` when it
    has no uri). Each buffer is read once."""

    def __init__(self, file: GltfFile, glb_bin: memoryview | None):
        self.file = file
        self.glb_bin = glb_bin
        self.buffers: dict[int, memoryview] = {}

    def buffer(self, index: int, where: str) -> memoryview:
        if index in self.buffers:
            return self.buffers[index]
        buf = self.file.item("buffers", index, where)
        where = f"buffers[{index}]"
        length = self.file.integer(buf.byteLength, where, "byteLength", minimum=1)
        if buf.uri is None:
            if self.glb_bin is None:
                self.file.fail(where, "has no uri and the file has no GLB binary chunk")
            if index != 0:
                self.file.fail(where, "has no uri, but only buffers[0] can be the GLB binary chunk")
            data, name = self.glb_bin, "the GLB binary chunk"
        else:
            data, name = memoryview(self.file.read_uri(buf.uri, where)), f"'{buf.uri}'"
            if buf.uri.startswith("data:"):
                name = "its data URI"
        if len(data) < length:
            self.file.fail(where, f"truncated: {name} has {len(data)} bytes, byteLength says "
                                  f"{length}")
        self.buffers[index] = data[:length]  # reads past byteLength are refused too
        return self.buffers[index]

    def view(self, index: Any, where: str) -> tuple[memoryview, int | None, str]:
        """(bytes, byteStride, name) of a buffer view."""
        view = self.file.item("bufferViews", index, where)
        name = f"bufferViews[{index}]"
        vwhere = f"{name} (used by {where})"
        data = self.buffer(self.file.integer(view.buffer, vwhere, "buffer"), vwhere)
        offset = self.file.integer(view.byteOffset, vwhere, "byteOffset", default=0)
        length = self.file.integer(view.byteLength, vwhere, "byteLength", minimum=1)
        if offset + length > len(data):
            self.file.fail(vwhere, f"bytes {offset}..{offset + length} lie outside "
                                   f"buffers[{view.buffer}] ({len(data)} bytes)")
        stride = view.byteStride
        if stride is not None:
            stride = self.file.integer(stride, vwhere, "byteStride", minimum=1)
            if stride > 252:
                self.file.fail(vwhere, f"byteStride {stride} exceeds glTF's limit of 252")
        return data[offset:offset + length], stride, name

    def accessor(self, index: Any, what: str, types: tuple[str, ...], *,
                 indices: bool = False) -> np.ndarray:
        """Read an accessor as float64 (count, components), or int64 (count,) for indices."""
        acc = self.file.item("accessors", index, what)
        where = f"accessors[{index}] ({what})"
        with self.file.element(where):
            ctype = acc.componentType
            if ctype not in _COMPONENTS:
                self.file.fail(where, f"componentType {json.dumps(ctype)} is not a glTF component "
                                      "type")
            if indices and ctype not in _INDEX_COMPONENTS:
                self.file.fail(where, f"indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or "
                                      f"UNSIGNED_INT, got {_COMPONENT_NAMES[ctype]}")
            if acc.type not in types:
                self.file.fail(where, f"type is {json.dumps(acc.type)}, expected "
                                      f"{' or '.join(types)}")
            count = self.file.integer(acc.count, where, "count", minimum=1)
            ncomp = _TYPES[acc.type]
            dtype, size = _COMPONENTS[ctype]
            elem = ncomp * size
            if acc.bufferView is None:
                if count > _MAX_UNBACKED:
                    self.file.fail(where, f"count {count} without a bufferView is "
                                          "implausibly large")
                raw = np.zeros((count, ncomp), dtype)
            else:
                data, stride, vname = self.view(acc.bufferView, where)
                offset = self.file.integer(acc.byteOffset, where, "byteOffset", default=0)
                stride = elem if stride is None else stride
                if stride < elem:
                    self.file.fail(where, f"{vname} has byteStride {stride}, smaller than one "
                                          f"{acc.type} of {_COMPONENT_NAMES[ctype]} ({elem} bytes)")
                need = offset + stride * (count - 1) + elem
                if need > len(data):
                    self.file.fail(where, f"needs {need} bytes, {vname} has {len(data)}")
                raw = np.ndarray((count, ncomp), dtype, buffer=data, offset=offset,
                                 strides=(stride, size)).copy()
            if acc.sparse is not None:
                self.sparse(acc.sparse, raw, where)
            if indices:
                return raw[:, 0].astype(np.int64)
            if acc.normalized:
                if ctype not in _NORMALIZE:
                    self.file.fail(where, f"normalized is only allowed for byte and short "
                                          f"components, not {_COMPONENT_NAMES[ctype]}")
                out = np.maximum(raw.astype(np.float64) / _NORMALIZE[ctype], -1.0)
            else:
                out = raw.astype(np.float64)
            if not np.all(np.isfinite(out)):
                self.file.fail(where, "contains NaN or infinity")
            return out

    def sparse(self, sparse: Any, raw: np.ndarray, where: str) -> None:
        """Apply a sparse substitution to ``raw`` in place."""
        swhere = f"{where}.sparse"
        count = self.file.integer(sparse.count, swhere, "count", minimum=1)
        if count > len(raw):
            self.file.fail(swhere, f"count {count} exceeds the accessor's count {len(raw)}")
        if sparse.indices is None or sparse.values is None:
            self.file.fail(swhere, "needs both indices and values")
        ctype = sparse.indices.componentType
        if ctype not in _INDEX_COMPONENTS:
            self.file.fail(swhere, f"indices.componentType {json.dumps(ctype)} must be "
                                   "UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT")
        idtype, isize = _COMPONENTS[ctype]
        data, _, vname = self.view(sparse.indices.bufferView, f"{swhere}.indices")
        offset = self.file.integer(sparse.indices.byteOffset, swhere, "indices.byteOffset",
                                   default=0)
        if offset + count * isize > len(data):
            self.file.fail(swhere, f"indices need {offset + count * isize} bytes, {vname} has "
                                   f"{len(data)}")
        idx = np.frombuffer(data, idtype, count, offset).astype(np.int64)
        if idx.max() >= len(raw):
            self.file.fail(swhere, f"index {int(idx.max())} out of range for count {len(raw)}")
        data, _, vname = self.view(sparse.values.bufferView, f"{swhere}.values")
        offset = self.file.integer(sparse.values.byteOffset, swhere, "values.byteOffset", default=0)
        nbytes = count * raw.shape[1] * raw.dtype.itemsize
        if offset + nbytes > len(data):
            self.file.fail(swhere, f"values need {offset + nbytes} bytes, {vname} has {len(data)}")
        values = np.frombuffer(data, raw.dtype, count * raw.shape[1], offset)
        raw[idx] = values.reshape(count, raw.shape[1])
