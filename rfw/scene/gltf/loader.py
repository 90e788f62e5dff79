"""The loader that ties the parts together: the file read and decoded, its geometry checked
against the limits, then the scene built from the roots down, each part making what it
reads once; and the container and URI rules as functions of their own for other callers
(the fetch cache packs GLB files with them)."""

from __future__ import annotations

from pathlib import Path

from ..model import Scene
from .accessors import Accessors
from .animations import Animations
from .container import read_document
from .container import split_glb as _split_glb
from .file import GltfFile
from .materials import Materials
from .meshes import Meshes, check_geometry
from .nodes import SceneGraph
from .textures import Textures


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
    file = GltfFile(Path(path))
    glb_bin = read_document(file)
    check_geometry(file)  # before any accessor is read
    scene = Scene(name=file.path.stem, materials=[], source=file.source)
    accessors = Accessors(file, glb_bin)
    materials = Materials(file, Textures(file, accessors, scene), scene)
    SceneGraph(file, Meshes(file, accessors, materials, scene), scene).build()
    Animations(file, accessors, scene).read()
    file.say_unread()
    # zero-scale nodes are valid glTF: skipped with a warning that names them
    return scene.drawable()


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
    text, glb_bin = _split_glb(GltfFile(Path(path)), data)
    return bytes(text), None if glb_bin is None else bytes(glb_bin)


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
    return GltfFile(Path(path)).read_uri(uri, where)
