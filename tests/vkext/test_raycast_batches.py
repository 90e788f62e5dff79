"""How vkext.raycast cuts a cast into batches (batch_rays): one batch by default, overlap
only where measured GPU and host times are both large enough to hide behind each other,
never on a CPU device; an explicit ``batch`` still caps every batch."""

from __future__ import annotations

import numpy as np
import pytest

import rfw
from rfw.errors import RfwError
from vkext.raycast import (
    DEFAULT_BATCH,
    OVERLAP_BATCH_MS,
    OVERLAP_MIN,
    OVERLAP_PARTS,
    batch_rays,
)

N = 921_600  # 1280x720 primary rays, the cast
# H200 figures (ns per ray) of the courtyard's 921,600 primary rays: GPU 1.3-1.7 ms in
# all (copies and trace), host copies 3-8 ms
H200 = (1.7e6 / N, 3.0e6 / N)


def _batches(n: int, per: int) -> int:
    return -(-n // per)


def test_one_batch_unless_overlap_pays():
    # no measurement yet (a first cast), or the H200's: one batch
    assert batch_rays(N, DEFAULT_BATCH) == N
    assert batch_rays(N, DEFAULT_BATCH, rates=H200) == N
    # GPU and host both over OVERLAP_PARTS * OVERLAP_BATCH_MS: OVERLAP_PARTS batches
    heavy = 2 * OVERLAP_PARTS * OVERLAP_BATCH_MS * 1e6 / N
    assert _batches(N, batch_rays(N, DEFAULT_BATCH, rates=(heavy, heavy))) == OVERLAP_PARTS
    # one of them short: nothing to hide behind
    assert batch_rays(N, DEFAULT_BATCH, rates=(heavy, H200[1])) == N
    assert batch_rays(N, DEFAULT_BATCH, rates=(H200[0], heavy)) == N
    # the GPU is the host's CPU (lavapipe): never
    assert batch_rays(N, DEFAULT_BATCH, device_type="cpu", rates=(heavy, heavy)) == N
    # too few rays to part: one batch whatever the rates
    few = 2 * OVERLAP_MIN - 1
    assert batch_rays(few, DEFAULT_BATCH, rates=(1e6, 1e6)) == few


def test_batch_is_still_the_cap():
    """Negative control: an explicit ``batch`` splits whatever the rule says, and a cast
    larger than DEFAULT_BATCH goes in batches of it."""
    assert _batches(N, batch_rays(N, 100_000)) == 10
    assert _batches(N, batch_rays(N, 100_000, device_type="cpu")) == 10
    assert batch_rays(3 * DEFAULT_BATCH, DEFAULT_BATCH) == DEFAULT_BATCH
    assert batch_rays(5, DEFAULT_BATCH) == 5


_TRI = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
_FACES = np.array([[0, 1, 2]])


def _rays(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    o = np.c_[rng.uniform(-0.2, 0.8, (n, 2)), np.ones(n)].astype(np.float32)
    return o, np.tile(np.float32([0, 0, -1]), (n, 1))


def test_casts_follow_the_rule(vk_device, monkeypatch):
    """A default cast of 4 * OVERLAP_MIN rays is one batch here; batch=OVERLAP_MIN makes it
    four (the control), and so does a GPU device with measured rates that say overlap
    pays; every way gives the same hits. A cast of OVERLAP_MIN rays or more measures the
    rates anew (with timestamps)."""
    n = OVERLAP_PARTS * OVERLAP_MIN
    o, d = _rays(n)
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        one = scene.cast(o, d)
        assert scene.last["batches"] == 1
        buffers = scene._scene.buffers
        if "timestamp" in vk_device.caps:
            assert buffers.rates is not None and min(buffers.rates) > 0
        monkeypatch.setattr(vk_device, "device_type", "discrete_gpu")
        buffers.rates = (1e3, 1e3)  # 262 ms each: overlap pays
        overlapped = scene.cast(o, d)
        assert scene.last["batches"] == OVERLAP_PARTS
        if "timestamp" in vk_device.caps:
            assert buffers.rates != (1e3, 1e3)
    with rfw.RayScene(_TRI, _FACES, device=vk_device, batch=OVERLAP_MIN) as scene:
        capped = scene.cast(o, d)
        assert scene.last["batches"] == OVERLAP_PARTS
    assert np.isfinite(one["t"]).any() and np.isinf(one["t"]).any()
    for got in (overlapped, capped):
        for k in one:
            np.testing.assert_array_equal(got[k], one[k], err_msg=k)


@pytest.mark.parametrize("placement", ["0", "1"])
def test_a_refused_ray_in_a_large_cast_is_named(vk_device, monkeypatch, placement):
    """The NaN check rides on the split readback: a bad row in the last part is found."""
    monkeypatch.setenv("RFW_RAYCAST_MAPPED", placement)
    n = 2 * OVERLAP_MIN
    o, d = _rays(n)
    d[n - 3] = 0.0
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        with pytest.raises(RfwError, match=f"zero-length rows \\(first: {n - 3}\\)"):
            scene.cast(o, d)
        o2, d2 = _rays(n)
        assert np.isfinite(scene.cast(o2, d2)["t"]).any()  # control: good rays pass
