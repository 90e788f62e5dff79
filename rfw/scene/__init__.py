"""Scenes: the data model, loaders for glTF and mesh files, and the built-in courtyard.

``load_scene`` picks the loader from the file suffix; every loader returns a ``Scene`` and
raises ``SceneError`` (naming the file and the element) for anything it cannot read.
"""

from __future__ import annotations

from pathlib import Path

from .courtyard import courtyard
from .gltf import load_gltf
from .meshfile import load_meshfile, mesh_suffixes
from .model import Camera, Instance, Light, Material, Mesh, Scene, SceneError, Texture

GLTF_SUFFIXES = frozenset({".gltf", ".glb"})


def load_scene(path: str | Path) -> Scene:
    """Load a scene file: ``.gltf``/``.glb`` natively, mesh formats through trimesh.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        For unknown suffixes and for anything the loader cannot read.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in GLTF_SUFFIXES:
        return load_gltf(path)
    meshes = mesh_suffixes()
    if suffix in meshes:
        return load_meshfile(path)
    known = ", ".join(sorted(GLTF_SUFFIXES | meshes))
    raise SceneError(f"{path}: unknown scene file type '{path.suffix}' (expected {known})")


def default_scene() -> Scene:
    """The built-in courtyard (seed 0)."""
    return courtyard(0)


__all__ = [
    "Camera", "Instance", "Light", "Material", "Mesh", "Scene", "SceneError", "Texture",
    "courtyard", "default_scene", "load_gltf", "load_meshfile", "load_scene",
]
