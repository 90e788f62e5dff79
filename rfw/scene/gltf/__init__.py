"""glTF 2.0 (.gltf with external or embedded data, and .glb) to a ``Scene``.

The JSON is decoded into pygltflib's document classes, every value type-checked; every
index, offset, length and stride is validated before a read, so a malformed file raises a
``SceneError`` naming the file and the element ("scene.gltf: accessors[3] (POSITION of
meshes[0].primitives[1]): needs 4800 bytes, bufferViews[2] has 1200") rather than an
IndexError or a read past a buffer. External files are only read from the scene's folder.

What is read: the node hierarchy (TRS or matrix), the chosen scene, every triangle primitive
(strips and fans become lists), indexed or not, any accessor component type (normalised or
not, strided, sparse), POSITION / NORMAL / TANGENT, the TEXCOORD_0 or TEXCOORD_1 set a
primitive's textures use (with KHR_texture_transform), a constant COLOR_0 (folded into the
material; one that varies per vertex is drawn with its mean and a warning), metallic-roughness
materials with their five textures and samplers, KHR_materials_specular's specularFactor
(its texture and colour are not read, with a warning), perspective cameras and
KHR_lights_punctual, and node animations (translation, rotation and scale channels, with
the node hierarchy they move: :mod:`~.animations`, :mod:`rfw.scene.animation`). Normals and
tangents are computed where the file has none.

Not read: skins and morph targets (meshes appear in their bind pose), texture
coordinate sets past TEXCOORD_1 (TEXCOORD_0 is used, with a warning). Orthographic cameras
are approximated by a narrow perspective camera (warning).

The parts, each a class over the one :class:`~.file.GltfFile` (the file, its decoded
document, checked reads and errors naming the element) that makes what it reads once:
:mod:`~.container` (GLB, JSON, version, extensions), :mod:`~.accessors` (buffers, views,
accessors), :mod:`~.textures` (images, samplers), :mod:`~.materials`, :mod:`~.meshes`
(primitives, strokes, the geometry limit), :mod:`~.nodes` (the hierarchy, instances,
cameras, lights), :mod:`~.animations` (the clips) and :mod:`~.loader`, which ties them
together.
"""

from .container import SUPPORTED_EXTENSIONS
from .file import SceneWarning
from .loader import load_gltf, read_uri, split_glb

__all__ = ["SUPPORTED_EXTENSIONS", "SceneWarning", "load_gltf", "read_uri", "split_glb"]
