"""glTF node animations read by the loader: each interpolation (LINEAR, STEP, CUBICSPLINE,
slerp for rotations) against values worked out by hand, a parent's animation moving its
child's instance, morph weights left out without a word, bad keyframes refused in one
line naming the animation, and the frame timeline (frame k at start + k / fps)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from rfw.backends.scene_data import InstanceFrames, posed_bounds
from rfw.config import apply_overrides, load_config
from rfw.errors import RfwError
from rfw.scene import SceneError, load_gltf
from rfw.scene.animation import Animator
from rfw.timeline import timeline_for

from .test_gltf import F32, I16, Gltf

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
EXACT = 1e-12  # float64 arithmetic on float32 keys chosen to be exact


def keys(g: Gltf, times, values, ctype: int = F32, normalized: bool = False) -> tuple[int, int]:
    return (g.accessor(np.asarray(times, np.float32)),
            g.accessor(np.asarray(values), ctype, normalized=normalized))


def animated(channels: list[tuple[str, str, list, list]], *, parent: bool = False,
             rest: dict | None = None) -> tuple[Gltf, int]:
    """A quad on a node moved by ``channels`` of (path, interpolation, times, values); with
    ``parent`` the channels move a parent node one unit up, the quad's node is its child."""
    g = Gltf()
    mesh = g.mesh(g.primitive())
    if parent:
        child = g.node(root=False, mesh=mesh, translation=[0, 1, 0])
        target = g.node(children=[child], **(rest or {}))
    else:
        target = g.node(mesh=mesh, **(rest or {}))
    samplers, chans = [], []
    for path, interpolation, times, values in channels:
        t, v = keys(g, times, values)
        samplers.append({"input": t, "output": v, "interpolation": interpolation})
        chans.append({"sampler": len(samplers) - 1, "target": {"node": target, "path": path}})
    g.doc["animations"] = [{"name": "clip", "channels": chans, "samplers": samplers}]
    return g, target


def pose(scene, t: float) -> np.ndarray:
    """The one instance's world matrix at ``t`` seconds, as the backends find it."""
    frames = InstanceFrames(scene)
    return frames.transforms(t)[0].astype(np.float64)


def z_rotation(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_linear_translation_between_and_beyond_the_keys(tmp_path):
    g, _ = animated([("translation", "LINEAR", [0, 1, 3], [[0, 0, 0], [2, 0, 0], [2, 4, 0]])])
    scene = load_gltf(g.write(tmp_path))
    (channel,) = scene.animations[0].channels
    for t, want in ((0.25, (0.5, 0, 0)), (2.0, (2, 2, 0)), (3.0, (2, 4, 0)), (7.0, (2, 4, 0))):
        np.testing.assert_allclose(channel.at(t), want, atol=EXACT)
        np.testing.assert_allclose(pose(scene, t)[:3, 3], want, atol=1e-6)  # float32 rows
    assert scene.animations[0].duration == 3.0


def test_step_holds_the_key_before(tmp_path):
    g, _ = animated([("scale", "STEP", [0, 1], [[1, 1, 1], [2, 3, 4]])])
    (channel,) = load_gltf(g.write(tmp_path)).animations[0].channels
    np.testing.assert_array_equal(channel.at(0.999), [1, 1, 1])
    np.testing.assert_array_equal(channel.at(1.0), [2, 3, 4])


def test_rotation_slerps_the_shorter_way(tmp_path):
    """90 degrees about z over 2 s: at 0.5 s a quarter of the way, 22.5 degrees (nlerp of
    the components would give 21.6: the check tells the two apart); the second key
    negated (the same rotation) takes the same short way, not 270 degrees round."""
    h = math.sqrt(0.5)
    for q1 in ([0, 0, h, h], [0, 0, -h, -h]):
        g, _ = animated([("rotation", "LINEAR", [0, 2], [[0, 0, 0, 1], q1])])
        scene = load_gltf(g.write(tmp_path))
        half = math.radians(22.5) / 2
        np.testing.assert_allclose(abs(scene.animations[0].channels[0].at(0.5) @
                                       [0, 0, math.sin(half), math.cos(half)]), 1.0,
                                   atol=EXACT)
        np.testing.assert_allclose(pose(scene, 0.5)[:3, :3], z_rotation(22.5), atol=1e-6)
    nlerp = np.array([0, 0, 0.25 * h, 0.75 + 0.25 * h])
    nlerp /= np.linalg.norm(nlerp)
    assert abs(math.degrees(2 * math.atan2(nlerp[2], nlerp[3])) - 22.5) > 0.5  # control


def test_normalized_integer_rotations(tmp_path):
    """Rotation keys as normalised shorts (glTF allows them): the same 90 degrees."""
    g = Gltf()
    node = g.node(mesh=g.mesh(g.primitive()))
    t, v = keys(g, [0, 1], [[0, 0, 0, 32767], [0, 0, 23170, 23170]], I16, normalized=True)
    g.doc["animations"] = [{"channels": [{"sampler": 0, "target": {"node": node,
                                                                   "path": "rotation"}}],
                            "samplers": [{"input": t, "output": v}]}]
    np.testing.assert_allclose(pose(load_gltf(g.write(tmp_path)), 1.0)[:3, :3],
                               z_rotation(90.0), atol=1e-6)


def test_cubic_spline_hermite(tmp_path):
    """Keys at 0 and 2 s, (in-tangent, value, out-tangent) each: at 1 s the Hermite basis is
    (1/2, 1/8, 1/2, -1/8) on (p0, 2 m0, p1, 2 m1): (0.25 + 2, -0.75, 0)."""
    values = [[9, 9, 9], [0, 0, 0], [1, 0, 0],   # key 0: in-tangent unused, out (1, 0, 0)
              [0, 3, 0], [4, 0, 0], [9, 9, 9]]   # key 1: in (0, 3, 0), out-tangent unused
    g, _ = animated([("translation", "CUBICSPLINE", [0, 2], values)])
    (channel,) = load_gltf(g.write(tmp_path)).animations[0].channels
    np.testing.assert_allclose(channel.at(1.0), [2.25, -0.75, 0.0], atol=EXACT)
    np.testing.assert_allclose(channel.at(2.0), [4, 0, 0], atol=EXACT)  # the key's value
    np.testing.assert_allclose(channel.at(0.0), [0, 0, 0], atol=EXACT)
    straight = replace(channel, interpolation="LINEAR", values=channel.values[:, 1])
    assert np.abs(straight.at(1.0) - [2.25, -0.75, 0.0]).max() > 0.2  # control: (2, 0, 0)


def test_a_parents_animation_moves_its_childs_instance(tmp_path):
    g, target = animated([("translation", "LINEAR", [0, 1], [[0, 0, 0], [4, 0, 0]])],
                         parent=True, rest={"scale": [2, 2, 2]})
    scene = load_gltf(g.write(tmp_path))
    (inst,) = scene.instances
    assert inst.node != target and scene.nodes[inst.node].parent == target
    assert Animator(scene.nodes, scene.animations).moving == {target, inst.node}
    # the parent's scale (rest: no scale channel) doubles the child's offset of 1 up
    np.testing.assert_allclose(pose(scene, 0.5)[:3, 3], [2, 2, 0], atol=1e-6)
    np.testing.assert_allclose(pose(scene, 0.5)[:3, :3], 2 * np.identity(3), atol=1e-6)
    # the rest pose (the file's node values) is what a still frame shows
    np.testing.assert_allclose(inst.transform[:3, 3], [0, 2, 0])


def test_weights_channels_are_left_out_without_a_word(tmp_path, capfd):
    g = Gltf()
    node = g.node(mesh=g.mesh(g.primitive()))
    t, v = keys(g, [0, 1], [0.0, 1.0])
    g.doc["animations"] = [{"channels": [{"sampler": 0, "target": {"node": node,
                                                                   "path": "weights"}}],
                            "samplers": [{"input": t, "output": v}]}]
    scene = load_gltf(g.write(tmp_path))
    assert scene.animations == [] and scene.nodes == [] and scene.instances[0].node is None
    assert capfd.readouterr().err == ""
    g, _ = animated([("translation", "LINEAR", [0, 1], [[0, 0, 0], [1, 0, 0]])])  # control
    assert len(load_gltf(g.write(tmp_path, "moving.gltf")).animations) == 1


def _bad(kind: str) -> Gltf:
    """An animated quad with one fault of ``kind``."""
    g, node = animated([("translation", "LINEAR", [0, 1, 2], [[0, 0, 0], [1, 0, 0],
                                                              [2, 0, 0]])])
    anim = g.doc["animations"][0]
    if kind == "sampler":
        anim["channels"][0]["sampler"] = 3
    elif kind == "accessor":
        anim["samplers"][0]["output"] = 99
    elif kind == "count":
        anim["samplers"][0]["output"] = g.accessor(np.zeros((2, 3), np.float32))
    elif kind == "times":
        anim["samplers"][0]["input"] = g.accessor(np.array([0, 1, 1], np.float32))
    elif kind == "nan":
        anim["samplers"][0]["output"] = g.accessor(np.array([[0, 0, 0], [np.nan, 0, 0],
                                                             [2, 0, 0]], np.float32))
    elif kind == "matrix":
        g.doc["nodes"][node]["matrix"] = list(np.identity(4).ravel())
    elif kind == "quaternion":
        anim["channels"][0]["target"]["path"] = "rotation"
        anim["samplers"][0]["output"] = g.accessor(np.array([[0, 0, 0, 1], [0, 0, 0, 0],
                                                             [0, 0, 0, 1]], np.float32))
    return g


BAD = {  # fault -> what its one line says
    "sampler": "animations[0] (\"clip\").channels[0]: sampler 3 is not an index into the "
               "animation's 1 samplers",
    "accessor": "output of animations[0] (\"clip\").samplers[0]: refers to accessors[99]",
    "count": "animations[0] (\"clip\").samplers[0]: output has 2 values for 3 keyframe times",
    "times": "animations[0] (\"clip\").samplers[0]: keyframe times must increase: key 2 at 1 s "
             "follows 1 s",
    "nan": "(output of animations[0] (\"clip\").samplers[0]): contains NaN or infinity",
    "matrix": "animations[0] (\"clip\").channels[0]: targets nodes[0], which has a matrix",
    "quaternion": "animations[0] (\"clip\").samplers[0]: output key 1 is a zero quaternion",
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_bad_keyframes_are_refused_naming_the_animation(tmp_path, kind):
    path = _bad(kind).write(tmp_path)
    with pytest.raises(SceneError) as e:
        load_gltf(path)
    assert str(e.value).startswith(str(path)) and "\n" not in str(e.value)
    assert BAD[kind] in str(e.value), str(e.value)


def test_the_timeline_plays_frame_k_at_start_plus_k_over_fps(tmp_path):
    g, _ = animated([("translation", "LINEAR", [0, 2], [[0, 0, 0], [4, 0, 0]])])
    scene = load_gltf(g.write(tmp_path))
    cfg = load_config(CONFIGS / "deferred.toml")
    assert timeline_for(cfg, scene).time(3) == 3 / 60  # the default: 60 frames a second
    cfg = apply_overrides(cfg, ["animation.fps=4", "animation.start=0.5"])
    line = timeline_for(cfg, scene)
    assert [line.time(k) for k in range(8)] == [0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 0.0, 0.25]
    line = timeline_for(apply_overrides(cfg, ["animation.loop=false"]), scene)
    assert line.time(7) == 2.25  # held: the channel's last value from 2 s on
    assert timeline_for(cfg, SimpleNamespace(animations=[])) is None  # a still scene
    with pytest.raises(RfwError, match=r"animation\.clip.*no animation named 'walk' "
                                       r"\(animations: 0: 'clip'\)"):
        timeline_for(apply_overrides(cfg, ["animation.clip=walk"]), scene)
    with pytest.raises(RfwError, match=r"--set animation\.fsp: unknown key 'fsp' \(did you "
                                       r"mean 'fps'\?\)"):
        apply_overrides(cfg, ["animation.fsp=3"])


def test_the_shadow_box_encloses_every_key_pose(tmp_path):
    """The sun's box (``posed_bounds``) reaches where the keys take the quad (x 0..1 moved
    by up to 4): 5, against the rest pose's 1 (the still file, the control)."""
    g, _ = animated([("translation", "LINEAR", [0, 1, 2], [[0, 0, 0], [4, 0, 0], [1, 0, 0]])])
    lo, hi = posed_bounds(load_gltf(g.write(tmp_path)))
    np.testing.assert_allclose([lo[0], hi[0]], [0.0, 5.0], atol=1e-6)
    del g.doc["animations"]
    np.testing.assert_allclose(posed_bounds(load_gltf(g.write(tmp_path, "still.gltf")))[1][0],
                               1.0)
