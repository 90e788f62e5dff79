"""The bad-input corpus: every case is input a user can give rfw, built in a scratch folder.

A ``Case`` lists the files to write (relative to the working folder), the command line after
``rfw``, and the words its one error line must contain (the file and the element: pass, slot,
key, line). ``ACCEPTED`` lists inputs that are valid by design and must render (exit 0).
Nothing here runs rfw; tests/cli/test_bad_input_corpus.py does.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FORWARD = str(ROOT / "configs" / "forward.toml")
DEFERRED = str(ROOT / "configs" / "deferred.toml")
SSAO = str(ROOT / "configs" / "deferred_ssao_shadows.toml")
RAPTOR = ROOT / "tests" / "data" / "raptor" / "chapter4_graph.json"
GRAPH_TOML = ROOT / "tests" / "data" / "three_ways" / "deferred.toml"
SMALL = ("--size", "32x18", "--frames", "1")


@dataclass(frozen=True)
class Case:
    id: str
    argv: tuple[str, ...]  # after "rfw"; run cases get --out out (and a small size) added
    files: dict[str, bytes] = field(default_factory=dict)
    needles: tuple[str, ...] = ()  # each must appear in the error line
    setup: Callable[[Path], None] | None = None  # more preparation in the working folder
    env: dict[str, str] = field(default_factory=dict)
    area: str = ""  # the product area that owns the behaviour (for the report)

    @property
    def out(self) -> str | None:
        """The --out folder (relative to the working folder), or None for commands without."""
        if "--out" in self.argv:
            return self.argv[self.argv.index("--out") + 1]
        return "out" if self.argv[0] == "run" else None

    def command(self) -> list[str]:
        argv = list(self.argv)
        if argv[0] == "run":
            for flag, value in (("--size", "32x18"), ("--frames", "1"), ("--out", "out")):
                if flag not in argv:
                    argv += [flag, value]
        return argv


def _b(text: str | bytes) -> bytes:
    return text if isinstance(text, bytes) else text.encode("utf-8")


# ---------------------------------------------------------------------------------------------
# scenes: glTF


def _triangle_bin() -> bytes:
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    return pos + idx


def gltf_doc(**changes: object) -> dict:
    """A valid one-triangle glTF with an embedded buffer; ``changes`` replace top-level keys."""
    data = _triangle_bin()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64,"
                            + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    }
    doc.update(changes)
    return doc


def _edit(path: str, value: object) -> dict:
    """A valid document with the element at ``path`` (``nodes.0.mesh``) replaced; the value
    ``DELETE`` removes it."""
    doc = gltf_doc()
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = doc
    for k in keys[:-1]:
        node = node[k]
    if value is DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return doc


DELETE = object()


def glb(doc: dict | bytes, bin_chunk: bytes | None = None, *, version: int = 2,
        length: int | None = None, json_kind: bytes = b"JSON") -> bytes:
    text = doc if isinstance(doc, bytes) else json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I4s", len(text), json_kind) + text
    if bin_chunk is not None:
        bin_chunk += b"\0" * (-len(bin_chunk) % 4)
        body += struct.pack("<I4s", len(bin_chunk), b"BIN\0") + bin_chunk
    total = 12 + len(body) if length is None else length
    return struct.pack("<4sII", b"glTF", version, total) + body


def _glb_doc() -> dict:
    data = _triangle_bin()
    doc = gltf_doc()
    doc["buffers"] = [{"byteLength": len(data)}]
    return doc


def anim_doc(times: list[float], values: list[list[float]], *, sampler: int = 0,
             output: int = 3) -> dict:
    """The triangle's node moved by one translation channel, its keyframes in a second
    (embedded) buffer."""
    data = struct.pack(f"<{len(times)}f", *times)
    data += struct.pack(f"<{3 * len(values)}f", *(x for v in values for x in v))
    doc = gltf_doc()
    doc["buffers"].append({"byteLength": len(data), "uri": "data:application/octet-stream;"
                           "base64," + base64.b64encode(data).decode()})
    doc["bufferViews"] += [{"buffer": 1, "byteOffset": 0, "byteLength": 4 * len(times)},
                           {"buffer": 1, "byteOffset": 4 * len(times),
                            "byteLength": 12 * len(values)}]
    doc["accessors"] += [{"bufferView": 2, "componentType": 5126, "count": len(times),
                          "type": "SCALAR"},
                         {"bufferView": 3, "componentType": 5126, "count": len(values),
                          "type": "VEC3"}]
    doc["animations"] = [{"name": "slide", "samplers": [{"input": 2, "output": output}],
                          "channels": [{"sampler": sampler,
                                        "target": {"node": 0, "path": "translation"}}]}]
    return doc


TRI_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
NAN_BIN = struct.pack("<9f", float("nan"), 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 2) \
    + b"\0\0"

# (id, document or raw bytes, element named in the line)
GLTF_CASES: list[tuple[str, object, str]] = [
    ("empty", b"", "JSON"),
    ("not-json", b"hello, world\n", "JSON"),
    ("truncated-json", json.dumps(gltf_doc()).encode()[:200], "JSON"),
    ("top-level-list", b"[1, 2, 3]", "JSON"),
    ("invalid-utf8", b'{"asset": {"version": "2.0\xff\xfe"}}', "JSON"),
    ("nan-literal", json.dumps(gltf_doc()).replace('"scene": 0', '"scene": NaN').encode(),
     "JSON"),
    ("no-asset", _edit("asset", DELETE), "asset"),
    ("version-1", _edit("asset.version", "1.0"), "asset"),
    ("version-number", _edit("asset.version", 2), "asset"),
    ("scene-out-of-range", _edit("scene", 5), "scene"),
    ("scene-is-string", _edit("scene", "main"), "scene"),
    ("root-node-out-of-range", _edit("scenes.0.nodes", [7]), "scenes[0].nodes[0]"),
    ("nodes-is-object", _edit("nodes", {"mesh": 0}), "nodes"),
    ("node-mesh-out-of-range", _edit("nodes.0.mesh", 3), "nodes[0].mesh"),
    ("node-mesh-is-string", _edit("nodes.0.mesh", "zero"), "mesh"),
    ("translation-two-numbers", _edit("nodes.0.translation", [1, 2]), "nodes[0]"),
    ("translation-strings", _edit("nodes.0.translation", ["a", "b", "c"]), "nodes[0]"),
    ("translation-huge", _edit("nodes.0.translation", [1e400, 0, 0]), "JSON"),
    ("rotation-zero", _edit("nodes.0.rotation", [0, 0, 0, 0]), "nodes[0]"),
    ("matrix-15", _edit("nodes.0.matrix", [1.0] * 15), "nodes[0]"),
    ("node-cycle", _edit("nodes.0.children", [0]), "nodes[0]"),
    ("mesh-no-primitives", _edit("meshes.0.primitives", []), "meshes[0]"),
    ("primitives-is-null", _edit("meshes.0.primitives", None), "meshes[0]"),
    ("mode-unknown", _edit("meshes.0.primitives.0.mode", 7), "meshes[0].primitives[0]"),
    ("mode-string", _edit("meshes.0.primitives.0.mode", "triangles"), "mode"),
    ("no-position", _edit("meshes.0.primitives.0.attributes", {}), "meshes[0].primitives[0]"),
    ("position-out-of-range", _edit("meshes.0.primitives.0.attributes", {"POSITION": 9}),
     "POSITION"),
    ("position-vec2", _edit("accessors.0.type", "VEC2"), "POSITION"),
    ("component-type-bogus", _edit("accessors.0.componentType", 9999), "accessors[0]"),
    ("accessor-count-too-big", _edit("accessors.0.count", 300), "accessors[0]"),
    ("accessor-count-negative", _edit("accessors.0.count", -3), "accessors[0]"),
    ("accessor-count-huge", _edit("accessors.0.count", 10 ** 15), "accessors[0]"),
    ("view-offset-past-buffer", _edit("bufferViews.0.byteOffset", 4096), "bufferViews[0]"),
    ("view-buffer-out-of-range", _edit("bufferViews.0.buffer", 4), "bufferViews[0]"),
    ("buffer-missing-file", _edit("buffers.0.uri", "missing.bin"), "buffers[0]"),
    ("buffer-uri-escapes", _edit("buffers.0.uri", "../../../etc/passwd"), "buffers[0]"),
    ("buffer-uri-absolute", _edit("buffers.0.uri", "/etc/passwd"), "buffers[0]"),
    ("buffer-uri-http", _edit("buffers.0.uri", "http://example.com/a.bin"), "buffers[0]"),
    ("buffer-bad-base64", _edit("buffers.0.uri", "data:application/octet-stream;base64,@@@"),
     "buffers[0]"),
    ("buffer-too-short", _edit("buffers.0.byteLength", 4000), "buffers[0]"),
    ("buffer-length-zero", _edit("buffers.0.byteLength", 0), "buffers[0]"),
    ("index-out-of-range", gltf_doc(buffers=[{
        "byteLength": 44, "uri": "data:application/octet-stream;base64," + base64.b64encode(
            struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 9)
            + b"\0\0").decode()}]), "indices"),
    ("indices-float", _edit("accessors.1.componentType", 5126), "indices"),
    ("nan-position", gltf_doc(buffers=[{
        "byteLength": 44, "uri": "data:application/octet-stream;base64,"
        + base64.b64encode(NAN_BIN).decode()}]), "POSITION"),
    ("material-out-of-range", _edit("meshes.0.primitives.0.material", 4), "material"),
    ("required-extension", gltf_doc(extensionsRequired=["KHR_texture_basisu"],
                                    extensionsUsed=["KHR_texture_basisu"]),
     "extensionsRequired"),
    ("camera-out-of-range", _edit("nodes.0.camera", 2), "camera"),
    ("camera-yfov-zero", gltf_doc(nodes=[{"mesh": 0}, {"camera": 0}], scenes=[{"nodes": [0, 1]}],
                                  cameras=[{"type": "perspective",
                                            "perspective": {"yfov": 0, "znear": 0.1}}]),
     "cameras[0]"),
    ("light-bad-type", gltf_doc(
        nodes=[{"mesh": 0, "extensions": {"KHR_lights_punctual": {"light": 0}}}],
        extensionsUsed=["KHR_lights_punctual"],
        extensions={"KHR_lights_punctual": {"lights": [{"type": "laser"}]}}), "light"),
    ("light-out-of-range", gltf_doc(
        nodes=[{"mesh": 0, "extensions": {"KHR_lights_punctual": {"light": 3}}}],
        extensionsUsed=["KHR_lights_punctual"],
        extensions={"KHR_lights_punctual": {"lights": []}}), "light"),
    ("texture-image-missing", gltf_doc(
        meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        textures=[{"source": 0}], images=[{"uri": "nope.png"}]), "images[0]"),
    ("texture-image-garbage", gltf_doc(
        meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        textures=[{"source": 0}],
        images=[{"uri": "data:image/png;base64," + base64.b64encode(b"not a png").decode()}]),
     "images[0]"),
    # node animations: each line names the animation
    ("animation-sampler-out-of-range", anim_doc([0, 1], [[0, 0, 0], [1, 0, 0]], sampler=2),
     'animations[0] ("slide").channels[0]'),
    ("animation-accessor-out-of-range", anim_doc([0, 1], [[0, 0, 0], [1, 0, 0]], output=9),
     'output of animations[0] ("slide").samplers[0]'),
    ("animation-count-mismatch", anim_doc([0, 1, 2], [[0, 0, 0], [1, 0, 0]]),
     'animations[0] ("slide").samplers[0]'),
    ("animation-times-not-increasing", anim_doc([0, 2, 1], [[0, 0, 0]] * 3),
     'animations[0] ("slide").samplers[0]'),
    ("animation-nan", anim_doc([0, 1], [[0, 0, 0], [float("nan"), 0, 0]]),
     'animations[0] ("slide").samplers[0]'),
]

GLB_CASES: list[tuple[str, bytes, str]] = [
    ("header-truncated", b"glTF\x02\0", "GLB"),
    ("version-1", glb(_glb_doc(), _triangle_bin(), version=1), "GLB"),
    ("length-past-end", glb(_glb_doc(), _triangle_bin(), length=10_000), "GLB"),
    ("first-chunk-bin", glb(_glb_doc(), _triangle_bin(), json_kind=b"BIN\0"), "GLB"),
    ("no-bin-chunk", glb(_glb_doc()), "buffers[0]"),
    ("bin-chunk-short", glb(_glb_doc(), _triangle_bin()[:20]), "buffers[0]"),
    ("json-chunk-garbage", glb(b"{{{{", _triangle_bin()), "JSON"),
    ("cut-in-half", glb(_glb_doc(), _triangle_bin())[:60], "GLB"),
]

# (id, file name, bytes, words of the line besides the file name)
MESH_CASES: list[tuple[str, str, bytes, tuple[str, ...]]] = [
    ("obj-empty", "m.obj", b"", ()),
    # vertices only: a point cloud, drawn (tests/scene/test_strokes.py); no vertices either
    ("obj-no-faces", "m.obj", b"vn 0 0 1\nvt 0 0\n", ("triangle",)),
    ("obj-face-out-of-range", "m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", ()),
    ("obj-nan-vertex", "m.obj", b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ()),
    ("obj-garbage", "m.obj", bytes(range(256)) * 8, ()),
    ("ply-empty", "m.ply", b"", ()),
    ("ply-header-only", "m.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", ()),
    ("ply-binary-truncated", "m.ply",
     b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
     b"property float y\nproperty float z\nelement face 1\nproperty list uchar int "
     b"vertex_indices\nend_header\n" + struct.pack("<4f", 0, 0, 0, 1), ()),
    ("ply-inf-vertex", "m.ply",
     b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
     b"inf 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ()),
    ("stl-empty", "m.stl", b"", ()),
    ("stl-binary-truncated", "m.stl", b"\0" * 80 + struct.pack("<I", 100) + b"\0" * 50, ()),
    ("stl-ascii-garbage", "m.stl", b"solid x\nfacet normal banana\nendsolid\n", ()),
    ("off-empty", "m.off", b"", ()),
    ("off-wrong-counts", "m.off", b"OFF\n10 10 0\n0 0 0\n", ()),
    ("off-face-out-of-range", "m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", ()),
    ("off-text-junk", "m.off", b"OFF\nthree one zero\n", ()),
]


def _mkdir(rel: str) -> Callable[[Path], None]:
    return lambda cwd: (cwd / rel).mkdir(parents=True, exist_ok=True)


def _symlink(rel: str, target: str) -> Callable[[Path], None]:
    return lambda cwd: os.symlink(target, cwd / rel)


def scene_cases() -> list[Case]:
    cases = []
    for name, doc, element in GLTF_CASES:
        data = doc if isinstance(doc, bytes) else json.dumps(doc).encode()
        cases.append(Case(f"gltf-{name}", ("run", "--scene", "bad.gltf"),
                          {"bad.gltf": data}, ("bad.gltf", element), area="scene/gltf"))
    for name, data, element in GLB_CASES:
        cases.append(Case(f"glb-{name}", ("run", "--scene", "bad.glb"), {"bad.glb": data},
                          ("bad.glb", element), area="scene/gltf"))
    for name, fname, data, words in MESH_CASES:
        cases.append(Case(f"mesh-{name}", ("run", "--scene", fname), {fname: data},
                          (fname, *words), area="scene/meshfile"))
    tri = json.dumps(gltf_doc()).encode()
    cases += [
        Case("scene-missing-glb", ("run", "--scene", "nope.glb"), needles=("nope.glb",),
             area="scene"),
        Case("scene-missing-obj", ("run", "--scene", "nope.obj"), needles=("nope.obj",),
             area="scene"),
        Case("scene-is-directory", ("run", "--scene", "dir.gltf"), setup=_mkdir("dir.gltf"),
             needles=("dir.gltf",), area="scene"),
        Case("scene-obj-is-directory", ("run", "--scene", "dir.obj"), setup=_mkdir("dir.obj"),
             needles=("dir.obj",), area="scene"),
        Case("scene-wrong-extension", ("run", "--scene", "scene.txt"), {"scene.txt": tri},
             ("scene.txt", ".txt"), area="scene"),
        Case("scene-no-extension", ("run", "--scene", "scene"), {"scene": tri}, ("scene",),
             area="scene"),
        Case("scene-obj-text-as-gltf", ("run", "--scene", "s.gltf"),
             {"s.gltf": TRI_OBJ}, ("s.gltf", "JSON"),
             area="scene/gltf"),
        Case("scene-png-as-glb", ("run", "--scene", "s.glb"),
             {"s.glb": b"\x89PNG\r\n\x1a\n" + b"\0" * 64}, ("s.glb",), area="scene/gltf"),
        Case("scene-dangling-symlink", ("run", "--scene", "link.glb"),
             setup=_symlink("link.glb", "gone.glb"), needles=("link.glb",), area="scene"),
        Case("scene-dev-null-obj", ("run", "--scene", "null.obj"),
             setup=_symlink("null.obj", "/dev/null"), needles=("null.obj",),
             area="scene/meshfile"),
    ]
    return cases


# ---------------------------------------------------------------------------------------------
# configs


BASE = """name = "corpus"
scene = "default"
size = [32, 18]
outputs = ["tonemap.ldr"]

[[pass]]
name = "shadow"
use = "shadow_map"
enabled = false

[[pass]]
name = "forward"
inputs = { shadow = "shadow.depth" }

[[pass]]
name = "tonemap"
inputs = { hdr = "forward.hdr" }
"""


def _cfg(id: str, text: str | bytes, *needles: str, args: tuple[str, ...] = (),
         area: str = "config") -> Case:
    return Case(f"config-{id}", ("run", "c.toml", *args), {"c.toml": _b(text)},
                ("c.toml", *needles), area=area)


def _top(key_line: str) -> str:
    # a top-level key must precede the first table
    return key_line + "\n" + BASE


def _tonemap(settings: str) -> str:
    return BASE.replace('inputs = { hdr = "forward.hdr" }',
                        f'inputs = {{ hdr = "forward.hdr" }}\nsettings = {{ {settings} }}')


def _rename(old: str, new: str) -> str:
    """BASE with pass ``old`` renamed (its readers and the output follow); ``use`` keeps the
    pass id, so the name is the only thing wrong."""
    text = BASE.replace(f'name = "{old}"', f'name = {json.dumps(new)}\nuse = "{old}"')
    return text.replace(f'"{old}.', f'{json.dumps(new)[:-1]}.')


def config_cases() -> list[Case]:
    b = BASE
    return [
        _cfg("malformed-toml", "name = \n" + b, "line 1"),
        _cfg("malformed-toml-later-line", b + "\n[[pass]\nname = 'x'\n", "line 19"),
        _cfg("duplicate-key", b.replace('name = "corpus"', 'name = "a"\nname = "b"'), "line 2"),
        _cfg("invalid-utf8", b.encode() + b"# caf\xe9\n", "UTF-8"),
        _cfg("invalid-utf8-in-string", b.replace("corpus", "c\udcff").encode(
            "utf-8", "surrogateescape"), "UTF-8"),
        _cfg("empty", "", "pass"),
        _cfg("binary-garbage", bytes(range(1, 256)), "UTF-8"),
        _cfg("unknown-key", _top('sceen = "default"'), "sceen"),
        _cfg("unknown-pass-key", b.replace('name = "forward"', 'name = "forward"\ninptus = {}'),
             "forward", "inptus"),
        _cfg("size-string", b.replace("size = [32, 18]", 'size = "big"'), "size"),
        _cfg("size-zero", b.replace("size = [32, 18]", "size = [0, 18]"), "size"),
        _cfg("size-float", b.replace("size = [32, 18]", "size = [32.5, 18]"), "size"),
        _cfg("size-huge", b.replace("size = [32, 18]", "size = [1000000, 1000000]"), "size"),
        _cfg("size-three", b.replace("size = [32, 18]", "size = [32, 18, 2]"), "size"),
        _cfg("frames-string", _top('frames = "two"'), "frames"),
        _cfg("frames-negative", _top("frames = -2"), "frames", args=("--frames", "1")),
        _cfg("frames-inf", _top("frames = inf"), "frames"),
        _cfg("frames-huge", _top("frames = 99999999999999999"), "frames"),
        _cfg("async-compute-word", _top('async_compute = "sometimes"'), "async_compute"),
        _cfg("async-compute-int", _top("async_compute = 2"), "async_compute"),
        _cfg("async-compute-table", _top("async_compute = { on = true }"), "async_compute"),
        _cfg("name-table", _top("name = { a = 1 }").replace('name = "corpus"\n', ""), "name"),
        _cfg("scene-int", b.replace('scene = "default"', "scene = 5"), "scene"),
        _cfg("scene-missing-file", b.replace('scene = "default"', 'scene = "nope.glb"'),
             "scene", "nope.glb", area="config/scene"),
        _cfg("camera-int", _top("camera = 5"), "camera"),
        _cfg("camera-unknown-key", b + "\n[camera]\npositon = [1, 2, 3]\n", "positon"),
        _cfg("camera-position-string", b + '\n[camera]\nposition = "x"\n', "position"),
        _cfg("camera-position-inf", b + "\n[camera]\nposition = [inf, 0, 0]\n", "position"),
        _cfg("camera-yfov-nan", b + "\n[camera]\nyfov = nan\n", "yfov"),
        _cfg("camera-yfov-zero", b + "\n[camera]\nyfov = 0\n", "yfov"),
        _cfg("camera-znear-negative", b + "\n[camera]\nznear = -1.0\n", "znear"),
        _cfg("outputs-string", b.replace('outputs = ["tonemap.ldr"]', 'outputs = "tonemap.ldr"'),
             "outputs"),
        _cfg("outputs-unknown", b.replace('outputs = ["tonemap.ldr"]', 'outputs = ["tonemap.hdr"]'),
             "tonemap.hdr"),
        _cfg("outputs-int", b.replace('outputs = ["tonemap.ldr"]', "outputs = [5]"), "outputs"),
        # without outputs every pass is culled: once a traceback from a zero-query set
        _cfg("outputs-none", b.replace('outputs = ["tonemap.ldr"]\n', ""), "outputs",
             "tonemap.ldr"),
        _cfg("outputs-empty", b.replace('outputs = ["tonemap.ldr"]', "outputs = []"), "outputs"),
        _cfg("outputs-escape", b.replace('outputs = ["tonemap.ldr"]',
                                         'outputs = ["tonemap.ldr/../../../x"]'), "outputs"),
        _cfg("pass-is-int", _top("pass = 5").replace(b, "") + 'name = "x"\n', "pass"),
        _cfg("pass-name-missing", b.replace('name = "forward"\n', ""), "#2"),
        _cfg("pass-name-int", b.replace('name = "forward"', "name = 5"), "#2"),
        _cfg("pass-name-dotdot", _rename("tonemap", "../../x"), "../../x", area="identifiers"),
        _cfg("pass-name-absolute", _rename("tonemap", "/tmp/abs/x"), "/tmp/abs/x",
             area="identifiers"),
        _cfg("pass-name-slash", _rename("tonemap", "a/b"), "a/b", area="identifiers"),
        _cfg("pass-name-control", _rename("tonemap", "tone\u0001map"), "tone\\x01map",
             area="identifiers"),
        _cfg("pass-name-newline", _rename("tonemap", "tone\nmap"), "tone\\nmap",
             area="identifiers"),
        _cfg("pass-name-empty", _rename("forward", ""), "name", area="identifiers"),
        _cfg("pass-name-duplicate", b + '\n[[pass]]\nname = "tonemap"\ninputs = { hdr = '
             '"forward.hdr" }\n', "tonemap", area="graph"),
        _cfg("use-unknown", b.replace('use = "shadow_map"', 'use = "shadow_mapp"'),
             "shadow_mapp", area="graph"),
        _cfg("use-int", b.replace('use = "shadow_map"', "use = 7"), "use"),
        _cfg("enabled-string", b.replace("enabled = false", 'enabled = "yes"'), "enabled"),
        _cfg("backend-unknown", b.replace('name = "forward"', 'name = "forward"\nbackend = '
                                          '"metal"'), "forward", "metal"),
        _cfg("inputs-not-table", b.replace('inputs = { hdr = "forward.hdr" }', 'inputs = 5'),
             "tonemap", "inputs"),
        _cfg("input-int", b.replace('inputs = { hdr = "forward.hdr" }', "inputs = { hdr = 5 }"),
             "tonemap", "hdr"),
        _cfg("input-unknown-slot", b.replace('{ hdr = "forward.hdr" }',
                                             '{ hdr = "forward.hdr", hrd = "forward.hdr" }'),
             "tonemap", "hrd"),
        _cfg("input-unknown-pass", b.replace('"forward.hdr"', '"forwrd.hdr"'), "forwrd",
             area="graph"),
        _cfg("input-unknown-resource", b.replace('"forward.hdr"', '"forward.hdx"'),
             "tonemap", "hdx", area="graph"),
        _cfg("input-cycle", b.replace('inputs = { shadow = "shadow.depth" }',
                                      'inputs = { shadow = "tonemap.ldr" }'), "cycle",
             area="graph"),
        _cfg("input-escape", b.replace('"forward.hdr"', '"../../forward.hdr"'), "tonemap",
             area="identifiers"),
        _cfg("settings-not-table", _tonemap("").replace("settings = {  }", "settings = 3"),
             "tonemap", "settings"),
        _cfg("setting-unknown", _tonemap("exposur = 1.0"), "tonemap", "exposur"),
        _cfg("setting-nan", _tonemap("exposure = nan"), "tonemap", "exposure"),
        _cfg("setting-inf", _tonemap("exposure = inf"), "tonemap", "exposure"),
        _cfg("setting-negative-inf", _tonemap("exposure = -inf"), "tonemap", "exposure"),
        _cfg("setting-string", _tonemap('exposure = "bright"'), "tonemap", "exposure"),
        _cfg("setting-table", _tonemap("exposure = { a = 1 }"), "tonemap", "exposure"),
        _cfg("setting-bool-for-int", _tonemap("curve = true"), "tonemap", "curve"),
        _cfg("setting-float-for-int", _tonemap("curve = 1.5"), "tonemap", "curve"),
        _cfg("setting-int-huge", b.replace("enabled = false", "enabled = true\nsettings = { "
                                           "resolution = 99999999999999 }"),
             "shadow", "resolution"),
        _cfg("setting-int-negative", b.replace("enabled = false", "enabled = true\nsettings = "
                                               "{ resolution = -4 }"),
             "shadow", "resolution"),
        _cfg("variants-int", b + "\n[variants]\nx = 5\n", "x"),
        _cfg("variant-option-int", b + '\n[variants.x]\ndefault = "a"\na = 5\n', "x"),
        _cfg("variant-no-default", b + "\n[variants.x]\na = {}\n", "x", "default"),
        _cfg("variant-default-unknown", b + '\n[variants.x]\ndefault = "c"\na = {}\n', "x",
             "default"),
        _cfg("variant-unknown-pass", b + '\n[variants.x]\ndefault = "a"\na = { "nope.enabled"'
                                         " = true }\n", "nope"),
        _cfg("variant-name-dotdot", b + '\n[variants."../../v"]\ndefault = "a"\na = {}\n',
             "../../v", area="identifiers"),
        _cfg("variant-name-control", b + '\n[variants."v\\u0007"]\ndefault = "a"\na = {}\n',
             "v\\x07", area="identifiers"),
        _cfg("variant-list-unknown", b + '\n[variants.x]\ndefault = "auto"\nauto = ["b"]\n'
                                         "a = {}\n", "x", "auto"),
        _cfg("nested-too-deep", _top("frames = " + "[" * 2000 + "]" * 2000)),  # no position
    ]


def config_path_cases() -> list[Case]:
    return [
        Case("config-missing", ("run", "nope.toml"), needles=("nope.toml",), area="config"),
        Case("config-is-directory", ("run", "conf.toml"), setup=_mkdir("conf.toml"),
             needles=("conf.toml",), area="config"),
        Case("config-dangling-symlink", ("run", "l.toml"), setup=_symlink("l.toml", "x.toml"),
             needles=("l.toml",), area="config"),
        Case("config-is-gltf", ("run", "c.toml"), {"c.toml": json.dumps(gltf_doc()).encode()},
             ("c.toml",), area="config"),
    ]


# ---------------------------------------------------------------------------------------------
# command-line values


def _cli(id: str, *args: str, needles: tuple[str, ...] = (), files: dict | None = None,
         setup: Callable[[Path], None] | None = None, area: str = "cli") -> Case:
    return Case(f"cli-{id}", ("run", FORWARD, *args), files or {}, needles, setup, area=area)


def _file(rel: str, data: bytes = b"x") -> Callable[[Path], None]:
    def make(cwd: Path) -> None:
        (cwd / rel).parent.mkdir(parents=True, exist_ok=True)
        (cwd / rel).write_bytes(data)
    return make


def cli_cases() -> list[Case]:
    return [
        _cli("frames-word", "--frames", "abc", needles=("--frames", "abc")),
        _cli("frames-negative", "--frames", "-2", needles=("--frames",)),
        _cli("frames-zero", "--frames", "0", needles=("--frames",)),
        _cli("frames-float", "--frames", "1.5", needles=("--frames",)),
        _cli("frames-huge", "--frames", "99999999999999999999", needles=("--frames",)),
        _cli("size-zero", "--size", "0x18", needles=("--size",)),
        _cli("size-one-number", "--size", "32", needles=("--size",)),
        _cli("size-letters", "--size", "axb", needles=("--size",)),
        _cli("size-negative", "--size", "-5x5", needles=("--size",)),
        _cli("size-huge", "--size", "100000x100000", needles=("--size",)),
        _cli("size-float", "--size", "32.5x18", needles=("--size",)),
        _cli("backend-unknown", "--backend", "metal", needles=("--backend", "metal")),
        _cli("validate-without-vk", "--validate", needles=("--validate",)),
        _cli("no-alias-without-vk", "--no-alias", needles=("--no-alias",)),
        _cli("unknown-option", "--frobnicate", needles=("--frobnicate",)),
        _cli("set-no-equals", "--set", "tonemap", needles=("--set", "tonemap")),
        _cli("set-empty-key", "--set", "=5", needles=("--set",)),
        _cli("set-unknown-pass", "--set", "tonemapp.exposure=1", needles=("tonemapp",)),
        _cli("set-unknown-setting", "--set", "tonemap.exposur=1", needles=("tonemap", "exposur")),
        _cli("set-nan", "--set", "tonemap.exposure=nan", needles=("tonemap", "exposure")),
        _cli("set-inf", "--set", "tonemap.exposure=inf", needles=("tonemap", "exposure")),
        _cli("set-word-for-float", "--set", "tonemap.exposure=bright",
             needles=("tonemap", "exposure")),
        _cli("set-float-for-int", "--set", "tonemap.curve=0.5", needles=("tonemap", "curve")),
        _cli("set-int-huge", "--set", "shadow.enabled=true", "--set",
             "shadow.resolution=99999999999999", needles=("shadow", "resolution")),
        _cli("set-enabled-maybe", "--set", "shadow.enabled=maybe", needles=("shadow.enabled",)),
        _cli("set-frames-word", "--set", "frames=two", needles=("frames",)),
        _cli("set-frames-negative", "--set", "frames=-1", needles=("frames",)),
        _cli("set-size-zero", "--set", "size=0x0", needles=("size",)),
        _cli("set-scene-missing", "--set", "scene=nope.ply", needles=("nope.ply",),
             area="scene"),
        _cli("set-bare-key", "--set", "exposure=1", needles=("exposure",)),
        _cli("set-input-unknown", "--set", "tonemap.inputs.hdr=nowhere.hdr",
             needles=("tonemap", "nowhere")),
        _cli("set-input-escape", "--set", "tonemap.inputs.hdr=../../x.hdr",
             needles=("tonemap",), area="identifiers"),
        _cli("set-control-char", "--set", "tonemap.exposure=1\x01",
             needles=("tonemap", "exposure")),
        Case("cli-set-variant-unknown-option", ("run", SSAO, "--set", "ao=maybe"),
             needles=("ao", "maybe"), area="config"),
        Case("cli-set-variant-word-for-switch", ("run", SSAO, "--set", "view=sideways"),
             needles=("view", "sideways"), area="config"),
        # --out
        _cli("out-is-a-file", "--out", "afile", setup=_file("afile"), needles=("afile",),
             area="output"),
        _cli("out-under-a-file", "--out", "afile/sub", setup=_file("afile"),
             needles=("afile",), area="output"),
        _cli("out-unwritable", "--out", "/proc/rfw-corpus-out", needles=("/proc/rfw-corpus-out",),
             area="output"),
        _cli("out-empty-string", "--out", "", needles=("--out",), area="output"),
    ]


# ---------------------------------------------------------------------------------------------
# graphs: Raptor JSON and graph TOML through `rfw graph plan`


def _raptor(**changes: object) -> dict:
    doc = json.loads(RAPTOR.read_text())
    doc.update(changes)
    return doc


def _raptor_pass(index: int, **changes: object) -> dict:
    doc = _raptor()
    doc["passes"][index].update(changes)
    return doc


def _raptor_output(index: int, **changes: object) -> dict:
    doc = _raptor()
    doc["passes"][0]["outputs"][index].update(changes)
    return doc


def _gplan(id: str, name: str, data: bytes | dict, *needles: str,
           args: tuple[str, ...] = ()) -> Case:
    blob = json.dumps(data).encode() if isinstance(data, dict) else data
    return Case(f"graph-{id}", ("graph", "plan", name, *args), {name: blob}, (name, *needles),
                area="graph/loaders")


def graph_cases() -> list[Case]:
    toml = GRAPH_TOML.read_text()
    first = _raptor()["passes"][0]["name"]
    return [
        _gplan("json-empty", "g.json", b""),
        _gplan("json-malformed", "g.json", b'{"name": "x", "passes": [', "line 1"),
        _gplan("json-invalid-utf8", "g.json", b'{"name": "\xff", "passes": []}'),
        _gplan("json-top-level-list", "g.json", b"[]"),
        _gplan("json-passes-object", "g.json", _raptor(passes={"a": 1}), "passes"),
        _gplan("json-passes-empty", "g.json", _raptor(passes=[]), "passes"),
        _gplan("json-pass-no-name", "g.json", _raptor_pass(0, name=None), "name"),
        _gplan("json-pass-name-int", "g.json", _raptor_pass(0, name=5), "name"),
        _gplan("json-pass-name-dotdot", "g.json", _raptor_pass(0, name="../../x"), "../../x"),
        _gplan("json-pass-name-newline", "g.json", _raptor_pass(0, name="a\nb"), "a\\nb"),
        _gplan("json-inputs-string", "g.json", _raptor_pass(0, inputs="depth"), first),
        _gplan("json-format-unknown", "g.json", _raptor_output(0, format="VK_FORMAT_BOGUS"),
               first, "VK_FORMAT_BOGUS"),
        _gplan("json-resolution-zero", "g.json", _raptor_output(0, resolution=[0, 0]), first,
               "resolution"),
        _gplan("json-resolution-strings", "g.json", _raptor_output(0, resolution=["a", "b"]),
               first, "resolution"),
        _gplan("json-resolution-huge", "g.json", _raptor_output(0, resolution=[10 ** 9, 10 ** 9]),
               first, "gbuffer_colour"),
        _gplan("json-resolution-nan", "g.json",
               json.dumps(_raptor_output(0, resolution=[1, 1])).replace(
                   '"resolution": [1, 1]', '"resolution": [NaN, 1]').encode(), "resolution"),
        _gplan("json-output-type-unknown", "g.json", _raptor_output(0, type="texturee"), first,
               "texturee"),
        _gplan("json-output-name-dotdot", "g.json", _raptor_output(0, name="../../x"),
               "../../x"),
        _gplan("json-op-unknown", "g.json", _raptor_output(0, op="VK_ATTACHMENT_LOAD_OP_EXPLODE"),
               first, "EXPLODE"),
        _gplan("json-nested-deep", "g.json", b'{"name": "x", "passes": ' + b"[" * 100000
               + b"]" * 100000 + b"}"),
        _gplan("toml-malformed", "g.toml", toml.replace("[[pass]]", "[[pass]", 1).encode(),
               "line"),
        _gplan("toml-invalid-utf8", "g.toml", toml.encode() + b"\n# \xff\n"),
        _gplan("toml-type-unknown", "g.toml", toml.replace('type = "compute"',
                                                           'type = "rasterize"', 1).encode(),
               "lighting", "rasterize"),
        _gplan("toml-format-unknown", "g.toml", toml.replace("VK_FORMAT_R16G16_SFLOAT",
                                                             "VK_FORMAT_NOPE").encode(),
               "gbuffer", "VK_FORMAT_NOPE"),
        _gplan("toml-size-negative", "g.toml", toml.replace("size = [1280, 800]",
                                                            "size = [-1, 800]", 1).encode(),
               "size"),
        _gplan("toml-scale-nan", "g.toml", toml.replace("scale = [0.5, 0.5]",
                                                        "scale = [nan, 0.5]").encode(),
               "bloom", "scale"),
        _gplan("toml-input-from-nowhere", "g.toml", toml.replace('hdr = "lighting.hdr", bloom',
                                                                 'hdr = "lightning.hdr", bloom'
                                                                 ).encode(),
               "tonemap", "lightning"),
        _gplan("toml-unknown-key", "g.toml", toml.replace('type = "compute"',
                                                          'type = "compute"\ncolour = 1',
                                                          1).encode(), "colour"),
        _gplan("toml-pass-name-absolute", "g.toml",
               toml.replace('name = "debug"', 'name = "/abs/debug"').encode(), "/abs/debug"),
        Case("graph-plan-missing", ("graph", "plan", "nope.json"), needles=("nope.json",),
             area="graph/loaders"),
        Case("graph-plan-directory", ("graph", "plan", "d.toml"), setup=_mkdir("d.toml"),
             needles=("d.toml",), area="graph/loaders"),
        Case("graph-plan-unknown-suffix", ("graph", "plan", "g.yaml"), {"g.yaml": b"a: 1\n"},
             ("g.yaml",), area="graph/loaders"),
        Case("graph-plan-size-zero", ("graph", "plan", str(RAPTOR), "--size", "0x0"),
             needles=("--size",), area="cli"),
        Case("graph-plan-output-unknown", ("graph", "plan", str(RAPTOR), "--output", "nothing"),
             needles=("nothing",), area="graph/loaders"),
        Case("graph-dot-out-is-directory", ("graph", "dot", str(RAPTOR), "-o", "d"),
             setup=_mkdir("d"), needles=("d",), area="output"),
        Case("graph-convert-out-under-file", ("graph", "convert", str(RAPTOR), "-o", "f/g.toml"),
             setup=_file("f"), needles=("f/g.toml",), area="output"),
    ]


# ---------------------------------------------------------------------------------------------
# shaders: a third-party pass (found through entry points) with a broken shader


PLUGIN_PY = '''"""A corpus pass: copies its input through a shader the case replaces."""
from rfw import ComputePass, Tex2D, register_pass


@register_pass("corpus_copy")
class CorpusCopyPass(ComputePass):
    shader = "corpus_copy.comp.wgsl"
    inputs = {"src": Tex2D(desc="image")}
    outputs = {"dst": Tex2D("rgba8unorm", size_of="src", desc="copy")}

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("dst"), t_src=ctx.sampled("src"),
                     o_dst=ctx.storage("dst"))
'''

WGSL = """@group(0) @binding(0) var t_src: texture_2d<f32>;
@group(0) @binding(1) var o_dst: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_dst);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    textureStore(o_dst, vec2i(id.xy), textureLoad(t_src, vec2i(id.xy), 0));
}
"""

# the same pass with its GLSL source, which both backends run
PLUGIN_GLSL_PY = PLUGIN_PY.replace("corpus_copy.comp.wgsl", "corpus_copy.comp.glsl")

GLSL = """#version 460
#extension GL_EXT_samplerless_texture_functions : require
layout(local_size_x = 8, local_size_y = 8) in;
layout(set = 0, binding = 0) uniform texture2D t_src;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D o_dst;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_dst)))) {
        return;
    }
    imageStore(o_dst, p, texelFetch(t_src, p, 0));
}
"""

# a small frame both backends run
PLUGIN_CONFIG = """name = "corpus"
scene = "tri.obj"
size = [32, 18]
outputs = ["copy.dst"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", \
emissive = "gbuffer.emissive", depth = "gbuffer.depth" }

[[pass]]
name = "tonemap"
inputs = { hdr = "lighting.hdr" }

[[pass]]
name = "copy"
use = "corpus_copy"
inputs = { src = "tonemap.ldr" }
"""


def plugin_files(wgsl: bytes | None = None, glsl: bytes | None = None,
                 module: str = PLUGIN_PY) -> dict[str, bytes]:
    pkg = "site/rfw_corpus_plugin"
    files = {
        f"{pkg}/__init__.py": b"",
        f"{pkg}/corpus_copy.py": module.encode(),
        "site/rfw_corpus_plugin-0.0.dist-info/METADATA":
            b"Metadata-Version: 2.1\nName: rfw-corpus-plugin\nVersion: 0.0\n",
        "site/rfw_corpus_plugin-0.0.dist-info/entry_points.txt":
            b"[rfw.passes]\ncorpus_copy = rfw_corpus_plugin.corpus_copy\n",
        "c.toml": PLUGIN_CONFIG.encode(),
        "tri.obj": TRI_OBJ,  # beside the config: a small scene keeps the render short
    }
    if wgsl is not None:
        files[f"{pkg}/corpus_copy.comp.wgsl"] = wgsl
    if glsl is not None:
        files[f"{pkg}/corpus_copy.comp.glsl"] = glsl
    return files


PLUGIN_ENV = {"PYTHONPATH": "site"}


def _shader(id: str, *needles: str, wgsl: bytes | None = WGSL.encode(),
            glsl: bytes | None = GLSL.encode(), backend: str = "wgpu",
            module: str = PLUGIN_PY) -> Case:
    return Case(f"shader-{id}", ("run", "c.toml", "--backend", backend),
                plugin_files(wgsl, glsl, module), needles, env=PLUGIN_ENV, area="shaders")


def shader_cases() -> list[Case]:
    w, g = WGSL, GLSL
    wf, gf, copy = "corpus_copy.comp.wgsl", "corpus_copy.comp.glsl", "'copy'"
    return [
        _shader("wgsl-syntax-error", f"{wf}:6", wgsl=w.replace("let size", "let size =").encode()),
        _shader("wgsl-unknown-identifier", f"{wf}:10",
                wgsl=w.replace("textureLoad(t_src", "textureLoad(t_srcc").encode()),
        _shader("wgsl-missing-binding", wf, copy, "t_src",
                wgsl=w.replace("textureLoad(t_src, vec2i(id.xy), 0)", "vec4f(1.0)").replace(
                    "@group(0) @binding(0) var t_src: texture_2d<f32>;\n", "").encode()),
        _shader("wgsl-extra-binding", wf, copy, "u_extra",
                wgsl=w.replace("@compute", "@group(0) @binding(2) var<uniform> u_extra: vec4f;"
                               "\n\n@compute").replace(
                    "textureLoad(t_src, vec2i(id.xy), 0)",
                    "textureLoad(t_src, vec2i(id.xy), 0) + u_extra").encode()),
        _shader("wgsl-wrong-storage-format", wf, copy, "o_dst",
                wgsl=w.replace("rgba8unorm", "rgba16float").encode()),
        _shader("wgsl-no-entry-point", wf,
                wgsl=w.replace("@compute @workgroup_size(8, 8)\nfn main", "fn main").encode()),
        _shader("wgsl-empty", wf, copy, wgsl=b""),
        _shader("wgsl-invalid-utf8", f"{wf}:12", wgsl=w.encode() + b"// \xff\xfe\n"),
        _shader("wgsl-missing-file", wf, copy, wgsl=None),
        _shader("wgsl-include-missing", f"{wf}:1", "nope.wgsl",
                wgsl=('#include "nope.wgsl"\n' + w).encode()),
        _shader("plugin-import-error", "corpus_copy", module="import nonexistent_module_xyz\n"),
        _shader("plugin-syntax-error", "corpus_copy", module="def broken(:\n"),
        _shader("wgsl-on-vk", wf, copy, "only --backend wgpu runs", backend="vk"),
        *(c for b in ("vk", "wgpu") for c in _glsl_cases(b, g, gf, copy)),
    ]


def _glsl_cases(backend: str, g: str, gf: str, copy: str) -> list[Case]:
    """The GLSL source's errors, the same one line on either backend (file and line)."""
    tail = "" if backend == "vk" else "-wgpu"
    kw = {"backend": backend, "module": PLUGIN_GLSL_PY, "wgsl": None}
    return [
        _shader(f"glsl-syntax-error{tail}", f"{gf}:8",
                glsl=g.replace("ivec2 p =", "ivec2 p = =").encode(), **kw),
        _shader(f"glsl-missing-binding{tail}", gf, copy, "t_src",
                glsl=g.replace("layout(set = 0, binding = 0) uniform texture2D t_src;\n",
                               "").replace("texelFetch(t_src, p, 0)", "vec4(1.0)").encode(),
                **kw),
        _shader(f"glsl-wrong-storage-format{tail}", gf, copy, "o_dst",
                glsl=g.replace("rgba8)", "rgba16f)").encode(), **kw),
        _shader(f"glsl-invalid-utf8{tail}", f"{gf}:14", glsl=g.encode() + b"// \xff\xfe\n",
                **kw),
        _shader(f"glsl-missing-file{tail}", gf, copy, glsl=None, **kw),
    ]


# ---------------------------------------------------------------------------------------------
# the other commands: view, new-pass, meshlets, scenes, bench


def _other(id: str, argv: tuple[str, ...], *needles: str, area: str,
           files: dict[str, bytes] | None = None,
           setup: Callable[[Path], None] | None = None) -> Case:
    return Case(id, argv, files or {}, needles, setup, area=area)


def other_cases() -> list[Case]:
    shot = ("--screenshot", "s.png")
    bench = ("--frames", "1", "--warmup", "0", "--repeat", "1", "--size", "32x18", "--out", "b")
    return [
        _other("view-missing-scene", ("view", FORWARD, "--scene", "nope.glb", "--frames", "1"),
               "nope.glb", area="view"),
        _other("view-malformed-config", ("view", "c.toml", "--frames", "1"), "c.toml",
               "line 1", files={"c.toml": b"name = \n"}, area="view"),
        _other("view-frames-negative", ("view", FORWARD, "--frames", "-1"), "--frames",
               area="view"),
        _other("new-pass-dotdot", ("new-pass", "../../evil", "--dir", "passes"), "../../evil",
               area="new-pass"),
        _other("new-pass-absolute", ("new-pass", "/tmp/rfw-corpus-evil"), "/tmp/rfw-corpus-evil",
               area="new-pass"),
        _other("new-pass-capitals", ("new-pass", "BadName", "--dir", "p"), "BadName",
               area="new-pass"),
        _other("new-pass-keyword", ("new-pass", "class", "--dir", "p"), "class", area="new-pass"),
        _other("new-pass-exists", ("new-pass", "mine", "--dir", "p"), "mine",
               setup=_mkdir("p/mine"), area="new-pass"),
        _other("new-pass-dir-is-a-file", ("new-pass", "mine", "--dir", "afile"), "afile",
               setup=_file("afile"), area="new-pass"),
        _other("meshlets-missing-mesh", ("meshlets", "show", "nope.obj", *shot), "nope.obj",
               area="meshlets"),
        _other("meshlets-broken-mesh", ("meshlets", "show", "m.ply", *shot), "m.ply",
               files={"m.ply": b"ply\nformat ascii 1.0\n"}, area="meshlets"),
        _other("meshlets-default-unknown-part", ("meshlets", "show", "default:nothing", *shot),
               "nothing", area="meshlets"),
        _other("meshlets-max-triangles-odd", ("meshlets", "show", "default", "--max-triangles",
                                              "7", *shot), "--max-triangles", area="meshlets"),
        _other("meshlets-max-vertices-zero", ("meshlets", "show", "default", "--max-vertices",
                                              "0", *shot), "--max-vertices", area="meshlets"),
        _other("meshlets-cone-weight-nan", ("meshlets", "show", "default", "--cone-weight",
                                            "nan", *shot), "--cone-weight", area="meshlets"),
        _other("meshlets-screenshot-in-missing-folder", ("meshlets", "show", "m.obj",
                                                         "--screenshot", "afile/s.png"),
               "afile/s.png", files={"m.obj": TRI_OBJ}, setup=_file("afile"), area="meshlets"),
        _other("scenes-fetch-unknown", ("scenes", "fetch", "no_such_scene"), "no_such_scene",
               area="scenes"),
        _other("bench-missing-config", ("bench", "nope.toml", *bench), "nope.toml",
               area="bench"),
        # a built-in scene's bad count fails before any run (it once failed every run, exit 1)
        _other("bench-stress-count", ("bench", FORWARD, *bench, "--scene", "stress:x"),
               "stress:x", "instance count", area="bench"),
        _other("run-stress-count", ("run", FORWARD, "--scene", "stress:0"), "stress:0",
               "instance count", area="scene"),
        _other("bench-malformed-config", ("bench", "c.toml", *bench), "c.toml", "line 1",
               files={"c.toml": b"name = \n"}, area="bench"),
        _other("bench-frames-zero", ("bench", FORWARD, *bench, "--frames", "0"), "--frames",
               area="bench"),
        _other("bench-repeat-zero", ("bench", FORWARD, *bench, "--repeat", "0"), "--repeat",
               area="bench"),
        _other("bench-timeout-nan", ("bench", FORWARD, *bench, "--timeout", "nan"),
               "--timeout", area="bench"),
        _other("bench-vary-malformed", ("bench", FORWARD, *bench, "--vary", "nokey"), "nokey",
               area="bench"),
        _other("bench-set-unknown-pass", ("bench", FORWARD, *bench, "--set", "nopass.x=1"),
               "nopass", area="bench"),
        _other("bench-compare-missing", ("bench", "compare", "old", "new"), "old",
               area="bench"),
    ]


def all_cases() -> list[Case]:
    return [*scene_cases(), *config_cases(), *config_path_cases(), *cli_cases(),
            *graph_cases(), *shader_cases(), *other_cases()]


# ---------------------------------------------------------------------------------------------
# accepted by design: these render (exit 0)


def _node_scene(**node: object) -> bytes:
    doc = gltf_doc(nodes=[{"mesh": 0}, {"mesh": 0, **node}], scenes=[{"nodes": [0, 1]}])
    return json.dumps(doc).encode()


def _truncate_one(folder: str) -> Callable[[Path], None]:
    """Cut the first cache entry (by name) under ``folder`` to a third: one damaged entry."""
    def cut(root: Path) -> None:
        entry = min(p for p in (root / folder).rglob("*") if p.is_file())
        entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 3])
    return cut


def _scratch(rel: str, data: bytes) -> Callable[[Path], None]:
    """Write ``data`` at ``rel`` under the scratch root (cache/, home/)."""
    def write(root: Path) -> None:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return write


@dataclass(frozen=True)
class Accepted:
    id: str
    argv: tuple[str, ...]
    files: dict[str, bytes] = field(default_factory=dict)
    warm: tuple[str, ...] = ()  # a first run (fills caches) before ``damage``
    damage: Callable[[Path], None] | None = None  # given the scratch root (cache/, home/)
    warning: bool = False  # a one-line "rfw: warning:" is expected on stderr
    env: dict[str, str] = field(default_factory=dict)

    def command(self) -> list[str]:
        return [*self.argv, *SMALL, "--out", "out"] if self.argv[0] == "run" else list(self.argv)


ACCEPTED = [
    # the corpus pass unbroken: the shader cases are only meaningful if this renders
    # the plugin's one GLSL source on both backends, and a WGSL-only plugin on wgpu
    Accepted("plugin-pass-wgpu", ("run", "c.toml", "--backend", "wgpu"),
             plugin_files(None, GLSL.encode(), PLUGIN_GLSL_PY), env=PLUGIN_ENV),
    Accepted("plugin-pass-vk", ("run", "c.toml", "--backend", "vk"),
             plugin_files(None, GLSL.encode(), PLUGIN_GLSL_PY), env=PLUGIN_ENV),
    Accepted("plugin-pass-wgsl-wgpu", ("run", "c.toml", "--backend", "wgpu"),
             plugin_files(WGSL.encode(), None), env=PLUGIN_ENV),
    Accepted("gltf-mirrored-node", ("run", FORWARD, "--scene", "m.gltf"),
             {"m.gltf": _node_scene(scale=[-1, 1, 1], translation=[2, 0, 0])}),
    Accepted("gltf-zero-scale-node", ("run", FORWARD, "--scene", "z.gltf"),
             {"z.gltf": _node_scene(scale=[0, 0, 0])}),
    # the bad animation cases' document with good keyframes: played, nothing to say
    Accepted("gltf-animated-node", ("run", DEFERRED, "--scene", "a.gltf", "--set",
                                    "gbuffer.velocity=true"),
             {"a.gltf": json.dumps(anim_doc([0, 1], [[0, 0, 0], [1, 0, 0]])).encode()}),
    Accepted("obj-without-normals", ("run", FORWARD, "--scene", "t.obj"),
             {"t.obj": TRI_OBJ}),
    Accepted("scene-relative-to-config", ("run", "sub/c.toml"),
             {"sub/c.toml": BASE.replace('scene = "default"', 'scene = "t.obj"').encode(),
              "sub/t.obj": TRI_OBJ}),
    Accepted("set-boolean-spelling", ("run", FORWARD, "--set", "shadow.enabled=on")),
    # the README points at these
    Accepted("graph-plan-of-a-run-config", ("graph", "plan", DEFERRED)),
    Accepted("readme-rt-shadows-ray-pipeline-ssao",
             ("run", str(ROOT / "configs" / "rt_shadows.toml"), "--backend", "vk", "--set",
              "shadows=ray_pipeline", "--set", "ao=ssao", "--scene", "t.obj"),
             {"t.obj": TRI_OBJ}),
    Accepted("spirv-cache-truncated", ("run", DEFERRED, "--backend", "vk"),
             warm=("run", DEFERRED, "--backend", "vk"), damage=_truncate_one("cache/rfw/spirv"),
             warning=True),
    Accepted("meshlet-cache-truncated", ("run", str(ROOT / "configs" / "meshlet.toml"),
                                         "--backend", "vk", "--scene", "t.obj"),
             {"t.obj": TRI_OBJ},
             warm=("run", str(ROOT / "configs" / "meshlet.toml"), "--backend", "vk",
                   "--scene", "t.obj"),
             damage=_truncate_one("home/.cache/rfw/meshlets"), warning=True),
    # a damaged fetched scene is listed as not cached (a fetch would rebuild it)
    Accepted("scenes-list-with-damaged-entries", ("scenes", "fetch", "--list"),
             damage=lambda root: [_scratch(f"cache/rfw-scenes/{name}", data)(root) for name, data
                                  in (("dragon.json", b"\xff{not json"),
                                      ("dragon.glb", b"glTF"),
                                      ("boxtextured.json", b"[1, 2]"))]),
]
