"""The glTF file being read, as every part of the loader sees it: its name in errors and
warnings, its folder (the only place external files are read from), the decoded document,
checked reads of the document's values, and what it holds that is read past."""

from __future__ import annotations

import base64
import binascii
import json
import math
import re
import struct
import urllib.parse
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path, PureWindowsPath
from typing import Any, NoReturn

import numpy as np
import pygltflib

from ...errors import warn as warn_once
from ..model import SceneError


class SceneWarning(UserWarning):
    """Something in a scene file that is not drawn as the file means it (a skin, a point
    primitive). Each is also one ``rfw: warning:`` line on stderr; as a Python warning it is
    ignored unless a caller asks for it (``warnings.catch_warnings``, ``pytest.warns``), so
    the line is not said twice."""


warnings.filterwarnings("ignore", category=SceneWarning)

# what load_gltf() reads past, and how its warning says so
_UNREAD = {
    "stroke_textures": "textures of points and lines not read: drawn with the material's "
                       "base colour and emissive factors",
    "skins": "skins not read: skinned meshes are drawn unposed, by their nodes' transforms",
    "morphs": "morph targets not read: meshes are drawn with their base shape",
    "specular": "specularTexture, specularColorFactor and specularColorTexture not read: the "
                "specular lobe is scaled by specularFactor alone, uncoloured",
}

_URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")

_FLOAT32_MAX = float(np.finfo(np.float32).max)


class GltfFile:
    """One glTF file: ``fail`` raises a ``SceneError`` naming it and the element, ``warn``
    says a thing once, ``item``, ``integer`` and ``number`` read the document's values
    checked, ``read_uri`` reads the bytes a URI names; ``unread`` collects what is read past,
    said in one line each by ``say_unread``."""

    doc: pygltflib.GLTF2  # the decoded document (container.read_document)

    def __init__(self, path: Path):
        self.path = path
        self.source = str(path)
        self.folder = path.absolute().parent
        self.root = self.folder.resolve()
        # what the file holds that is not drawn as it means, said in one line each after
        # the scene is built: kind -> the elements (first few named)
        self.unread: dict[str, list[str]] = {k: [] for k in _UNREAD}
        self.warned: set[str] = set()

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

    # -- checked values ------------------------------------------------------------------

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

    # -- bytes and what is read past -----------------------------------------------------

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

    def say_unread(self) -> None:
        """One warning line per kind of thing read past."""
        for kind, message in _UNREAD.items():
            where = self.unread[kind]
            if where:
                more = f" and {len(where) - 1} more" if len(where) > 1 else ""
                self.warn(f"{where[0]}{more}: {message}")
