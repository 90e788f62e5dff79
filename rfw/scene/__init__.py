"""Scenes: the data model, loaders for glTF and mesh files, and the built-in scenes.

``load_scene`` picks the loader from the file suffix; every loader returns a ``Scene`` and
raises ``SceneError`` (naming the file and the element) for anything it cannot read.
Built-in scenes are generated, and found by name (``builtin_scene``): ``default`` and
``courtyard`` (the courtyard), ``stress`` (100,000 cubes) and ``stress:COUNT``, and the
agreement scenes ``cornell`` and ``spheres`` (which rfw's path tracer and Mitsuba 3 render
alike, ``rfw.truth``).
"""

from __future__ import annotations

from pathlib import Path

from .agreement import cornell, spheres
from .courtyard import courtyard
from .model import Camera, Instance, Light, Material, Mesh, Scene, SceneError, Texture
from .stress import MAX_INSTANCES, STRESS_INSTANCES, stress

GLTF_SUFFIXES = frozenset({".gltf", ".glb"})


BUILTIN_SCENES = ("default", "courtyard", "cornell", "spheres", "stress", "stress:COUNT")
# the built-in scenes without a parameter, each built by one call
_FIXED = {"default": courtyard, "courtyard": courtyard, "cornell": cornell, "spheres": spheres}


def is_builtin(name: str | Path) -> bool:
    """Whether ``name`` names a built-in scene (``stress:x`` does, and is refused later by
    ``builtin_scene`` with the reason)."""
    text = str(name)
    return text in _FIXED or text == "stress" or text.startswith("stress:")


def builtin_scene(name: str) -> Scene:
    """The built-in scene called ``name`` (see ``BUILTIN_SCENES``).

    Raises
    ------
    SceneError
        For an unknown name, or a ``stress:COUNT`` whose count is not an integer from 1 to
        ``MAX_INSTANCES``.
    """
    if name in _FIXED:
        return _FIXED[name]()
    return stress(stress_count(name))


def stress_count(name: str) -> int:
    """The instance count ``stress`` or ``stress:COUNT`` asks for, checked without building
    the scene (so a bench refuses a bad count before any run)."""
    if name == "stress":
        return STRESS_INSTANCES
    if name.startswith("stress:"):
        text = name.split(":", 1)[1]
        if not text.isdigit() or not 1 <= int(text) <= MAX_INSTANCES:
            raise SceneError(f"the instance count must be an integer from 1 to "
                             f"{MAX_INSTANCES:,}, not {text!r}", file=name,
                             element="scene")
        return int(text)
    raise SceneError(f"no built-in scene is called {name!r} (built-in: "
                     f"{', '.join(BUILTIN_SCENES)})", file=name, element="scene",
                     suggest=(name, BUILTIN_SCENES[:-1]))


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
    if is_builtin(path) and not Path(path).exists():  # a file of that name comes first
        return builtin_scene(str(path))
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in GLTF_SUFFIXES:
        return load_gltf(path)
    from .meshfile import mesh_suffixes

    meshes = mesh_suffixes()
    if suffix in meshes:
        return load_meshfile(path)
    known = ", ".join(sorted(GLTF_SUFFIXES | meshes))
    raise SceneError(f"{path}: unknown scene file type '{path.suffix}' (expected {known})")


def load_gltf(path: str | Path) -> Scene:
    """Load a ``.gltf``/``.glb`` file (``rfw.scene.gltf.load_gltf``).

    Its loader, and pygltflib with it (about 0.07 s of CPU), is imported on the first call,
    as trimesh is for mesh files: most ``rfw`` processes draw a built-in scene.
    """
    from .gltf import load_gltf as load

    return load(path)


def load_meshfile(path: str | Path) -> Scene:
    """Load a mesh file through trimesh (``rfw.scene.meshfile.load_meshfile``).

    trimesh is imported on the first call: it costs about 0.15 s of CPU, which every
    ``rfw`` process whose scene is no mesh file (most runs, every failed config) saves.
    """
    from .meshfile import load_meshfile as load

    return load(path)


def default_scene() -> Scene:
    """The built-in courtyard (seed 0)."""
    return courtyard(0)


__all__ = [
    "BUILTIN_SCENES", "Camera", "Instance", "Light", "Material", "Mesh", "Scene", "SceneError",
    "Texture", "builtin_scene", "cornell", "courtyard", "default_scene", "is_builtin",
    "load_gltf", "load_meshfile", "load_scene", "spheres", "stress",
]
