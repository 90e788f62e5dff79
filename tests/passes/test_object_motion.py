"""Object motion from glTF node animations, on both backends: a cube slid along x by a
translation channel (loaded from a glTF file written here) gives the G-buffer's motion
vectors of its pixels as the analytic screen motion (each pixel's surface, found from its
depth, projected where it was last frame), the still slab under it gives exactly 0, and the
cube moves in the rendered image. Negative controls: the same file without its animation
has no motion at all, and its cube stays put. On vk the ray-traced passes see the move too:
``rt_primary``'s albedo follows the cube (the TLAS is built from the moved transforms; a
TLAS that keeps the rest pose fails the check), the visibility-buffer and meshlet
G-buffers draw it moving, and the path tracer restarts its sums."""

from __future__ import annotations

import base64
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pass_scenes import box, still

from rfw.config import apply_overrides, load_config
from rfw.render import render

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
W, H = 64, 36
FPS = 4  # frame k at k / 4 s: the cube moves 0.5 along x each frame (2 units a second)
CAMERA = ["camera.position=[3, 2.5, 4]", "camera.target=[0, 0.3, 0]", "camera.znear=0.05",
          "camera.zfar=500"]  # _camera()
TOLERANCE = 0.01  # pixels: float16 motion vectors (tests/passes/test_velocity.py)


SLIDE = ("translation", "LINEAR", [0.0, 1.0], [[0, 0.5, 0], [2, 0.5, 0]])


def write_scene(folder: Path, *, animated: bool = True, channel: tuple = SLIDE,
                cube: dict | None = None, name: str | None = None) -> Path:
    """A grey slab and a red unit cube on it (glTF, one embedded buffer); the cube's node
    (rest TRS ``cube``) is moved by ``channel`` (path, interpolation, times, values):
    by default it slides from x = 0 to x = 2 over the first second."""
    blob, views, accessors = bytearray(), [], []

    def add(array: np.ndarray, ctype: int, kind: str) -> int:
        blob.extend(b"\0" * (-len(blob) % 4))
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes})
        blob.extend(array.tobytes())
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": len(array),
               "type": kind}
        if kind == "VEC3" and ctype == 5126:
            acc.update(min=array.min(axis=0).tolist(), max=array.max(axis=0).tolist())
        accessors.append(acc)
        return len(accessors) - 1

    meshes = []
    for k, mesh in enumerate((box(10, 0.2, 10), box(1, 1, 1))):
        meshes.append({"primitives": [{
            "attributes": {"POSITION": add(mesh.positions.astype(np.float32), 5126, "VEC3"),
                           "NORMAL": add(mesh.normals.astype(np.float32), 5126, "VEC3")},
            "indices": add(mesh.indices.astype(np.uint32), 5125, "SCALAR"), "material": k}]})
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
           "nodes": [{"name": "slab", "mesh": 0, "translation": [0, -0.1, 0]},
                     {"name": "cube", "mesh": 1, "translation": [0, 0.5, 0], **(cube or {})}],
           "meshes": meshes,
           "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1]}},
                         {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.1, 0.1, 1]}}]}
    if animated:
        path, interpolation, times, values = channel
        times = add(np.array(times, np.float32), 5126, "SCALAR")
        values = add(np.array(values, np.float32), 5126, "VEC3")
        doc["animations"] = [{"name": "slide", "samplers": [{
            "input": times, "output": values, "interpolation": interpolation}],
            "channels": [{"sampler": 0, "target": {"node": 1, "path": path}}]}]
    doc.update(bufferViews=views, accessors=accessors,
               buffers=[{"byteLength": len(blob), "uri": "data:application/octet-stream;"
                         "base64," + base64.b64encode(bytes(blob)).decode()}])
    path = folder / (name or ("slide.gltf" if animated else "still.gltf"))
    path.write_text(json.dumps(doc))
    return path



def _frames(backend, scene: Path, config: str = "deferred.toml", outputs=(
        "gbuffer.velocity", "gbuffer.depth", "gbuffer.albedo", "tonemap.ldr"),
        sets=("gbuffer.velocity=true",), frames: int = 3) -> tuple[list[dict], dict]:
    name, dev = backend
    cfg = apply_overrides(load_config(CONFIGS / config),
                          [f"size={W}x{H}", f"frames={frames}", f"animation.fps={FPS}",
                           f"scene={scene}", *CAMERA, *sets])
    cfg = replace(cfg, outputs=list(dict.fromkeys([*cfg.outputs, *outputs])))
    got: list[dict] = []
    result = render(cfg, backend=name, device=dev,
                    each_frame=lambda k, f: got.append({o: f.read(o) for o in outputs}))
    return got, result.timings


def _pixels(world: np.ndarray, cam) -> np.ndarray:
    size = (W, H)
    vp = cam.projection(W / H).astype(np.float64) @ cam.view().astype(np.float64)
    p = world @ vp.T
    p = p[..., :2] / p[..., 3:]
    return np.stack([(p[..., 0] + 1) / 2 * size[0], (1 - p[..., 1]) / 2 * size[1]], -1)


def _camera():
    from rfw.scene.model import Camera

    return Camera((3.0, 2.5, 4.0), (0.0, 0.3, 0.0))


def _analytic(depth: np.ndarray, moved: np.ndarray, shift: float) -> np.ndarray:
    """Pixels from each pixel's surface to where it was last frame: ``shift`` back along x
    where ``moved`` (the cube), nowhere else (the slab, the background)."""
    cam = _camera()
    vp = cam.projection(W / H).astype(np.float64) @ cam.view().astype(np.float64)
    y, x = np.mgrid[0:H, 0:W] + 0.5
    ndc = np.stack([x / W * 2 - 1, 1 - y / H * 2, depth, np.ones_like(depth)], -1)
    world = ndc @ np.linalg.inv(vp).T
    world /= world[..., 3:]
    before = world.copy()
    before[..., 0] -= np.where(moved, shift, 0.0)
    return _pixels(before, cam) - _pixels(world, cam)


def _red(image: np.ndarray) -> np.ndarray:
    rgb = image[..., :3].astype(np.float64)
    return (rgb[..., 0] > 2 * rgb[..., 1] + 0.05 * rgb.max()) & (rgb[..., 0] > 0)


def _centroid_x(mask: np.ndarray) -> float:
    return float(np.mgrid[0:H, 0:W][1][mask].mean()) + 0.5


def _center_shift() -> float:
    """Pixels the cube's centre moves along x from frame 0 (x = 0) to frame 2 (x = 1)."""
    cam = _camera()
    a, b = (_pixels(np.array([x, 0.5, 0.0, 1.0]), cam)[0] for x in (0.0, 1.0))
    return float(b - a)


def test_a_sliding_cube_gives_the_analytic_motion_and_the_slab_none(backend, tmp_path):
    frames, timings = _frames(backend, write_scene(tmp_path))
    assert timings["animation"]["times"] == [0.0, 0.25, 0.5]
    assert still(frames[0]["gbuffer.velocity"])  # the first frame: no last frame
    for f in frames[1:]:
        velocity = f["gbuffer.velocity"].astype(np.float64)
        depth = f["gbuffer.depth"][..., 0].astype(np.float64)
        cube = _red(f["gbuffer.albedo"])
        want = _analytic(depth, cube, 0.5)
        assert cube.sum() > 40 and np.abs(want[cube]).max() > 1.5  # pixels, not a rounding
        assert np.abs(velocity - want)[cube].max() < TOLERANCE
        assert still(velocity[~cube])  # the still slab and the clear


def test_without_the_animation_nothing_moves(backend, tmp_path):
    """Negative control: the same file without its animation: no motion anywhere, far from
    the sliding cube's."""
    rest, timings = _frames(backend, write_scene(tmp_path, animated=False))
    assert "animation" not in timings
    f = rest[-1]
    cube = _red(f["gbuffer.albedo"])
    want = _analytic(f["gbuffer.depth"][..., 0].astype(np.float64), cube, 0.5)
    assert still(f["gbuffer.velocity"])
    assert np.abs(f["gbuffer.velocity"] - want)[cube].max() > 100 * TOLERANCE


def test_the_cube_moves_in_the_image(backend, tmp_path):
    """The red pixels' centroid in the tonemapped image moves by the cube centre's screen
    motion from frame 0 to frame 2 (within a pixel: the centroid of the visible faces is
    not the centre's projection); without the animation it stays exactly put."""
    moving, _ = _frames(backend, write_scene(tmp_path), outputs=("tonemap.ldr",), sets=())
    still, _ = _frames(backend, write_scene(tmp_path, animated=False), outputs=("tonemap.ldr",),
                       sets=())
    shift = _center_shift()
    moved = _centroid_x(_red(moving[2]["tonemap.ldr"])) - _centroid_x(_red(moving[0][
        "tonemap.ldr"]))
    stayed = _centroid_x(_red(still[2]["tonemap.ldr"])) - _centroid_x(_red(still[0][
        "tonemap.ldr"]))
    assert shift > 4.0
    assert abs(moved - shift) < 1.0, (moved, shift)
    assert stayed == 0.0 and abs(stayed - shift) > 1.0


def test_a_cube_scaled_up_from_zero_pops_in_without_motion(backend, tmp_path):
    """A node at scale 0 (valid glTF: the loader would skip it were it still) that a STEP
    channel scales to 1 at 0.25 s: nothing red in frame 0, the cube in frame 1 with no
    motion (last frame it had no shape to move from); the same file with the cube at
    scale 1 throughout (the control) shows it in frame 0."""
    pop = ("scale", "STEP", [0.0, 0.25, 1.0], [[0, 0, 0], [1, 1, 1], [1, 1, 1]])
    frames, _ = _frames(backend, write_scene(tmp_path, channel=pop, cube={"scale": [0, 0, 0]}))
    assert not _red(frames[0]["gbuffer.albedo"]).any()
    cube = _red(frames[1]["gbuffer.albedo"])
    assert cube.sum() > 40 and still(frames[1]["gbuffer.velocity"])
    kept = ("scale", "STEP", [0.0, 0.25, 1.0], [[1, 1, 1]] * 3)
    control, _ = _frames(backend, write_scene(tmp_path, channel=kept, name="still.gltf"))
    assert _red(control[0]["gbuffer.albedo"]).sum() == cube.sum()


@pytest.mark.parametrize("config", ["deferred_vis.toml", "meshlet.toml"])
def test_the_visibility_buffer_and_the_meshlets_follow_too(vk_device, tmp_path, config):
    """vk's other G-buffers read their own copies of the instance rows (the scene tables'
    and the meshlets'): the cube moves in their images as in the raster one's; the still
    file (the control) keeps it put."""
    backend = ("vk", vk_device)
    shifts = []
    for animated in (True, False):
        got, _ = _frames(backend, write_scene(tmp_path, animated=animated), config=config,
                         outputs=("tonemap.ldr",), sets=())
        shifts.append(_centroid_x(_red(got[2]["tonemap.ldr"]))
                      - _centroid_x(_red(got[0]["tonemap.ldr"])))
    assert abs(shifts[0] - _center_shift()) < 1.0 and shifts[1] == 0.0, shifts


@pytest.fixture
def rt_device(vk_device):
    for cap in ("VK_KHR_acceleration_structure", "VK_KHR_ray_tracing_pipeline",
                "buffer_device_address"):
        if cap not in vk_device.caps:
            pytest.skip(f"no {cap}")
    return "vk", vk_device


@pytest.mark.parametrize("refit", [False, True])
def test_the_tlas_follows_the_animation(rt_device, tmp_path, monkeypatch, refit):
    """``rt_primary``'s albedo (primary rays through the TLAS, rebuilt or refit each frame)
    shows the cube where the raster G-buffer does, frame by frame; a TLAS left at the rest
    pose (the negative control) keeps it at frame 0's place."""
    scene = write_scene(tmp_path)
    raster, _ = _frames(rt_device, scene, outputs=("gbuffer.albedo",), sets=())
    traced, timings = _frames(rt_device, scene, config="rt_primary.toml",
                              outputs=("primary.albedo",),
                              sets=(f"accel.allow_update={str(refit).lower()}",))
    assert timings["accel"]["frame_builds"]["update" if refit else "build"] >= 3
    for r, t in zip(raster, traced, strict=True):
        a, b = _red(r["gbuffer.albedo"]), _red(t["primary.albedo"])
        assert abs(_centroid_x(a) - _centroid_x(b)) < 0.25 and (a != b).mean() < 0.02

    from vkext.accel import SceneAccel

    monkeypatch.setattr(SceneAccel, "move", lambda self, transforms: None)
    frozen, _ = _frames(rt_device, scene, config="rt_primary.toml",
                        outputs=("primary.albedo",),
                        sets=(f"accel.allow_update={str(refit).lower()}",))
    last = _red(raster[2]["gbuffer.albedo"])
    assert abs(_centroid_x(last) - _centroid_x(_red(frozen[2]["primary.albedo"]))) > 4.0


def test_the_path_tracer_restarts_when_the_cube_moves(rt_device, tmp_path):
    """``pt.error``'s alpha counts the samples in the sums: one per frame since the last
    restart. The cube moves every frame, so each frame starts again (1 sample); the still
    file (the control) sums all four frames (the warm-up one and three timed)."""
    sets = ("pt.max_bounces=1",)
    moving, _ = _frames(rt_device, write_scene(tmp_path), config="pathtrace.toml",
                        outputs=("pt.error",), sets=sets)
    still, _ = _frames(rt_device, write_scene(tmp_path, animated=False),
                       config="pathtrace.toml", outputs=("pt.error",), sets=sets)
    assert np.all(moving[2]["pt.error"][..., 3] == 1.0)
    assert np.all(still[2]["pt.error"][..., 3] == 4.0)
