"""rfw.RayScene from several threads (issue 21, item 6): casts take turns on the device's
lock, and every thread gets the hits a serial cast gives (four threads on one scene got
VkNotReady or other threads' hits before). Vulkan with ray queries (lavapipe has them)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import rfw

from ..golden_util import changed_share

pytest.importorskip("vulkan")


def _mesh(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    v = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    return v, rng.integers(0, 300, (120, 3))


@pytest.mark.parametrize("threads", [4, 6])
def test_threads_casting_on_one_scene_get_the_serial_hits(threads):
    rng = np.random.default_rng(7)
    v, idx = _mesh(rng)
    try:
        scene = rfw.RayScene(v, idx, batch=1500)  # several batches per cast: more to race
    except rfw.RfwError as e:
        pytest.skip(str(e))
    rays = []
    for _ in range(threads):
        o = rng.uniform(-2, 2, (4000, 3))
        rays.append((o, -o + rng.normal(0, 0.3, o.shape)))
    with scene:
        serial = [scene.cast(o, d) for o, d in rays]
        got: list[list[dict]] = [[] for _ in range(threads)]
        errors: list[BaseException] = []
        start = threading.Barrier(threads)

        def work(k: int) -> None:
            try:
                start.wait()
                for _ in range(3):
                    got[k].append(scene.cast(*rays[k]))
                    assert scene.last["rays"] == 4000
            except BaseException as e:  # handed to the test thread
                errors.append(e)

        pool = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
        for t in pool:
            t.start()
        for t in pool:
            t.join(timeout=300)
        assert not errors, errors
    for k in range(threads):
        assert len(got[k]) == 3
        for hits in got[k]:
            for key in serial[k]:
                np.testing.assert_array_equal(hits[key], serial[k][key], err_msg=key)
    # control: the ray sets differ, so another thread's hits would not pass as one's own
    hit = [s["primitive"] >= 0 for s in serial]
    assert all(h.mean() > 0.5 for h in hit)
    assert changed_share(serial[0]["t"], serial[1]["t"], over=0) > 0.5  # every ray


def test_a_scene_closed_by_another_thread_refuses_cleanly():
    rng = np.random.default_rng(3)
    v, idx = _mesh(rng)
    try:
        scene = rfw.RayScene(v, idx)
    except rfw.RfwError as e:
        pytest.skip(str(e))
    o = rng.uniform(-2, 2, (2000, 3))
    d = -o
    outcomes: list[str] = []

    def cast() -> None:
        for _ in range(5):
            try:
                scene.cast(o, d)
                outcomes.append("hit")
            except rfw.RfwError as e:  # after the close: one line naming the scene
                assert "closed" in str(e)
                outcomes.append("closed")

    t = threading.Thread(target=cast)
    t.start()
    scene.close()
    t.join(timeout=300)
    assert len(outcomes) == 5 and outcomes[-1] == "closed"
    assert outcomes == sorted(outcomes, key=lambda x: x != "hit")  # hits, then refusals


def test_a_bad_device_is_one_line_naming_it():
    v, idx = _mesh(np.random.default_rng(1))
    for bad in ("gpu0", 0, object()):
        with pytest.raises(rfw.RfwTypeError, match=r"^rfw\.RayScene: 'device' must be a "
                                                    r"vkext\.VkDevice"):
            rfw.RayScene(v, idx, device=bad)
    from vkext import VkDevice, VkUnavailableError

    try:
        dev = VkDevice(label="dead")
    except VkUnavailableError as e:
        pytest.skip(str(e))
    dev.destroy()
    with pytest.raises(rfw.RfwValueError, match="'device' was destroyed"):
        rfw.RayScene(v, idx, device=dev)
