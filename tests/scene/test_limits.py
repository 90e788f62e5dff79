"""rfw.scene.limits: what a glTF file may ask for, counted before anything is allocated.

Accessors with and without a bufferView count alike against the geometry limit; each
distinct image is decoded once and counted once; sizes come from the image header; an empty
scene and a scene whose only instance is skipped render alike. Each refusal is checked with
a control that stays under the limit."""

from __future__ import annotations

import base64
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.backends.scene_data import mip_chain
from rfw.scene import SceneError, limits, load_gltf
from rfw.scene.model import Instance, Material, Mesh, Scene, Texture

from ..cli.warm import warm_cli
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
IDX = np.array([0, 1, 2, 0, 2, 3], np.uint16)


def data_uri(blob: bytes, kind: str = "application/octet-stream") -> str:
    return f"data:{kind};base64," + base64.b64encode(blob).decode()


def quad_doc(meshes: int = 1) -> dict:
    """``meshes`` meshes, each one node, all reading one quad's accessors (a backed
    bufferView shared by every mesh)."""
    blob = QUAD.tobytes() + UV.tobytes() + IDX.tobytes()
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": data_uri(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                                    "indices": 2}]} for _ in range(meshes)],
        "nodes": [{"mesh": k, "translation": [1.5 * k, 0, 0]} for k in range(meshes)],
        "scenes": [{"nodes": list(range(meshes))}], "scene": 0,
    }


def unbacked(count: int, *, mode: int | None = None, extra: dict | None = None) -> dict:
    prim: dict = {"attributes": {"POSITION": 0}}
    if mode is not None:
        prim["mode"] = mode
    doc = {"asset": {"version": "2.0"},
           "accessors": [{"componentType": 5126, "count": count, "type": "VEC3"}],
           "meshes": [{"primitives": [prim]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}], "scene": 0}
    doc.update(extra or {})
    return doc


def write(tmp_path: Path, doc: dict, name: str = "scene.gltf") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def png(pixels: np.ndarray, **save: object) -> bytes:
    f = io.BytesIO()
    Image.fromarray(pixels).save(f, "PNG", **save)
    return f.getvalue()


def textured(doc: dict, uris: list[str], sources: list[int]) -> dict:
    """Each mesh k gets a material whose base colour is textures[k] = images[sources[k]]."""
    doc["images"] = [{"uri": u} for u in uris]
    doc["textures"] = [{"source": s} for s in sources]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}}
                        for k in range(len(sources))]
    for k, mesh in enumerate(doc["meshes"]):
        mesh["primitives"][0]["material"] = k
    return doc


# -- geometry ---------------------------------------------------------------------------------


def test_unbacked_accessor_over_the_limit_is_refused_before_it_is_allocated(tmp_path):
    path = write(tmp_path, unbacked(67_108_863))
    with pytest.raises(SceneError) as e:
        load_gltf(path)
    line = str(e.value)
    assert line.startswith(f"{path}: meshes: 67,108,863 vertices and 67,108,863 indices")
    assert "13.25 GiB" in line and "limit of 1.00 GiB per scene" in line
    assert "meshes[0].primitives[0], POSITION accessors[0] with count 67,108,863 and no " \
           "bufferView" in line
    assert "\n" not in line


def test_small_unbacked_accessor_loads_as_zeros(tmp_path):
    # the control: zero-filled accessors are valid glTF, and small ones load
    scene = load_gltf(write(tmp_path, unbacked(6)))
    assert len(scene.meshes) == 1 and scene.meshes[0].positions.shape == (6, 3)
    assert not scene.meshes[0].positions.any()


def test_backed_accessors_count_alike_through_a_shared_buffer_view(tmp_path):
    # one 4-vertex bufferView read by many meshes: each mesh holds its own copy
    per = limits.geometry_bytes(4, 6)
    n = limits.MAX_GEOMETRY_BYTES // per
    assert load_gltf(write(tmp_path, quad_doc(3))).meshes  # the control: few meshes load
    old = limits.MAX_GEOMETRY_BYTES
    try:
        limits.MAX_GEOMETRY_BYTES = 3 * per  # three meshes fit exactly, four do not
        assert len(load_gltf(write(tmp_path, quad_doc(3))).meshes) == 3
        with pytest.raises(SceneError, match=r"meshes: 16 vertices and 24 indices would "
                                             r"need about .* \(the largest: meshes\[0\]"):
            load_gltf(write(tmp_path, quad_doc(4)))
    finally:
        limits.MAX_GEOMETRY_BYTES = old
    assert n > 1_000_000  # the real limit leaves room for real scenes


def test_strips_count_their_triangles_and_unreached_meshes_do_not_count(tmp_path):
    # a strip of n indices makes n - 2 triangles: 3 (n - 2) corners
    n = 4_000_000
    need = limits.geometry_bytes(n, 3 * (n - 2))
    assert need > limits.MAX_GEOMETRY_BYTES > limits.geometry_bytes(n, n)
    with pytest.raises(SceneError, match=f"{n:,} vertices and {3 * (n - 2):,} indices"):
        load_gltf(write(tmp_path, unbacked(n, mode=5)))
    # a mesh no node of the scene reaches is never read, so it is not counted
    doc = unbacked(6)
    doc["accessors"].append({"componentType": 5126, "count": 67_108_863, "type": "VEC3"})
    doc["meshes"].append({"primitives": [{"attributes": {"POSITION": 1}}]})
    doc["nodes"].append({"mesh": 1})
    assert len(load_gltf(write(tmp_path, doc)).meshes) == 1
    doc["scenes"][0]["nodes"].append(1)  # the control: reached, it counts
    with pytest.raises(SceneError, match="67,108,869 vertices"):
        load_gltf(write(tmp_path, doc))


def test_geometry_limit_boundary():
    at = limits.MAX_GEOMETRY_BYTES // limits.VERTEX_BYTES
    limits.check_geometry(at, 0, file="f", largest="x")
    with pytest.raises(SceneError, match=r"f: meshes: .*\(the largest: x\)"):
        limits.check_geometry(at + 1, 0, file="f", largest="x")


# -- images -----------------------------------------------------------------------------------


def test_one_image_used_by_many_textures_is_decoded_once(tmp_path):
    (tmp_path / "a.png").write_bytes(png(np.full((8, 8, 3), 200, np.uint8)))
    (tmp_path / "b.png").write_bytes(png(np.full((8, 8, 3), 50, np.uint8)))
    # one image named by 3 textures, and 3 images naming one file: one decode each way
    for uris, sources in ((["a.png"], [0, 0, 0]), (["a.png"] * 3, [0, 1, 2])):
        scene = load_gltf(write(tmp_path, textured(quad_doc(3), uris, sources)))
        assert len(scene.textures) == 3
        assert len({id(t.pixels) for t in scene.textures}) == 1
    # the control: two different files are two images
    scene = load_gltf(write(tmp_path, textured(quad_doc(2), ["a.png", "b.png"], [0, 1])))
    assert len({id(t.pixels) for t in scene.textures}) == 2


def test_declared_size_over_the_side_limit_is_refused_from_the_header(tmp_path):
    # a 100000x100000 PNG of a few hundred bytes: Pillow's DecompressionBombError before
    (tmp_path / "bomb.png").write_bytes(_declared_png(100_000, 100_000))
    (tmp_path / "wide.png").write_bytes(png(np.zeros((1, 20_000, 3), np.uint8)))
    for name, size in (("bomb.png", "100000x100000"), ("wide.png", "20000x1")):
        path = write(tmp_path, textured(quad_doc(1), [name], [0]))
        with pytest.raises(SceneError) as e:
            load_gltf(path)
        assert str(e.value) == (f"{path}: images[0]: {size} pixels is over the limit of 16384 "
                                "pixels per side")
    assert Image.MAX_IMAGE_PIXELS == 89_478_485  # Pillow's own check is left as it was
    # the control: at the limit, an image loads
    (tmp_path / "edge.png").write_bytes(png(np.zeros((1, 16384, 3), np.uint8)))
    scene = load_gltf(write(tmp_path, textured(quad_doc(1), ["edge.png"], [0])))
    assert scene.textures[0].pixels.shape == (1, 16384, 4)


def test_distinct_texels_count_against_the_limit_once_per_image(tmp_path, monkeypatch):
    (tmp_path / "a.png").write_bytes(png(np.full((8, 8, 3), 200, np.uint8)))
    (tmp_path / "b.png").write_bytes(png(np.full((8, 8, 3), 50, np.uint8)))
    monkeypatch.setattr(limits, "MAX_TEXELS", 100)  # one 8x8 image fits, two do not
    scene = load_gltf(write(tmp_path, textured(quad_doc(4), ["a.png"] * 2, [0, 1, 0, 1])))
    assert len(scene.textures) == 4
    path = write(tmp_path, textured(quad_doc(2), ["a.png", "b.png"], [0, 1]))
    with pytest.raises(SceneError) as e:
        load_gltf(path)
    assert str(e.value).startswith(f"{path}: images[1]: 8x8 pixels brings the scene's "
                                   "distinct images to 128 texels")
    assert "over the limit of 100" in str(e.value)


def test_texture_over_the_device_limit_is_refused_before_upload():
    from rfw import load
    from rfw.render import render

    mesh = Mesh("quad", QUAD, np.tile(np.float32([0, 0, 1]), (4, 1)), UV,
                np.tile(np.float32([1, 0, 0, 1]), (4, 1)), IDX.astype(np.uint32))

    def scene(side: int) -> Scene:
        return Scene("wide", [mesh], [Material(base_color_texture=0)],
                     [Texture("wide.png", np.zeros((1, side, 4), np.uint8))],
                     [Instance(0, np.identity(4, np.float32))], source="wide.gltf")

    for backend in ("wgpu", "vk"):
        key = "max-texture-dimension-2d" if backend == "wgpu" else "maxImageDimension2D"
        cfg = load(ROOT / "configs" / "flat.toml", size=(16, 16))
        with pytest.raises(SceneError) as e:  # far past any device: its limit is named
            render(cfg, scene=scene(1 << 20), frames=1, backend=backend)
        found = re.fullmatch(rf"wide.gltf: textures: texture 'wide.png' is {1 << 20}x1, over "
                             rf"this device's {key} \((\d+) pixels per side\)", str(e.value))
        assert found, str(e.value)
        limit = int(found[1])
        assert limit >= 8192  # what Vulkan and WebGPU promise at least
        with pytest.raises(SceneError) as e:  # one past the limit
            render(cfg, scene=scene(limit + 1), frames=1, backend=backend)
        assert str(e.value) == (f"wide.gltf: textures: texture 'wide.png' is {limit + 1}x1, "
                                f"over this device's {key} ({limit} pixels per side)")
        render(cfg, scene=scene(limit), frames=1, backend=backend)  # the control: at it


def test_textures_sharing_an_image_render_as_two_copies(tmp_path):
    # one image named by two textures against the same pixels in two files (encoded apart,
    # so both are decoded): the same picture; the control, a different image, is not
    pixels = np.random.default_rng(3).integers(0, 256, (16, 16, 3), np.uint8)
    (tmp_path / "a.png").write_bytes(png(pixels))
    (tmp_path / "a2.png").write_bytes(png(pixels, compress_level=1))
    (tmp_path / "c.png").write_bytes(png(255 - pixels))
    assert (tmp_path / "a.png").read_bytes() != (tmp_path / "a2.png").read_bytes()
    shared = write(tmp_path, textured(quad_doc(2), ["a.png"], [0, 0]), "shared.gltf")
    copies = write(tmp_path, textured(quad_doc(2), ["a.png", "a2.png"], [0, 1]), "copies.gltf")
    other = write(tmp_path, textured(quad_doc(2), ["a.png", "c.png"], [0, 1]), "other.gltf")
    assert len({id(t.pixels) for t in load_gltf(copies).textures}) == 2
    for backend in ("wgpu", "vk"):
        a, b, c = (_render(tmp_path, p, backend) for p in (shared, copies, other))
        assert np.array_equal(a, b), backend
        assert np.abs(a.astype(int) - c).max() > 20, backend


def _srgb_decode(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _srgb_encode(x):
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.maximum(x, 0) ** (1 / 2.4) - 0.055)


def _float_chain(pixels, srgb=False):
    """The whole-level chain: each level from the last at once, in float32 means rounded
    half up (sRGB colour: decoded by the formula, averaged and encoded back in float64)."""
    levels = [pixels]
    while max(levels[-1].shape[:2]) > 1:
        h, w = levels[-1].shape[:2]
        last = levels[-1][: h - h % 2 or 1, : w - w % 2 or 1]
        p = last.astype(np.float32)
        if srgb:
            p = np.concatenate([_srgb_decode(last[..., :3] / 255.0), p[..., 3:]], axis=-1)
        if p.shape[0] >= 2:
            p = (p[0::2] + p[1::2]) / 2
        if p.shape[1] >= 2:
            p = (p[:, 0::2] + p[:, 1::2]) / 2
        if srgb:
            p[..., :3] = 255 * _srgb_encode(p[..., :3])
        levels.append(np.clip(np.floor(p + 0.5), 0, 255).astype(np.uint8))
    return levels


@pytest.mark.parametrize("srgb", [False, True])
@pytest.mark.parametrize("band", [None, 3])
def test_mip_chain_is_the_float_chain(band, srgb, monkeypatch):
    if band is not None:  # levels built in bands of 3 output texels: the same bytes
        import rfw.backends.scene_data as scene_data
        monkeypatch.setattr(scene_data, "MIP_BAND_TEXELS", band)
    # linear: sums in uint16, the same bytes as the float32 means rounded half up it
    # replaced; sRGB: the table and the edge search, the same bytes as the formulas
    rng = np.random.default_rng(1)
    for shape in ((1, 1), (1, 7), (7, 1), (5, 3), (33, 17), (2, 300)):
        for a in (rng.integers(0, 256, (*shape, 4), np.uint8), np.full((*shape, 4), 255,
                                                                          np.uint8)):
            want, got = _float_chain(a, srgb), mip_chain(a, srgb=srgb)
            assert len(want) == len(got)
            assert all(np.array_equal(x, y) and y.dtype == np.uint8 for x, y in zip(want, got,
                                                                                    strict=True))
    # the controls: rounding down instead differs on random texels, and so does the other
    # colour space's chain, in colour only (alpha is averaged as bytes in both)
    a = rng.integers(0, 256, (8, 8, 4), np.uint8)
    down = (a.reshape(4, 2, 4, 2, 4).astype(int).sum((1, 3)) // 4).astype(np.uint8)
    assert not np.array_equal(mip_chain(a, srgb=srgb)[1], down)
    other = mip_chain(a, srgb=not srgb)[1]
    assert not np.array_equal(mip_chain(a, srgb=srgb)[1][..., :3], other[..., :3])
    assert np.array_equal(mip_chain(a, srgb=srgb)[1][..., 3], other[..., 3])


def test_srgb_mips_keep_the_linear_mean():
    # every byte maps to its own linear value and back; a red/white checker's level 1 is
    # the linear mean (0.5 in green and blue) within one 8-bit step, where the mean of the
    # stored bytes (the linear chain, as sRGB textures were built) is 60 steps darker
    every = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(4, 2)
    blocks = every.repeat(2, 0).repeat(2, 1)  # 2x2 texels of each byte
    assert np.array_equal(mip_chain(blocks, srgb=True)[1], every)
    checker = _checker(8)
    want = 255 * _srgb_encode(_srgb_decode(checker[..., :3] / 255).mean((0, 1)))
    for level in mip_chain(checker, srgb=True)[1:]:
        assert np.abs(level[..., :3] - want).max() <= 1
    assert np.abs(mip_chain(checker)[1][..., :3] - want).max() > 50


def _checker(n: int) -> np.ndarray:
    """An n x n red/white checker of single texels, opaque."""
    c = np.full((n, n, 4), 255, np.uint8)
    odd = (np.add.outer(np.arange(n), np.arange(n)) % 2).astype(bool)
    c[odd, 1:3] = 0
    return c


def test_minified_srgb_textures_keep_the_linear_mean(tmp_path, monkeypatch):
    # a 64x64 red/white checker as base colour and emission, drawn ~20 pixels across (mip
    # levels 1 and coarser, all one colour): both backends' G-buffers read the level-0
    # linear mean (1, 0.5, 0.5) within one 8-bit sRGB step; the control, the levels built
    # as the bytes' mean (the linear chain), reads 60 steps darker through the same upload
    import rfw
    import rfw.backends.scene_data as scene_data
    import rfw.backends.wgpu.scene as wgpu_scene
    import vkext.scene as vk_scene
    from rfw.render import render
    from rfw.scene import load_scene

    (tmp_path / "c.png").write_bytes(png(_checker(64)))
    doc = textured(quad_doc(1), ["c.png"], [0])
    doc["materials"][0].update(emissiveTexture={"index": 0}, emissiveFactor=[1, 1, 1])
    path = write(tmp_path, doc)
    cfg = rfw.make_config("mips", [{"name": "gbuffer"}], ["gbuffer.albedo", "gbuffer.emissive"],
                          size=(32, 32))
    want = 255 * _srgb_encode(np.array([1.0, 0.5, 0.5]))

    def steps(backend: str) -> float:
        """The G-buffer's largest distance from ``want``, in 8-bit sRGB steps."""
        im = render(cfg, scene=load_scene(path), frames=1, backend=backend).images
        albedo, emissive = im["gbuffer.albedo"], im["gbuffer.emissive"]
        drawn = albedo[..., 3] > 0
        assert drawn.sum() > 200, backend  # the quad, minified 3x
        emitted = 255 * _srgb_encode(emissive[drawn][:, :3].astype(np.float64))
        return max(np.abs(albedo[drawn][:, :3] - want).max(), np.abs(emitted - want).max())

    for backend in ("wgpu", "vk"):
        assert steps(backend) <= 1, backend
    byte_mean = lambda pixels, srgb: scene_data.mip_levels(pixels)  # noqa: E731
    monkeypatch.setattr(wgpu_scene, "mip_levels", byte_mean)
    monkeypatch.setattr(vk_scene, "mip_levels", byte_mean)
    for backend in ("wgpu", "vk"):
        assert steps(backend) > 50, backend


def test_textures_uploaded_in_small_chunks_render_the_same(tmp_path, monkeypatch):
    # both backends stream texels through bounded chunks (a few rows, a flush or a submit
    # each): 4 KiB chunks cut every level of a 64x48 texture into bands and give the same
    # picture as one chunk; the control, the texture flipped, does not
    import rfw.backends.wgpu.scene as wgpu_scene
    import vkext.scene as vk_scene

    pixels = np.random.default_rng(5).integers(0, 256, (48, 64, 3), np.uint8)
    (tmp_path / "a.png").write_bytes(png(pixels))
    (tmp_path / "b.png").write_bytes(png(pixels[::-1].copy()))
    scene = write(tmp_path, textured(quad_doc(1), ["a.png"], [0]), "a.gltf")
    flipped = write(tmp_path, textured(quad_doc(1), ["b.png"], [0]), "b.gltf")
    for backend in ("wgpu", "vk"):
        whole = _render(tmp_path, scene, backend)
        with monkeypatch.context() as m:
            m.setattr(wgpu_scene, "TEXTURE_CHUNK", 4096)
            m.setattr(vk_scene, "TEXTURE_CHUNK", 4096)
            chunked = _render(tmp_path, scene, backend)
        assert np.array_equal(whole, chunked), backend
        assert np.abs(whole.astype(int) - _render(tmp_path, flipped, backend)).max() > 20


def test_a_scene_that_does_not_keep_its_pixels_drops_them_once_uploaded(tmp_path):
    from rfw import load
    from rfw.render import render
    from rfw.scene import SceneError, load_scene

    (tmp_path / "a.png").write_bytes(png(np.full((8, 8, 3), 200, np.uint8)))
    path = write(tmp_path, textured(quad_doc(2), ["a.png"], [0, 0]))
    cfg = load(ROOT / "configs" / "forward.toml", size=(16, 16))
    for backend in ("wgpu", "vk"):
        kept = load_scene(path)
        render(cfg, scene=kept, frames=1, backend=backend)
        assert all(t.pixels is not None for t in kept.textures)  # the control: kept
        render(cfg, scene=kept, frames=1, backend=backend)
        scene = load_scene(path)
        scene.keep_pixels = False
        render(cfg, scene=scene, frames=1, backend=backend)
        assert [t.pixels for t in scene.textures] == [None, None]
        with pytest.raises(SceneError, match=r"texture '.*': its pixels were dropped after an "
                                             r"earlier upload .*load the scene again"):
            render(cfg, scene=scene, frames=1, backend=backend)


def test_bench_reads_back_images_over_pillows_bomb_limit(tmp_path):
    # rfw writes up to 16384x16384, over Pillow's 178-megapixel error: run with the limit
    # lowered so a 64x64 image stands for one that large
    code = """
import sys
import numpy as np
from PIL import Image
from rfw.bench.images import load_png
Image.fromarray(np.full((64, 64, 3), 7, np.uint8)).save(sys.argv[1])
Image.MAX_IMAGE_PIXELS = 1000
try:
    Image.open(sys.argv[1])
    print("no bomb check")
except Image.DecompressionBombError:
    print("bomb check")
print(load_png(sys.argv[1]).shape, Image.MAX_IMAGE_PIXELS)
"""
    run = subprocess.run([sys.executable, "-c", code, str(tmp_path / "x.png")],
                         capture_output=True, text=True, timeout=120)
    assert run.stdout.split("\n")[:2] == ["bomb check", "(64, 64, 3) 1000"], run.stderr


# -- empty scenes -----------------------------------------------------------------------------


def test_empty_scene_and_skipped_only_instance_render_alike(tmp_path):
    empty = write(tmp_path, {"asset": {"version": "2.0"}, "scenes": [{"nodes": []}],
                             "scene": 0}, "empty.gltf")
    doc = quad_doc(1)
    doc["nodes"][0]["scale"] = [0, 0, 0]
    skipped = write(tmp_path, doc, "skipped.gltf")
    drawn = write(tmp_path, quad_doc(1), "drawn.gltf")
    images = {}
    for path in (empty, skipped, drawn):
        out = tmp_path / f"out-{path.stem}"
        run = warm_cli("run", "configs/flat.toml", "--backend", "vk", "--scene", path, "--size",
                       "32x32", "--frames", "1", "--out", out, cwd=ROOT)
        assert run.returncode == 0, run.stderr
        said = [line for line in run.stderr.splitlines() if "nothing is drawable" in line]
        if path is drawn:  # the control: a drawable scene says nothing and shows the quad
            assert said == [] and "rfw: warning" not in run.stderr
        else:
            assert said == [f"rfw: warning: {path}: nothing is drawable (no instances, or "
                            "every one skipped): the images show the background only"]
        with Image.open(out / "flat.color.png") as im:
            images[path.stem] = np.asarray(im)
    assert np.array_equal(images["empty"], images["skipped"])
    assert changed_share(images["empty"], images["drawn"]) > 0.1  # the quad: 33 %


def _render(tmp_path: Path, scene: Path, backend: str) -> np.ndarray:
    from rfw import load
    from rfw.render import render
    from rfw.scene import load_scene

    cfg = load(ROOT / "configs" / "forward.toml", size=(48, 32))  # flat draws no textures
    result = render(cfg, scene=load_scene(scene), frames=1, backend=backend)
    return result.images[cfg.outputs[0]]


def _declared_png(width: int, height: int) -> bytes:
    """A PNG whose header declares ``width`` x ``height`` (its data is one short row)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + \
            struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + \
        chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


@pytest.mark.parametrize("mode", ["RGB", "LA", "P", "RGBA"])
def test_images_converted_in_bands_are_the_whole_conversion(mode, monkeypatch):
    # the glTF loader converts a decoded image to RGBA a few rows at a time (its peak is one
    # copy, not two): 100-texel bands of a 53x37 image give Pillow's whole conversion
    from PIL import Image

    import rfw.scene.gltf.textures as gltf

    rng = np.random.default_rng(2)
    im = Image.fromarray(rng.integers(0, 256, (37, 53, 3), np.uint8))
    im = im.convert(mode)
    if mode == "P":
        im.info["transparency"] = 5
    monkeypatch.setattr(gltf, "_RGBA_BAND_TEXELS", 100)
    whole = np.array(im.convert("RGBA"))
    assert np.array_equal(gltf._rgba(im), whole)
    assert not np.array_equal(gltf._rgba(im.transpose(Image.FLIP_TOP_BOTTOM)), whole)
