"""Mirrored and degenerate instances.

A scene mirrored through x = 0 (every instance transform, light and camera multiplied by
diag(-1, 1, 1)) must render as the horizontally flipped image of the original: front faces,
normals and normal-mapped tangent frames all have to follow the mirror. Checked on wgpu,
on Vulkan, on the meshlet path and with ray-traced shadows. Negative controls undo one part
of the fix (the per-instance winding, or the tangent sign) and the comparison must then fail.

Zero-scale nodes are valid glTF: through the CLI they are skipped with a one-line warning,
and a file with nothing left fails with one clean error line.
"""

from __future__ import annotations

import functools
import json
from dataclasses import replace

import numpy as np
import pytest

from rfw.config import apply_overrides, load_config
from rfw.render import render, to_png_array
from rfw.scene.model import Camera, Scene, SceneError, Texture

from .cli.warm import warm_cli
from .conftest import ROOT, tiny_scene
from .golden_util import changed_share

SIZE = "96x64"
MIRROR = np.diag([-1.0, 1.0, 1.0, 1.0]).astype(np.float32)
# pixels whose largest channel differs by more than TOL, allowed as rasterisation ties (the
# mirror turns a left edge into a right one, and the top-left rule treats them differently)
TOL, TIES = 2, 0.002


def _mx(v: tuple[float, float, float]) -> tuple[float, float, float]:
    return (-v[0], v[1], v[2])


def mirrored(scene: Scene) -> Scene:
    """``scene`` reflected through the plane x = 0."""
    return replace(
        scene,
        instances=[replace(i, transform=MIRROR @ i.transform) for i in scene.instances],
        lights=[replace(li, position=_mx(li.position), direction=_mx(li.direction))
                for li in scene.lights],
        cameras=[replace(c, position=_mx(c.position), target=_mx(c.target), up=_mx(c.up))
                 for c in scene.cameras])


def bumpy_scene() -> Scene:
    """The tiny scene with a tilted normal map on every surface, so that a wrong tangent
    frame under the mirror changes the shading."""
    s = tiny_scene()
    pixels = np.zeros((4, 4, 4), np.uint8)
    pixels[...] = (128, 230, 180, 255)  # tangent-space normal tilted towards +bitangent
    s.textures = [Texture("tilt", pixels, srgb=False)]
    for m in s.materials:
        m.normal_texture = 0
    return s


def image(config: str, scene: Scene, backend: str, sets: tuple[str, ...] = ()) -> np.ndarray:
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"),
                          [f"size={SIZE}", *sets])
    result = render(cfg, scene=scene, backend=backend)
    formats = {r.name: r.format for r in result.frame.plan.resources}
    ((name, img),) = result.images.items()
    return to_png_array(img, formats[name])[..., :3].astype(int)


@functools.cache
def _original(config: str, backend: str, sets: tuple[str, ...]) -> np.ndarray:
    # no mirrored instance in it, so the negative controls' patches cannot change it
    return image(config, bumpy_scene(), backend, sets)


def mirror_mismatch(config: str, backend: str, sets: tuple[str, ...] = ()) -> float:
    """The fraction of pixels where the mirrored scene's render differs (by more than TOL)
    from the original's render flipped left to right."""
    original = _original(config, backend, sets)
    mirror = image(config, mirrored(bumpy_scene()), backend, sets)
    diff = np.abs(mirror - original[:, ::-1]).max(axis=-1)
    return float((diff > TOL).mean())


CASES = {
    "forward-wgpu": ("forward", "wgpu", ("shadow.enabled=true",)),
    "deferred-wgpu": ("deferred", "wgpu", ("shadow.enabled=true",)),
    "deferred-vk": ("deferred", "vk", ("shadow.enabled=true",)),
    "meshlet-vk": ("meshlet", "vk", ("shadow.enabled=true", "culling.triangles=true")),
    # rt_ao's per-pixel random rays are not mirror-symmetric: a tiny radius turns AO off
    "rt_shadows-vk": ("rt_shadows", "vk", ("rt_ao.radius=0.0001",)),
}


@functools.cache
def _vk_extensions() -> frozenset[str] | str:
    """The Vulkan device's extensions, or why there is no device."""
    from vkext import VkDevice, VkUnavailableError

    try:
        dev = VkDevice(label="rfw-tests:caps")
    except VkUnavailableError as e:
        return str(e)
    try:
        return frozenset(dev.extensions)
    finally:
        dev.destroy()


def _needs(backend: str, config: str) -> None:
    if backend != "vk":
        return
    ext = _vk_extensions()
    if isinstance(ext, str):
        pytest.skip(f"no Vulkan: {ext}")
    need = {"meshlet": "VK_EXT_mesh_shader", "rt_shadows": "VK_KHR_ray_query"}.get(config)
    if need and need not in ext:
        pytest.skip(f"{need} is not supported here")


@pytest.mark.parametrize("case", sorted(CASES))
def test_mirrored_scene_renders_the_flipped_image(case):
    config, backend, sets = CASES[case]
    _needs(backend, config)
    assert mirror_mismatch(config, backend, sets) <= TIES


def _unfixed_winding(monkeypatch) -> None:
    # the old behaviour: every instance drawn with its mesh's own winding
    import rfw.backends.wgpu.scene as wgpu_scene
    import vkext.meshlet
    import vkext.scene

    for module in (wgpu_scene, vkext.scene):
        monkeypatch.setattr(module, "mirrored_mask", lambda models: np.zeros(len(models), bool))
    monkeypatch.setattr(vkext.meshlet, "is_mirrored", lambda transform: False)


def _unfixed_tangents(monkeypatch) -> None:
    # mirrored winding, but the tangent sign kept: the normal map tilts the wrong way
    import rfw.backends.wgpu.scene as wgpu_scene
    import vkext.scene
    from rfw.backends.scene_data import mirrored_arrays

    def keep_sign(mesh):
        indices, tangents = mirrored_arrays(mesh)
        tangents[:, 3] *= -1.0
        return indices, tangents

    for module in (wgpu_scene, vkext.scene):
        monkeypatch.setattr(module, "mirrored_arrays", keep_sign)


@pytest.mark.parametrize("case", ["deferred-wgpu", "deferred-vk", "meshlet-vk"])
def test_unfixed_winding_fails_the_comparison(case, monkeypatch):
    config, backend, sets = CASES[case]
    _needs(backend, config)
    _unfixed_winding(monkeypatch)
    assert mirror_mismatch(config, backend, sets) > 0.1


@pytest.mark.parametrize("case", ["forward-wgpu", "deferred-vk"])
def test_unfixed_tangent_sign_fails_the_comparison(case, monkeypatch):
    config, backend, sets = CASES[case]
    _needs(backend, config)
    _unfixed_tangents(monkeypatch)
    assert mirror_mismatch(config, backend, sets) > 0.1


def test_mirrored_courtyard_culls_the_same_meshlets():
    # the mirrored cone: a mirror keeps angles, so the same meshlets face away as before
    _needs("vk", "meshlet")
    from rfw.scene import default_scene

    cfg = apply_overrides(load_config(ROOT / "configs" / "meshlet.toml"), ["size=160x90"])
    images, culling = [], []
    for scene in (default_scene(), mirrored(default_scene())):
        result = render(cfg, scene=scene, backend="vk")
        formats = {r.name: r.format for r in result.frame.plan.resources}
        ((name, img),) = result.images.items()
        images.append(to_png_array(img, formats[name])[..., :3].astype(int))
        culling.append(result.timings["culling"])
    assert culling[0]["culled_cone"] > 0
    assert culling[1] == culling[0]
    diff = np.abs(images[1] - images[0][:, ::-1]).max(axis=-1)
    assert (diff > TOL).mean() <= TIES


def test_shading_differs_between_the_mirror_and_the_original():
    # the comparison is not trivially satisfied: the tiny scene is not mirror-symmetric
    original = _original(*CASES["forward-wgpu"])
    diff = np.abs(original - original[:, ::-1]).max(axis=-1)
    assert (diff > TOL).mean() > 0.1


# ---------------------------------------------------------------------------------------------
# zero-scale nodes through the CLI


def _cube_gltf(path, scales: list[list[float]]) -> None:
    """One cube mesh placed by a node per entry of ``scales``."""
    pos = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32)
    idx = np.array([0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                    2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5], np.uint16)
    data = pos.tobytes() + idx.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data), "uri": path.with_suffix(".bin").name}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes},
                        {"buffer": 0, "byteOffset": pos.nbytes, "byteLength": idx.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": len(idx),
                       "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0, "name": f"cube{k}", "scale": s, "translation": [2.0 * k, 0, 0]}
                  for k, s in enumerate(scales)],
        "scenes": [{"nodes": list(range(len(scales)))}], "scene": 0,
    }
    path.with_suffix(".bin").write_bytes(data)
    path.write_text(json.dumps(doc))


def test_zero_scale_node_loads_and_renders_through_the_cli(tmp_path):
    scene = tmp_path / "zero.gltf"
    _cube_gltf(scene, [[1, 1, 1], [0, 0, 0], [-1, 1, 1]])
    out = tmp_path / "out"
    run = warm_cli("run", str(ROOT / "configs" / "forward.toml"), "--scene", str(scene),
                   "--size", "64x48", "--frames", "1", "--out", str(out), cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    warnings = [line for line in run.stderr.splitlines() if "skipped" in line]
    assert warnings == [f"rfw: warning: {scene}: instance 'cube1' skipped: transform is "
                        "singular (a zero scale collapses the mesh)"]
    png = out / "tonemap.ldr.png"
    assert png.is_file()
    from PIL import Image

    with Image.open(png) as im:
        pixels = np.asarray(im.convert("RGB")).astype(int)
    assert pixels.shape == (48, 64, 3) and np.ptp(pixels) > 20  # the two cubes show


def test_only_zero_scale_nodes_render_the_empty_scene_with_a_warning(tmp_path):
    # as an empty scene does (tests/scene/test_limits.py): the background, one line saying so
    scene = tmp_path / "zero.gltf"
    _cube_gltf(scene, [[0, 0, 0], [1, 0, 1]])
    run = warm_cli("run", str(ROOT / "configs" / "forward.toml"), "--scene", str(scene),
                   "--size", "64x48", "--frames", "1", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    lines = [line for line in run.stderr.splitlines() if "nothing is drawable" in line]
    assert lines == [f"rfw: warning: {scene}: nothing is drawable (no instances, or every one "
                     "skipped): the images show the background only"]
    assert "Traceback" not in run.stderr



def test_degenerate_instances_in_a_built_scene_draw_nothing(capsys):
    # scenes built in code reach the backends without a loader: they drop the same instances
    scene = tiny_scene()
    cube = scene.instances[1]
    nan = cube.transform.copy()
    nan[0, 0] = np.nan
    flat = cube.transform.copy()
    flat[:3, 1] = 0.0
    scene.instances += [replace(cube, transform=nan, name="nan"),
                        replace(cube, transform=flat, name="flat")]
    plain = image("forward", tiny_scene(), "wgpu")
    assert np.array_equal(image("forward", scene, "wgpu"), plain)
    err = capsys.readouterr().err
    assert "instance 'nan' skipped: transform has NaN" in err
    assert "instance 'flat' skipped: transform is singular" in err
    # the control: a third, valid cube elsewhere does change the image (114 of the 6144
    # pixels, measured)
    moved = cube.transform.copy()
    moved[0, 3] = -1.5
    scene.instances.append(replace(cube, transform=moved, name="moved"))
    assert changed_share(image("forward", scene, "wgpu"), plain) > 0.005


# ---------------------------------------------------------------------------------------------
# degenerate cameras


def test_camera_looking_along_up_still_has_a_view():
    cam = Camera((0.0, 5.0, 0.0), (0.0, 0.0, 0.0))  # straight down, up = +Y
    view = cam.view()
    assert np.all(np.isfinite(view))
    centre = view @ np.array([0.0, 0.0, 0.0, 1.0])
    assert np.allclose(centre[:3], [0.0, 0.0, -5.0], atol=1e-5)
    assert np.allclose(view[:3, :3] @ view[:3, :3].T, np.identity(3), atol=1e-5)


def test_camera_on_its_target_is_a_scene_error():
    with pytest.raises(SceneError, match=r"camera 'c': position .* must be finite and apart"):
        Camera((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), name="c").view()
