"""Hypothesis mutates a valid glTF document (deletes, retypes and rescales its fields:
accessors, bufferViews, nodes' matrix/scale/rotation/translation, meshes, materials, index
values and counts, float32 extremes, NaN and infinity in the binary buffer) and the loader
must either load it or raise ``SceneError``; any other exception is a loader bug. A loaded scene must also be drawable: every instance has a finite,
invertible transform, and the bounds, default camera and instance uniforms are finite.

Derandomized (the same examples on every run and machine), and bounded so it takes seconds;
``RFW_FUZZ_EXAMPLES`` raises the count for a longer hunt.
"""

from __future__ import annotations

import copy
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rfw.backends.scene_data import instance_bytes, lights_bytes, main_camera_bytes
from rfw.scene import SceneError, load_gltf
from rfw.scene.model import transform_problem

from .test_gltf import U8, U32, Gltf, _check_scene, _paths, kitchen_sink

FUZZ = settings(max_examples=int(os.environ.get("RFW_FUZZ_EXAMPLES", 300)), deadline=None,
                derandomize=True, suppress_health_check=list(HealthCheck))

# the parts of the document the mutations aim at
TARGETS = ("accessors", "bufferViews", "nodes", "meshes", "materials", "buffers", "scenes")


def fuzz_doc(folder: Path) -> Gltf:
    """The kitchen sink plus a second mesh with 32-bit indices and a node with a matrix."""
    g = kitchen_sink(folder)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3, 0, 3, 1], np.uint32)
    prim = g.primitive(pos=pos, idx=idx, uv=None, index_type=U32)
    g.node(mesh=g.mesh(prim), matrix=[1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1])
    small = g.primitive(pos=pos, idx=np.array([3, 2, 1]), uv=None, index_type=U8)
    g.node(mesh=g.mesh(small), rotation=[0, 0.6, 0, 0.8], scale=[-1, 1, 1])
    return g


def _space() -> list[tuple]:
    with tempfile.TemporaryDirectory() as d:
        doc = fuzz_doc(Path(d)).doc
    return sorted((p for p in set(_paths(doc)) if p and p[0] in TARGETS), key=str)


PATHS = _space()
RETYPES = [None, True, "", "x", [], {}, [0], [[1]], {"a": 1}, -1, 0, 7, 1.5, 2 ** 31, 2 ** 63,
           1e308, -1e308, "SCALAR", "VEC4", "MAT4"]
WORDS = [0x7F7FFFFF, 0xFF7FFFFF, 0x7F800000, 0x7FC00000, 0x00000001, 0x5F000000,
         0xFFFFFFFF, 0]
SCALES = [0, -1, 0.5, 3, 1e-30, 1e30, 1e-300, 1e300, 2 ** 20]
TRANSFORMS = {
    "scale": [[0, 0, 0], [0, 1, 1], [-1, 1, 1], [-1, -1, -1], [1e-30, 1, 1], [1e30, 1e30, 1],
              [1e300, 1, 1]],
    "rotation": [[0, 0, 0, 0], [0, 0, 0, 1e-30], [1e300, 0, 0, 1], [0, 0, 0, -1]],
    "translation": [[1e308, 0, 0], [1e38, 1e38, 1e38]],
    "matrix": [[0] * 16, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0],
               [1e300] * 16, [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
               [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
               [1e20, 0, 0, 0, 0, 1e20, 0, 0, 0, 0, 1e20, 0, 0, 0, 0, 1]],
}


def _scale(value, factor):
    if isinstance(value, bool):
        return not value
    if isinstance(value, int) and isinstance(factor, int):
        return value * factor
    if isinstance(value, int | float):
        return value * factor
    if isinstance(value, list):
        return [_scale(v, factor) for v in value]
    return value


@st.composite
def mutation(draw):
    kind = draw(st.sampled_from(["delete", "retype", "rescale", "transform", "count",
                                 "index", "word"]))
    if kind == "transform":
        key = draw(st.sampled_from(sorted(TRANSFORMS)))
        return kind, key, draw(st.sampled_from(TRANSFORMS[key]))
    if kind == "count":
        return kind, None, draw(st.sampled_from([0, 1, 2, 3, 4, 5, 6, 1000, 2 ** 31, -1]))
    if kind == "index":
        return kind, None, draw(st.sampled_from([3, 4, 255, 2 ** 16 - 1, 2 ** 32 - 1]))
    if kind == "word":  # a 32-bit word of the binary buffer: float32 extremes, NaN, inf
        return kind, draw(st.integers(0, 10 ** 6)), draw(st.sampled_from(WORDS))
    path = draw(st.sampled_from(PATHS))
    value = draw(st.sampled_from(RETYPES if kind == "retype" else SCALES))
    return kind, path, value


def _set(doc: dict, path: tuple, value) -> None:
    obj = doc
    for k in path[:-1]:
        obj = obj[k]
    if value is _DELETE:
        del obj[path[-1]]
    else:
        obj[path[-1]] = copy.deepcopy(value)


_DELETE = object()


def apply(g: Gltf, kind: str, path, value, pick: int) -> None:
    doc = g.doc
    try:
        if kind == "delete":
            _set(doc, path, _DELETE)
        elif kind == "retype":
            _set(doc, path, value)
        elif kind == "rescale":
            obj = doc
            for k in path:
                obj = obj[k]
            _set(doc, path, _scale(obj, value))
        elif kind == "transform":
            node = doc["nodes"][pick % len(doc["nodes"])]
            if path == "matrix":
                for k in ("translation", "rotation", "scale"):
                    node.pop(k, None)
            node[path] = copy.deepcopy(value)
        elif kind == "count":
            doc["accessors"][pick % len(doc["accessors"])]["count"] = value
        elif kind == "index":
            # the last index of an index accessor, rewritten in the binary buffer
            acc = doc["accessors"][doc["meshes"][-1]["primitives"][0]["indices"]]
            view = doc["bufferViews"][acc["bufferView"]]
            size = {5121: 1, 5123: 2, 5125: 4}[acc["componentType"]]
            at = view["byteOffset"] + acc.get("byteOffset", 0) + (acc["count"] - 1) * size
            g.bin[at:at + size] = int(value % (1 << (8 * size))).to_bytes(size, "little")
        elif kind == "word":
            at = 4 * (path % (len(g.bin) // 4))
            g.bin[at:at + 4] = value.to_bytes(4, "little")
    except (KeyError, IndexError, TypeError, ValueError, ZeroDivisionError):
        pass  # an earlier change removed or retyped the place: the document stays as it is


def check_drawable(scene) -> None:
    _check_scene(scene)  # meshes and material references, as test_gltf's fuzz checks them
    for inst in scene.instances:
        assert transform_problem(inst.transform) is None, inst.name
        assert np.all(np.isfinite(np.frombuffer(instance_bytes(inst.transform), np.float32)))
    cam = scene.default_camera()
    assert np.all(np.isfinite(cam.view())) and np.all(np.isfinite(cam.projection(1.5)))
    # what the backends upload: packing must not overflow float32
    data = main_camera_bytes(cam, (64, 48)) + lights_bytes(scene)[0]
    assert np.all(np.isfinite(np.frombuffer(data, np.float32)))
    if scene.instances:
        lo, hi = scene.bounds()
        assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))


def load_or_scene_error(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = load_gltf(path)
        except SceneError as e:
            assert str(e).startswith(str(path.parent)), e  # names the file
            assert "\n" not in str(e)
            return None
    check_drawable(scene)
    return scene


@FUZZ
@given(st.lists(st.tuples(mutation(), st.integers(0, 63)), min_size=1, max_size=3),
       st.booleans())
def test_mutated_gltf_loads_or_raises_scene_error(changes, as_glb):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        g = fuzz_doc(folder)
        for (kind, path, value), pick in changes:
            apply(g, kind, path, value, pick)
        load_or_scene_error(g.glb(folder) if as_glb else g.write(folder))


# the fuzzer's own controls: the unmutated document loads, and each kind of mutation can
# reach the loader's checks (so a fuzzer that silently mutates nothing would fail here)

def test_unmutated_document_loads_whole(tmp_path):
    scene = load_or_scene_error(fuzz_doc(tmp_path).write(tmp_path))
    assert scene is not None and len(scene.instances) == 4


@pytest.mark.parametrize("kind, path, value, pick, match", [
    ("count", None, 2 ** 31, 0, r"accessors\[0\]"),
    ("index", None, 255, 0, r"index 255 out of range"),
    ("retype", ("nodes", 0, "mesh"), "x", 0, r"nodes\[0\]"),
    ("delete", ("bufferViews", 0, "buffer"), None, 0, r"bufferViews\[0\]"),
    ("rescale", ("accessors", 0, "count"), 1000, 0, r"accessors\[0\]"),
])
def test_mutations_reach_the_loaders_checks(tmp_path, kind, path, value, pick, match):
    g = fuzz_doc(tmp_path)
    apply(g, kind, path, value, pick)
    with pytest.raises(SceneError, match=match):
        load_gltf(g.write(tmp_path))


@pytest.mark.parametrize("key, value, why", [
    ("scale", [0, 0, 0], "singular"), ("scale", [0, 1, 1], "singular"),
    ("matrix", [0] * 16, "not affine"), ("translation", [1e30, 0, 0], "reaches 1e+30")])
def test_degenerate_node_is_skipped_with_a_warning(tmp_path, capsys, key, value, why):
    g = fuzz_doc(tmp_path)
    g.doc["nodes"][-1][key] = value
    if key == "matrix":
        for k in ("rotation", "scale"):
            g.doc["nodes"][-1].pop(k)
    scene = load_or_scene_error(g.write(tmp_path))
    assert scene is not None and len(scene.instances) == 3
    err = capsys.readouterr().err
    node = f"nodes[{len(g.doc['nodes']) - 1}]"
    assert f"rfw: warning: {tmp_path / 'scene.gltf'}: instance '{node}' skipped: " in err
    assert why in err


def test_mirrored_node_is_kept_with_a_negative_determinant(tmp_path):
    scene = load_or_scene_error(fuzz_doc(tmp_path).write(tmp_path))
    dets = [float(np.linalg.det(i.transform[:3, :3])) for i in scene.instances]
    assert sum(d < 0 for d in dets) == 1


def test_all_nodes_degenerate_is_an_empty_scene_with_a_warning(tmp_path, capsys):
    # as an empty scene is (rfw.scene.model.Scene.drawable): drawn as the background only
    g = fuzz_doc(tmp_path)
    for node in g.doc["nodes"]:
        node.pop("matrix", None)
        node["scale"] = [0, 0, 0]
    scene = load_gltf(g.write(tmp_path))
    assert scene.instances == []
    assert "scene.gltf: nothing is drawable" in capsys.readouterr().err
