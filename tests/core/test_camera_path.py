"""Cameras from config and --set, glTF cameras by name or index, and camera paths driving
``rfw run`` (keyframes and orbits): through the CLI in a subprocess, as users run it."""

from __future__ import annotations

import base64
import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rfw.camera_path import CameraPath, check_path
from rfw.errors import RfwError
from rfw.scene import Camera

from ..cli.warm import warm_cli
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
FLAT = ROOT / "configs" / "flat.toml"
SIZE = "32x18"


def run(out: Path, *args: str, config: Path = FLAT,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    done = warm_cli("run", str(config), "--size", SIZE, "--out", str(out), *args, env=env)
    assert done.returncode == 0, done.stderr
    return done


def image(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA"))


def refused(tmp_path: Path, *args: str, needles: tuple[str, ...],
            command: str = "run") -> str:
    """The CLI refuses: exit 2, one line naming ``needles``, no traceback, nothing
    written outside --out (the working folder stays empty)."""
    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    out = tmp_path / "o"
    extra = ["--out", str(out), "--frames", "2"] if command == "run" else []
    done = warm_cli(command, str(FLAT), "--size", SIZE, *extra, *args, cwd=work)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    assert "Traceback" not in done.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert list(work.iterdir()) == []
    assert not (out / "timings.json").exists()
    return lines[0]


# -- the path itself (no GPU) ---------------------------------------------------------------

BASE = Camera((0.0, 1.0, 5.0), (0.0, 0.0, 0.0))
KEYS = [{"position": [0.0, 1.0, 5.0], "target": [0.0, 0.0, 0.0]},
        {"position": [4.0, 2.0, 3.0], "target": [1.0, 0.5, 0.0], "yfov": 40.0},
        {"position": [5.0, 1.0, -1.0], "target": [0.0, 1.0, 0.0]}]


def test_keyframes_hit_their_keys_exactly():
    path = CameraPath(check_path({"keys": KEYS}, "t"), BASE)
    assert path.kind == "keyframes"
    first, mid, last = (path.camera(k, 5) for k in (0, 2, 4))
    assert first.position == (0.0, 1.0, 5.0) and first.target == (0.0, 0.0, 0.0)
    assert mid.position == (4.0, 2.0, 3.0) and mid.yfov == pytest.approx(math.radians(40))
    assert last.position == (5.0, 1.0, -1.0) and last.target == (0.0, 1.0, 0.0)
    # between keys: linear in position (and field of view)
    between = path.camera(1, 5)
    assert np.allclose(between.position, [2.0, 1.5, 4.0])
    assert between.yfov == pytest.approx((math.radians(60) + math.radians(40)) / 2)
    assert path.camera(0, 1).position == first.position  # one frame: the first key


def test_slerp_turns_the_view_direction():
    keys = [{"position": [0.0, 0.0, 0.0], "target": [0.0, 0.0, -2.0]},
            {"position": [0.0, 0.0, 0.0], "target": [4.0, 0.0, 0.0]}]
    slerp = CameraPath(check_path({"keys": keys, "target_interpolation": "slerp"}, "t"), BASE)
    linear = CameraPath(check_path({"keys": keys}, "t"), BASE)
    at = np.array(slerp.at(0.5).target)
    # halfway round the quarter turn, at the mean distance (3)
    assert np.allclose(at, 3.0 * np.array([math.sqrt(0.5), 0.0, -math.sqrt(0.5)]))
    assert np.allclose(linear.at(0.5).target, [2.0, 0.0, -1.0])  # control: a chord


def test_orbit_circles_the_center():
    path = CameraPath(check_path({"kind": "orbit", "center": [1.0, 0.0, 0.0], "radius": 2.0,
                                  "height": 0.5, "start": 90.0, "turns": 1.0}, "t"), BASE)
    eyes = np.array([path.camera(k, 4).position for k in range(4)])
    assert np.allclose(eyes[0], [3.0, 0.5, 0.0])
    assert np.allclose(eyes[1], [1.0, 0.5, -2.0])
    assert np.allclose(np.hypot(eyes[:, 0] - 1.0, eyes[:, 2]), 2.0)
    assert all(path.camera(k, 4).target == (1.0, 0.0, 0.0) for k in range(4))
    # defaults: the base camera's own circle, starting where it stands
    around = CameraPath(check_path("orbit", "t"), BASE)
    assert np.allclose(around.camera(0, 8).position, BASE.position)


@pytest.mark.parametrize(("spec", "needle"), [
    ({"kind": "spiral"}, "camera.path.kind"),
    ({"keys": KEYS[:1]}, "camera.path.keys"),
    ({"keys": [{"position": [0, 0]}, KEYS[1]]}, "camera.path.keys[0].position"),
    ({"keys": [KEYS[0], {"t": 0.7, **KEYS[1]}, {"t": 0.5, **KEYS[2]}]}, "camera.path.keys"),
    ({"keys": KEYS, "radius": 2.0}, "orbit keys (radius)"),
    ({"kind": "keyframes", "keys": KEYS, "radius": 2.0}, "camera.path.radius"),
    ({"kind": "orbit", "target_interpolation": "slerp"}, "camera.path.target_interpolation"),
    ({"kind": "orbit", "radius": -1.0}, "camera.path.radius"),
    ({"kind": "orbit", "speed": 1.0}, "speed"),
    ({"keys": [KEYS[0], {"posiiton": [0, 0, 0]}]}, "did you mean 'position'"),
])
def test_bad_paths_name_the_key(spec, needle):
    with pytest.raises(RfwError) as e:
        check_path(spec, "cfg.toml")
    assert needle in str(e.value)


# -- camera keys from --set ------------------------------------------------------------------


def test_set_camera_keys_render_like_the_config(tmp_path):
    cfg = tmp_path / "cam.toml"
    cfg.write_text(FLAT.read_text() + "\n[camera]\nposition = [6.0, 3.0, 7.0]\n"
                   "target = [0.0, 1.0, 0.0]\nyfov = 45.0\nznear = 0.1\nzfar = 90.0\n")
    run(tmp_path / "a", config=cfg)
    run(tmp_path / "b", "--set", "camera.position=[6.0, 3.0, 7.0]", "--set",
        "camera.target=0,1,0", "--set", "camera.yfov=45", "--set", "camera.znear=0.1",
        "--set", "camera.zfar=90")
    run(tmp_path / "c", "--set", "camera.position=[6.0, 3.0, 7.0]", "--set",
        "camera.target=0,1,0", "--set", "camera.yfov=50", "--set", "camera.znear=0.1",
        "--set", "camera.zfar=90")
    a, b, c = (image(tmp_path / d / "flat.color.png") for d in "abc")
    assert np.array_equal(a, b)
    assert changed_share(a, c) > 0.05  # control: another field of view shows (17 %)


@pytest.mark.parametrize(("value", "needles"), [
    ("camera.yfov=abc", ("--set camera.yfov", "abc")),
    ("camera.yfov=500", ("--set camera.yfov", "179")),
    ("camera.position=1,2", ("--set camera.position", "three numbers")),
    ("camera.znear=1e6", ("camera", "znear 1e+06 must be smaller than zfar")),
    ("camera.fov=60", ("--set camera.fov", "did you mean 'yfov'")),
    ("camera.path.kind=spiral", ("--set camera.path.kind", "orbit")),
    ("camera.path.turns=many", ("--set camera.path.turns", "many")),
    ("camera.gltf=true", ("--set camera.gltf", "name or index")),
    # the default camera's own position as target: the config's file is named
    ("camera.target=-7.2,1.7,7.2", ("flat.toml: camera", "must be finite and apart")),
])
def test_bad_camera_values_are_one_line(tmp_path, value, needles):
    refused(tmp_path, "--set", value, needles=needles)


# -- paths driving rfw run ------------------------------------------------------------------

A = ("[-6.0, 4.0, 9.0]", "[0.0, 1.0, 0.0]")
B = ("[9.0, 2.5, 2.0]", "[1.0, 0.5, -1.0]")


def _path_config(tmp_path: Path) -> Path:
    cfg = tmp_path / "path.toml"
    cfg.write_text(FLAT.read_text() + f"""
[camera.path]
kind = "keyframes"
target_interpolation = "slerp"
keys = [
  {{ position = {A[0]}, target = {A[1]} }},
  {{ position = [2.0, 6.0, 8.0], target = [0.0, 0.0, 0.0], yfov = 50.0 }},
  {{ position = {B[0]}, target = {B[1]} }},
]
""")
    return cfg


def test_path_renders_each_frame_from_its_camera(tmp_path):
    cfg = _path_config(tmp_path)
    done = run(tmp_path / "p1", "--frames", "4", "--save-every", "1", config=cfg)
    assert "wrote" in done.stdout
    run(tmp_path / "p2", "--frames", "4", "--save-every", "1", config=cfg)
    frames = [image(tmp_path / "p1" / "frames" / f"flat.color.{k:04d}.png") for k in range(4)]
    again = [image(tmp_path / "p2" / "frames" / f"flat.color.{k:04d}.png") for k in range(4)]
    for k in range(4):  # deterministic: the same path gives the same frames
        assert np.array_equal(frames[k], again[k])
        for j in range(k):
            assert changed_share(frames[k], frames[j]) > 0.1, (j, k)  # 38-61 %
    timings = json.loads((tmp_path / "p1" / "timings.json").read_text())
    cams = timings["camera_path"]["frames"]
    assert [c["t"] for c in cams] == pytest.approx([0.0, 1 / 3, 2 / 3, 1.0])
    assert cams[0]["position"] == json.loads(A[0]) and cams[-1]["target"] == json.loads(B[1])
    # the run's image is its last frame's
    assert np.array_equal(image(tmp_path / "p1" / "flat.color.png"), frames[-1])

    # the first and last keyframes are the static cameras' renders, exactly
    run(tmp_path / "a", "--set", f"camera.position={A[0]}", "--set", f"camera.target={A[1]}")
    run(tmp_path / "b", "--set", f"camera.position={B[0]}", "--set", f"camera.target={B[1]}")
    assert np.array_equal(image(tmp_path / "a" / "flat.color.png"), frames[0])
    assert np.array_equal(image(tmp_path / "b" / "flat.color.png"), frames[-1])
    # frames in flight (no --save-every: nothing drains between frames on wgpu) end on the
    # same last frame
    run(tmp_path / "p3", "--frames", "4", config=cfg)
    assert np.array_equal(image(tmp_path / "p3" / "flat.color.png"), frames[-1])
    # control: a keyframe shifted by a little renders differently (17 % of the pixels)
    run(tmp_path / "s", "--set", "camera.position=[9.2, 2.5, 2.0]", "--set",
        f"camera.target={B[1]}")
    assert changed_share(image(tmp_path / "s" / "flat.color.png"), frames[-1]) > 0.05


def test_orbit_from_set_on_vk_under_validation(tmp_path):
    out = tmp_path / "o"
    done = run(out, "--backend", "vk", "--validate", "--frames", "3", "--save-every", "2",
               "--set", "camera.path=orbit", "--set", "camera.path.turns=0.5")
    assert "validation: 0 message(s)" in done.stdout
    saved = sorted(p.name for p in (out / "frames").iterdir())
    assert saved == ["flat.color.0000.png", "flat.color.0002.png"]  # every 2nd and the last
    first, last = (image(out / "frames" / n) for n in saved)
    assert changed_share(first, last) > 0.2  # 75 %
    cams = json.loads((out / "timings.json").read_text())["camera_path"]
    assert cams["kind"] == "orbit" and [c["t"] for c in cams["frames"]] == \
        pytest.approx([0.0, 1 / 3, 2 / 3])
    # half a turn over the run: the last frame's eye is 120 degrees round from the first
    eyes = np.array([c["position"] for c in cams["frames"]])
    center = np.array(cams["frames"][0]["target"])
    u, v = eyes[0] - center, eyes[-1] - center
    cos = (u[0] * v[0] + u[2] * v[2]) / (np.hypot(u[0], u[2]) * np.hypot(v[0], v[2]))
    assert cos == pytest.approx(math.cos(math.radians(120)))
    # a path off again: one static frame, no camera_path in the timings
    run(out, "--set", "camera.path=orbit", "--set", "camera.path=off")
    assert "camera_path" not in json.loads((out / "timings.json").read_text())


# -- glTF cameras ---------------------------------------------------------------------------


def _gltf_with_cameras(folder: Path) -> Path:
    """A quad facing +Z and two cameras: 'front' straight on, 'side' off to the right."""
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob = pos.tobytes() + idx.tobytes()
    half = math.sqrt(0.5)
    gltf = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [-1, -1, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "cameras": [{"name": "front", "type": "perspective",
                     "perspective": {"yfov": 1.0, "znear": 0.1, "zfar": 50}},
                    {"name": "side", "type": "perspective",
                     "perspective": {"yfov": 0.8, "znear": 0.1, "zfar": 50}}],
        "nodes": [{"mesh": 0}, {"camera": 0, "translation": [0, 0, 3]},
                  {"camera": 1, "translation": [3, 0, 3], "rotation": [0, 0.3826834, 0,
                                                                       0.9238795]},
                  {"translation": [0, 0, 0]}],
        "scenes": [{"nodes": [0, 1, 2]}], "scene": 0,
    }
    assert half  # (rotation above: 45 degrees about +Y, towards the quad)
    path = folder / "cams.gltf"
    path.write_text(json.dumps(gltf))
    return path


def test_gltf_cameras_by_name_or_index(tmp_path):
    scene = str(_gltf_with_cameras(tmp_path))
    run(tmp_path / "name", "--scene", scene, "--set", "camera.gltf=side")
    run(tmp_path / "index", "--scene", scene, "--set", "camera.gltf=1")
    run(tmp_path / "front", "--scene", scene, "--set", "camera.gltf=front")
    run(tmp_path / "first", "--scene", scene)  # no choice: the scene's first camera
    name, index, front, first = (image(tmp_path / d / "flat.color.png")
                                 for d in ("name", "index", "front", "first"))
    assert np.array_equal(name, index)
    assert np.array_equal(front, first)
    # control: the other camera sees otherwise (36 of the 576 pixels)
    assert changed_share(name, front) > 0.02
    line = refused(tmp_path, "--scene", scene, "--set", "camera.gltf=sidee",
                   needles=("camera.gltf", "'sidee'", "0: 'front', 1: 'side'",
                            "did you mean 'side'"))
    assert "cams.gltf" in line
    refused(tmp_path, "--scene", scene, "--set", "camera.gltf=2",
            needles=("camera.gltf", "index 2 is out of range", "2 camera(s)"))


# -- frames in flight ------------------------------------------------------------------------


def _drains(monkeypatch, backend: str, sets: list[str]) -> tuple[int, dict, list[int]]:
    """Executor drains (with frames in flight) of a 6-frame run of flat.toml (2 frames in
    flight) with ``sets``, and the frames in flight right after each camera write."""
    import rfw.camera_path
    from rfw.config import apply_overrides, load_config
    from rfw.render import render

    if backend == "vk":
        from vkext.executor import VkExecutor as cls
    else:
        from rfw.backends.wgpu import Executor as cls
    calls, busy = [], []
    original, write = cls.drain, rfw.camera_path.set_frame_camera

    def drain(self):
        calls.append(self.in_flight.busy)
        original(self)

    def set_frame_camera(frame, camera):
        write(frame, camera)
        busy.append(sum(ex.in_flight.busy for ex in frame.executors.values()))

    monkeypatch.setattr(cls, "drain", drain)
    monkeypatch.setattr(rfw.camera_path, "set_frame_camera", set_frame_camera)
    cfg = apply_overrides(load_config(FLAT), ["size=32x18", *sets])
    result = render(cfg, frames=6, backend=backend, validation=backend == "vk",
                    frames_in_flight=2)
    monkeypatch.setattr(cls, "drain", original)
    monkeypatch.setattr(rfw.camera_path, "set_frame_camera", write)
    return sum(1 for b in calls if b), result.timings, busy


def test_wgpu_path_keeps_frames_in_flight(monkeypatch):
    # wgpu writes the camera through the queue (after every frame submitted before it): a
    # path drains no more often than a static camera
    static, _, _ = _drains(monkeypatch, "wgpu", [])
    path, timings, _ = _drains(monkeypatch, "wgpu", ["camera.path=orbit"])
    assert len(timings["camera_path"]["frames"]) == 6
    assert path == static


def test_vk_path_keeps_frames_in_flight(monkeypatch):
    # each vk frame copies the cameras it began with from its slot's own buffer into the
    # camera uniforms (vkext.scene.VkScene.copy_camera): no camera write drains, and the
    # frames before it are still in flight when the next camera is written
    static, _, _ = _drains(monkeypatch, "vk", [])
    path, timings, busy = _drains(monkeypatch, "vk", ["camera.path=orbit"])
    assert timings["validation"]["messages"] == 0
    assert len(timings["camera_path"]["frames"]) == 6
    assert path == static
    assert len(busy) == 6 and busy[0] == 0  # the first camera: before any frame
    assert all(b > 0 for b in busy[1:]), busy
    # control: a scene that writes its camera at once (as vk's did) drains before each
    # write, so nothing is in flight when it is written
    from vkext.scene import VkScene

    monkeypatch.setattr(VkScene, "camera_per_frame", False)
    drained, _, busy = _drains(monkeypatch, "vk", ["camera.path=orbit"])
    assert drained > static
    assert busy == [0] * 6


def _frames(out: Path, output: str, n: int) -> list[np.ndarray]:
    return [image(out / "frames" / f"{output}.{k:04d}.png") for k in range(n)]


PATHS = [  # (config, output, extra --set): the sun's camera, async compute, the meshlets
    ("deferred_ssao_shadows.toml", "fxaa.color", ["async_compute=on"]),
    ("meshlet.toml", "tonemap.ldr", []),
]


@pytest.mark.parametrize(("config", "output", "extra"), PATHS)
def test_vk_path_frames_in_flight_render_each_frames_camera(tmp_path, config, output,
                                                             extra):
    """A vk path with two frames in flight, under (synchronization) validation, saves the
    frames one frame in flight saves, each from its own camera."""
    n = 5
    args = ["--backend", "vk", "--frames", str(n), "--save-every", "1", "--size", "48x27",
            "--set", "camera.path=orbit", "--set", "camera.path.turns=0.25",
            *(a for s in extra for a in ("--set", s))]
    cfg = ROOT / "configs" / config
    two = run(tmp_path / "two", "--validate", *args, config=cfg,
              env={"RFW_FRAMES_IN_FLIGHT": "2"})
    assert "validation: 0 message(s)" in two.stdout, two.stdout
    timings = json.loads((tmp_path / "two" / "timings.json").read_text())
    assert timings["frames_in_flight"] == 2  # --validate: synchronization validation too
    run(tmp_path / "one", *args, config=cfg, env={"RFW_FRAMES_IN_FLIGHT": "1"})
    two_frames, one_frames = (_frames(tmp_path / d, output, n) for d in ("two", "one"))
    for k in range(n):
        assert np.array_equal(two_frames[k], one_frames[k]), k
    for k in range(1, n):  # the camera moved: 91-99 % of the pixels differ (measured)
        assert changed_share(two_frames[k], two_frames[k - 1]) > 0.25, k
    # control: a frame from its neighbour's camera fails the comparison
    for k in range(1, n):
        assert changed_share(two_frames[k], one_frames[k - 1]) > 0.25, k
        assert changed_share(two_frames[k - 1], one_frames[k]) > 0.25, k


def test_vk_camera_copy_is_synchronized_or_validation_says_so(monkeypatch):
    """Control for the validation runs above: the copy of a frame's cameras without its
    barriers is a hazard that synchronization validation reports (so their 0 means it is
    ordered against the passes that read the cameras)."""
    from rfw.config import apply_overrides, load_config
    from rfw.render import render
    from vkext.consts import lib
    from vkext.scene import VkScene

    def unsynchronized(self, cmd, source):  # the copy alone
        lib.vkCmdCopyBuffer(cmd, source.handle, self.dynamic_uniforms.handle, 1,
                            self._camera_region)

    cfg = apply_overrides(load_config(FLAT), ["size=32x18", "camera.path=orbit"])
    ok = render(cfg, frames=4, backend="vk", validation=True, frames_in_flight=2)
    assert ok.timings["validation"]["messages"] == 0
    monkeypatch.setattr(VkScene, "copy_camera", unsynchronized)
    bad = render(cfg, frames=4, backend="vk", validation=True, frames_in_flight=2)
    texts = bad.timings["validation"]["texts"]
    assert bad.timings["validation"]["messages"] > 0
    assert any("SYNC-HAZARD-READ-AFTER-WRITE" in t for t in texts), texts[:1]
