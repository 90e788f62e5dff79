"""Review fixes for cameras and run outputs, through the CLI in a subprocess as users run it:
``--set camera.path.*`` in any order, slerp between opposite directions, ``camera.up``
checked, ``--scene ""`` refused, and no earlier ``OUT/frames`` image left behind."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from PIL import Image

from ..cli.warm import warm_cli
from .test_camera_path import FLAT, SIZE, refused

# two keys from one eye, looking opposite ways (+z, then -z)
KEYS = ("camera.path.keys=[{position=[0,1,0],target=[0,1,5]},"
        "{position=[0,1,0],target=[0,1,-5]}]")
SLERP = "camera.path.target_interpolation=slerp"


def run(out: Path, *args: str, frames: int = 2) -> dict:
    """``rfw run`` that succeeds quietly (no warning on stderr); its timings.json."""
    done = warm_cli("run", str(FLAT), "--size", SIZE, "--frames", str(frames), "--out",
                    str(out), *args)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
    return json.loads((out / "timings.json").read_text())


def sets(*items: str) -> list[str]:
    return [a for s in items for a in ("--set", s)]


def image(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA")).astype(int)


# -- 1. a path's kind follows from its keys, in any --set order -----------------------------


def test_keyframe_keys_imply_keyframes_in_any_order(tmp_path):
    a = run(tmp_path / "a", *sets(SLERP, KEYS))
    b = run(tmp_path / "b", *sets(KEYS, SLERP))
    for rec in (a, b):
        assert rec["camera_path"]["kind"] == "keyframes"
        assert [f["target"] for f in rec["camera_path"]["frames"]] == [[0.0, 1.0, 5.0],
                                                                       [0.0, 1.0, -5.0]]
    assert np.array_equal(image(tmp_path / "a" / "flat.color.png"),
                          image(tmp_path / "b" / "flat.color.png"))
    # target_interpolation alone is keyframe-only too: keyframes, which need keys
    refused(tmp_path, *sets(SLERP), needles=("--set camera.path.keys", "two keyframes"))


def test_orbit_keys_imply_an_orbit_in_any_order(tmp_path):
    a = run(tmp_path / "a", *sets("camera.path.turns=0.25", "camera.path.radius=9"))
    b = run(tmp_path / "b", *sets("camera.path.radius=9", "camera.path.turns=0.25"))
    assert a["camera_path"] == {**b["camera_path"], "frames": a["camera_path"]["frames"]}
    assert a["camera_path"]["kind"] == "orbit"
    eyes = [f["position"] for f in a["camera_path"]["frames"]]
    assert eyes == [f["position"] for f in b["camera_path"]["frames"]]
    for f in a["camera_path"]["frames"]:  # 9 from the center it looks at
        (x, _, z), (cx, _, cz) = f["position"], f["target"]
        assert math.isclose(math.hypot(x - cx, z - cz), 9.0, rel_tol=1e-6)


def test_mixed_path_kinds_are_one_line(tmp_path):
    for order in ((KEYS, "camera.path.radius=2"), ("camera.path.radius=2", KEYS),
                  (SLERP, "camera.path.turns=1"), ("camera.path.turns=1", SLERP)):
        line = refused(tmp_path, *sets(*order), needles=("--set camera.path",))
        assert "mixes keyframe keys" in line and "orbit keys" in line
    # an explicit kind against the other kind's key: one line naming that key
    refused(tmp_path, *sets("camera.path.kind=orbit", SLERP),
            needles=("--set camera.path.target_interpolation", "an orbit has no"))
    refused(tmp_path, *sets(KEYS, "camera.path.kind=orbit"),
            needles=("--set camera.path.keys", "an orbit has no"))


# -- 2. slerp between opposite view directions ------------------------------------------------


def test_slerp_between_opposite_directions_turns_around_up(tmp_path):
    out = tmp_path / "o"
    rec = run(out, *sets(SLERP, KEYS), "--save-every", "1", frames=3)
    targets = np.array([f["target"] for f in rec["camera_path"]["frames"]])
    assert np.isfinite(targets).all()
    # halfway: a quarter turn around the camera's up (+y), still 5 away, level with the eye
    assert np.allclose(targets[1], [5.0, 1.0, 0.0], atol=1e-9)
    frames = [image(out / "frames" / f"flat.color.{k:04d}.png") for k in range(3)]
    assert all(np.abs(x - y).max() > 0 for i, x in enumerate(frames) for y in frames[i + 1:])
    # control: a direction just off the opposite one has one great circle, the same side
    near = run(tmp_path / "near", *sets(SLERP, KEYS.replace("target=[0,1,-5]",
                                                            "target=[0.01,1,-5]")), frames=3)
    mid = np.array(near["camera_path"]["frames"][1]["target"])
    assert np.allclose(mid, targets[1], atol=0.05) and not np.allclose(mid, targets[1])


# -- 4. no earlier frame image survives a later run -------------------------------------------


def test_a_run_clears_earlier_frame_images(tmp_path):
    out = tmp_path / "o"
    run(out, *sets("camera.path=orbit"), "--save-every", "1", frames=3)
    assert sorted(p.name for p in (out / "frames").iterdir()) == [
        f"flat.color.{k:04d}.png" for k in range(3)]
    # fewer frames: the earlier third frame goes
    run(out, *sets("camera.path=orbit"), "--save-every", "1", frames=2)
    assert sorted(p.name for p in (out / "frames").iterdir()) == [
        "flat.color.0000.png", "flat.color.0001.png"]
    # without --save-every: no frame image is left (and the emptied folder goes)
    run(out)
    assert not (out / "frames").exists()
    # control: a file of the user's in the folder is kept, only frame images go
    run(out, *sets("camera.path=orbit"), "--save-every", "1", frames=2)
    (out / "frames" / "notes.txt").write_text("mine")
    run(out)
    assert [p.name for p in (out / "frames").iterdir()] == ["notes.txt"]


# -- 5. camera.up --------------------------------------------------------------------------


def test_bad_up_is_one_line(tmp_path):
    refused(tmp_path, *sets("camera.up=0,0,0"), needles=("--set camera.up", "zero"))
    refused(tmp_path, *sets("camera.up=[0, nan, 0]"), needles=("--set camera.up", "finite"))
    refused(tmp_path, *sets("camera.up=[0, inf, 0]"), needles=("--set camera.up", "finite"))
    refused(tmp_path, *sets("camera.position=0,5,0", "camera.target=0,0,0",
                            "camera.up=0,-2,0"), needles=("--set camera.up", "parallel"))


def test_good_up_rolls_the_image(tmp_path):
    # the control: a valid up is used, not replaced (a rolled camera shows another image)
    view = ("camera.position=6,3,7", "camera.target=0,1,0")
    run(tmp_path / "a", *sets(*view, "camera.up=0,1,0"))
    run(tmp_path / "b", *sets(*view))
    run(tmp_path / "c", *sets(*view, "camera.up=1,0,0"))
    a, b, c = (image(tmp_path / d / "flat.color.png") for d in "abc")
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() > 0


# -- 6. --scene "" ---------------------------------------------------------------------------


def test_empty_scene_is_one_line(tmp_path):
    refused(tmp_path, "--scene", "", needles=("--scene", "names no scene"))
    refused(tmp_path, "--scene", "  ", needles=("--scene", "names no scene"))
    refused(tmp_path, "--set", "scene=", needles=("scene", "names no scene"))
    refused(tmp_path, "--scene", "", needles=("--scene", "names no scene"), command="view")
    # control: a scene that is named renders
    rec = run(tmp_path / "ok", "--scene", "default")
    assert rec["scene"]
