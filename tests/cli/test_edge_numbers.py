"""Numbers and environment variables at the edges, through the real CLI (issue 21, item 8;
forked from a warm one, tests/cli/warm.py).

Bad ``RFW_*`` values (one case or more per variable), camera numbers that are finite in
float64 but not in float32, cameras whose float32 matrices keep no picture (huge positions,
singular views, up along the view), camera paths that leave the range, and ``--backend ''``:
each is exit 2 and one line ``rfw: error: ...`` naming the variable or the key, with no
traceback, and the ``--out`` folder of an earlier good run is left byte for byte as it was
(nothing else in the working folder is written either). Valid values (``RFW_FETCH=0`` and
``1``, an empty value, a camera far out but in range, a path within it) still run: the
negative controls. Renders are 32x18, one frame.

The camera checks themselves (no GPU) are measured at the end: over 5,000 random cameras
with coordinates up to 1e30, every camera ``check_camera`` accepts packs into a finite camera
uniform without an exception, and without the check about 1,500 of them do not (the control)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from .warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
FLAT = ROOT / "configs" / "flat.toml"
RUN = ["run", str(FLAT), "--size", "32x18", "--frames", "1"]
TIMEOUT = 300
A_FILE = str(ROOT / "README.md")  # a path that is a file, not a folder

# (id, extra env, extra args, what the one line must name)
ENV_CASES = [
    ("fetch-maybe", {"RFW_FETCH": "maybe"}, [], "RFW_FETCH: expected 0 or 1"),
    ("fetch-2", {"RFW_FETCH": "2"}, [], "RFW_FETCH: expected 0 or 1"),
    ("fetch-bad-scene", {"RFW_FETCH": "sure"}, ["--scene", "boxtextured"], "RFW_FETCH"),
    ("bundles-maybe", {"RFW_VK_BUNDLES": "maybe"}, [], "RFW_VK_BUNDLES: expected 0 or 1"),
    ("bundles-maybe-vk", {"RFW_VK_BUNDLES": "maybe"}, ["--backend", "vk"], "RFW_VK_BUNDLES"),
    ("replay-2", {"RFW_VK_FRAME_REPLAY": "2"}, [], "RFW_VK_FRAME_REPLAY: expected 0 or 1"),
    ("span-x", {"RFW_VK_FRAME_SPAN": "x"}, [], "RFW_VK_FRAME_SPAN: expected 0 or 1"),
    ("async-fast", {"RFW_VK_ASYNC_QUEUE": "fast"}, [],
     "RFW_VK_ASYNC_QUEUE: expected family or graphics, not 'fast'"),
    ("raycast-yes", {"RFW_RAYCAST_MAPPED": "yes"}, [], "RFW_RAYCAST_MAPPED: expected 0, 1"),
    ("gpu-word", {"RFW_GPU": "gpu0"}, [], "RFW_GPU: expected a device index"),
    ("gpu-negative", {"RFW_GPU": "-1"}, [], "RFW_GPU: expected a device index"),
    ("gpu-superscript", {"RFW_GPU": "²"}, [], "RFW_GPU: expected a device index"),
    ("in-flight-0", {"RFW_FRAMES_IN_FLIGHT": "0"}, [], "RFW_FRAMES_IN_FLIGHT: expected a whole"),
    ("in-flight-9", {"RFW_FRAMES_IN_FLIGHT": "9"}, [], "RFW_FRAMES_IN_FLIGHT: "),
    ("in-flight-float", {"RFW_FRAMES_IN_FLIGHT": "2.0"}, [], "RFW_FRAMES_IN_FLIGHT: "),
    ("seed-word", {"RFW_ORDER_SEED": "seven"}, [], "RFW_ORDER_SEED: expected a seed"),
    ("seed-big", {"RFW_ORDER_SEED": str(2**32)}, [], "RFW_ORDER_SEED: expected a seed"),
    ("poison-maybe", {"RFW_POISON": "maybe"}, [], "RFW_POISON: expected 0 or 1"),
    ("view-format", {"RFW_VIEW_FORMAT": "rgba16float"}, [], "RFW_VIEW_FORMAT: expected"),
    ("commit-two-words", {"RFW_COMMIT": "a b"}, [], "RFW_COMMIT: expected a commit"),
    ("cache-file", {"RFW_CACHE": A_FILE}, [], "RFW_CACHE: expected a folder"),
    ("spirv-cache-file", {"RFW_CACHE_SPIRV": A_FILE}, [], "RFW_CACHE_SPIRV: expected a folder"),
    ("meshlet-cache-file", {"RFW_CACHE_MESHLETS": A_FILE}, [],
     "RFW_CACHE_MESHLETS: expected a folder"),
    ("backend-empty", {}, ["--backend", ""], "--backend"),
    ("backend-spaces", {}, ["--backend", "  "], "--backend"),
]

CAMERA_CASES = [
    ("position-f32-overflow", ["camera.position=1e39,0,0"], "camera.position"),
    ("position-f32-overflow-neg", ["camera.position=0,-3.5e38,0"], "camera.position"),
    ("position-1e30", ["camera.position=1e30,0,0"], "camera.position"),
    ("position-1e20", ["camera.position=0,1e20,5"], "camera.position"),
    ("position-1e10", ["camera.position=1e10,1,5"], "camera.position"),
    ("position-1e30-with-target", ["camera.position=1e30,0,0", "camera.target=0,0,0"],
     "camera.position"),
    ("position-toml-inf", ["camera.position=[inf, 0, 0]"], "camera.position"),
    ("target-f32-overflow", ["camera.target=1e39,0,0"], "camera.target"),
    ("up-f32-overflow", ["camera.up=0,1e39,0"], "camera.up"),
    ("up-zero", ["camera.up=0,0,0"], "camera.up"),
    ("up-along-view", ["camera.position=0,5,0", "camera.target=0,0,0", "camera.up=0,1,0"],
     "camera.up"),
    # the default scene's camera looks at (3, 2, -3): checked with the scene's target
    ("up-along-view-scene-target", ["camera.position=3,9,-3", "camera.up=0,-2,0"], "camera.up"),
    ("same-position-target", ["camera.position=1,2,3", "camera.target=1,2,3"], "camera"),
    ("yfov-0", ["camera.yfov=0"], "camera.yfov"),
    ("yfov-180", ["camera.yfov=180"], "camera.yfov"),
    ("yfov-f32-overflow", ["camera.yfov=1e39"], "camera.yfov"),
    ("znear-f32-overflow", ["camera.znear=1e39"], "camera.znear"),
    ("zfar-f32-overflow", ["camera.zfar=1e39"], "camera.zfar"),
    ("near-past-far", ["camera.znear=10", "camera.zfar=1"], "camera"),
    ("near-equals-far", ["camera.znear=5", "camera.zfar=5"], "camera"),
    ("depth-range-too-thin", ["camera.position=3e4,0,0", "camera.target=0,0,0",
                              "camera.znear=1", "camera.zfar=1.001"], "camera.position"),
    ("path-center-f32-overflow", ["camera.path.center=1e39,0,0"], "camera.path.center"),
    ("path-center-1e30", ["camera.path.center=1e30,0,0"], "camera.path"),
    ("path-radius-f32-overflow", ["camera.path.radius=1e39"], "camera.path.radius"),
    ("path-height-f32-overflow", ["camera.path.height=1e39"], "camera.path.height"),
    ("path-up-along-orbit", ["camera.up=0,1,0", "camera.path.radius=1e-6",
                             "camera.path.height=3"], "camera.path"),
]

# a config file of its own: the keys of a table and of a keyframe path
CONFIG_CASES = [
    ("file-position-f32", "[camera]\nposition = [1e39, 0, 0]\n", "camera.position"),
    ("file-position-1e30", "[camera]\nposition = [1e30, 0, 0]\ntarget = [0, 0, 0]\n",
     "camera.position"),
    ("file-key-f32", "[camera.path]\nkeys = [{ position = [0, 1, 5] }, "
                     "{ position = [1e39, 1, 5] }]\n", "camera.path.keys[1].position"),
    ("file-key-far", "[camera.path]\nkeys = [{ position = [0, 1, 5] }, "
                     "{ position = [1e25, 1, 5] }]\n", "camera.path.keys[1].position"),
    ("file-key-on-target", "[camera]\ntarget = [0, 0, 0]\n[camera.path]\nkeys = "
                           "[{ position = [0, 1, 5] }, { position = [0, 0, 0] }]\n",
     "camera.path.keys[1]"),
    ("file-key-target-f32", "[camera.path]\nkeys = [{ position = [0, 1, 5] }, "
                            "{ target = [0, -1e39, 0] }]\n", "camera.path.keys[1].target"),
]

GOOD_CASES = [
    ("fetch-0", {"RFW_FETCH": "0"}, []),
    ("fetch-1", {"RFW_FETCH": "1"}, []),
    ("empty-values-are-unset", {"RFW_FETCH": "", "RFW_GPU": " ", "RFW_VK_BUNDLES": "",
                                "RFW_FRAMES_IN_FLIGHT": ""}, []),
    ("switch-spellings", {"RFW_VK_BUNDLES": "off", "RFW_VK_FRAME_REPLAY": "0",
                          "RFW_POISON": "no", "RFW_VK_FRAME_SPAN": "false"}, []),
    ("in-range-camera", {}, ["--set", "camera.position=3e4,2,0", "--set",
                             "camera.target=29990,0,0", "--set", "camera.zfar=1e5"]),
    ("in-range-path", {}, ["--set", "camera.path.center=0,0,0", "--set",
                           "camera.path.radius=8"]),
    ("top-down-with-default-up", {}, ["--set", "camera.position=0,9,0", "--set",
                                      "camera.target=0,0,0"]),
]


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every file and folder under ``folder`` (hidden ones too): its bytes, or None."""
    out: dict[str, bytes | None] = {}
    for p in sorted(folder.rglob("*")):
        out[str(p.relative_to(folder))] = p.read_bytes() if p.is_file() else None
    return out


def _env(base: Path, extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("RFW_")}
    env.update(HOME=str(base / "home"), XDG_CACHE_HOME=str(base / "cache"),
               PYTHONDONTWRITEBYTECODE="1", **extra)
    return env


def _rfw(args: list[str], cwd: Path, base: Path, extra: dict[str, str]
         ) -> subprocess.CompletedProcess:
    return warm_cli(*args, cwd=cwd, environ=_env(base, extra), timeout=TIMEOUT)


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> tuple[Path, Path]:
    """One good run's --out folder (and the shared home and caches, warm)."""
    base = tmp_path_factory.mktemp("edge")
    (base / "home").mkdir()
    done = _rfw([*RUN, "--out", str(base / "good")], base, base, {})
    assert done.returncode == 0, done.stderr
    assert {"flat.color.png", "timings.json"} <= set(os.listdir(base / "good"))
    return base, base / "good"


def _case(good: tuple[Path, Path], name: str) -> tuple[Path, Path]:
    base, out = good
    cwd = base / "cases" / name
    cwd.mkdir(parents=True)
    shutil.copytree(out, cwd / "out")
    return base, cwd


def _refused(good: tuple[Path, Path], name: str, args: list[str], extra: dict[str, str],
             says: str, *, config: Path | None = None) -> str:
    base, cwd = _case(good, name)
    if config is not None:
        shutil.copy(config, cwd / config.name)
    before = _snapshot(cwd)
    done = _rfw([*args, "--out", "out"], cwd, base, extra)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    assert "Traceback" not in done.stderr, done.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    assert says in lines[0], lines[0]
    assert _snapshot(cwd) == before  # --out as the good run left it; nothing else written
    return lines[0]


@pytest.mark.parametrize(("name", "extra", "args", "says"), ENV_CASES,
                         ids=[c[0] for c in ENV_CASES])
def test_a_bad_environment_value_is_one_line(good, name, extra, args, says):
    _refused(good, name, [*RUN, *args], extra, says)


@pytest.mark.parametrize(("name", "sets", "says"), CAMERA_CASES,
                         ids=[c[0] for c in CAMERA_CASES])
def test_a_camera_float32_cannot_hold_is_one_line_naming_the_key(good, name, sets, says):
    args = [a for s in sets for a in ("--set", s)]
    _refused(good, name, [*RUN, *args], {}, says)


@pytest.mark.parametrize(("name", "table", "says"), CONFIG_CASES,
                         ids=[c[0] for c in CONFIG_CASES])
def test_a_config_camera_float32_cannot_hold_names_file_and_key(good, tmp_path, name, table,
                                                                  says):
    config = tmp_path / f"{name}.toml"
    config.write_text(FLAT.read_text() + "\n" + table)
    line = _refused(good, name, [*RUN[:1], config.name, *RUN[2:]], {}, says, config=config)
    assert f"{name}.toml" in line  # the file is named


@pytest.mark.parametrize(("name", "extra", "args"), GOOD_CASES,
                         ids=[c[0] for c in GOOD_CASES])
def test_valid_values_still_run(good, name, extra, args):
    base, cwd = _case(good, name)
    done = _rfw([*RUN, *args, "--out", "out"], cwd, base, extra)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "rfw: error" not in done.stderr and "Traceback" not in done.stderr
    assert (cwd / "out" / "flat.color.png").is_file()


def test_checked_cameras_pack_and_unchecked_ones_do_not():
    """The property behind the camera checks: 5,000 seeded random cameras (coordinates to
    1e30 either sign, znear 1e-6 to 1e9, zfar above it, yfov and aspect over their ranges).
    Every camera check_camera accepts packs into a finite float32 camera uniform with no
    exception; the control packs all of them and sees many fail."""
    from rfw.backends.scene_data import main_camera_bytes
    from rfw.camera_path import check_camera
    from rfw.errors import RfwError
    from rfw.scene.model import Camera

    rng = np.random.default_rng(21)
    accepted = failed_checked = failed_unchecked = 0
    for _ in range(5_000):
        pos = tuple(float(s * 10 ** e) for s, e in zip(rng.choice([-1, 1], 3),
                                                      rng.uniform(-6, 30, 3), strict=True))
        far = rng.random() < 0.5
        tgt = tuple(float(s * 10 ** e) for s, e in zip(rng.choice([-1, 1], 3),
                                                      rng.uniform(-6, 30, 3), strict=True)) \
            if far else tuple(p + float(rng.uniform(-1, 1)) for p in pos)
        n = float(10 ** rng.uniform(-6, 9))
        z = min(1e9, n * float(10 ** rng.uniform(0.001, 15)))
        if not n < z or pos == tgt:
            continue
        cam = Camera(position=pos, target=tgt, yfov=float(np.radians(rng.uniform(0.01, 179))),
                     znear=n, zfar=z)
        size = (int(rng.integers(1, 16385)), int(rng.integers(1, 16385)))
        try:
            check_camera(cam, file=None, element="camera", aspect=size[0] / size[1])
            ok = True
        except RfwError:
            ok = False
        try:
            with np.errstate(all="ignore"):
                packed = np.frombuffer(main_camera_bytes(cam, size), np.float32)
            good_pack = bool(np.all(np.isfinite(packed)))
        except (OverflowError, np.linalg.LinAlgError, RfwError):
            good_pack = False
        accepted += ok
        failed_checked += ok and not good_pack
        failed_unchecked += not good_pack
    assert accepted > 500 and failed_checked == 0
    assert failed_unchecked > 500  # control: without the check these reach the GPU
