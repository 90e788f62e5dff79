"""Zero-copy arrays where a CUDA device is the same GPU as the Vulkan device (the H200), with
torch: rays from torch tensors, contiguous and transposed, give the host cast's hits bit
for bit as CUDA tensors, with no hit copied to the host; the control: other rays differ.
Skipped where there is no such device (lavapipe: tests/vkext/test_zero_copy.py covers the
host path there). benchmarks/bench_zerocopy.py times the same calls."""

from __future__ import annotations

import numpy as np
import pytest

import rfw
from rfw import interop

from .test_ray_scene import _FACES, _TRI
from .test_zero_copy import _rays

torch = pytest.importorskip("torch")


@pytest.fixture
def scene(vk_device):
    if "VK_KHR_acceleration_structure" not in vk_device.caps:
        pytest.skip("no VK_KHR_acceleration_structure")
    if not torch.cuda.is_available():
        pytest.skip("torch has no CUDA device")
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as s:
        if not s.zero_copy:
            pytest.skip(f"no zero-copy casts here: {s.zero_copy_reason}")
        yield s


def test_torch_rays_give_the_host_hits_as_cuda_tensors(scene):
    o, d = _rays(4096)
    want = scene.cast(o, d)
    before = dict(interop.copies)
    ot, dt = (torch.from_numpy(a).cuda() for a in (o, d))
    got = {k: torch.from_dlpack(v) for k, v in scene.cast(ot, dt).items()}
    torch.cuda.synchronize()
    assert interop.copies["device_to_host"] == before["device_to_host"]
    assert set(got) == set(want)
    for k, t in got.items():
        assert t.is_cuda, k
        np.testing.assert_array_equal(t.cpu().numpy(), want[k], err_msg=k)
    # transposed views (strides (1, N) elements) are gathered on the device
    ott, dtt = (torch.from_numpy(np.ascontiguousarray(a.T)).cuda().T for a in (o, d))
    assert not ott.is_contiguous()
    again = torch.from_dlpack(scene.cast(ott, dtt)["t"]).cpu().numpy()
    np.testing.assert_array_equal(again, want["t"])
    other = scene.cast(*(torch.from_numpy(a).cuda() for a in _rays(4096, shift=0.37)))
    assert not np.array_equal(torch.from_dlpack(other["t"]).cpu().numpy(), want["t"])


def test_frames_hand_out_one_tensor_per_buffer(vk_device):
    """After device_outputs, read_device(..., wrap=torch.from_dlpack) wraps each frame
    slot's exported buffer once and hands the same tensor out again: each frame's tensor
    holds that frame's image (the host readback, bit for bit), and the tensors are as many
    as the slots used, not the frames. The control: a frame's tensor differs from the
    image of a frame rendered with another camera."""
    from dataclasses import replace

    from rfw.config import apply_overrides, load_config
    from rfw.render import render

    from .test_zero_copy import FORWARD

    if not torch.cuda.is_available():
        pytest.skip("torch has no CUDA device")
    cfg = apply_overrides(load_config(FORWARD), ["size=64x36", "frames=6",
                                                 "camera.path=orbit"])
    cfg = replace(cfg, outputs=["forward.hdr"])
    seen, wraps = [], []

    def wrap(a):
        wraps.append(a)
        return torch.from_dlpack(a)

    def each(k, frame):
        if k == 0:
            why = interop.device_outputs(frame, ["forward.hdr"])["forward.hdr"]
            if why:
                pytest.skip(f"no in-frame device outputs: {why}")
            return
        t = interop.read_device(frame, "forward.hdr", wrap=wrap)
        torch.cuda.synchronize()
        seen.append((id(t), np.array_equal(t.cpu().numpy(), frame.read("forward.hdr")),
                     t.cpu().numpy().copy()))

    render(cfg, device=vk_device, backend="vk", each_frame=each)
    assert len(seen) == 5 and all(s[1] for s in seen)
    assert 1 <= len(wraps) == len({s[0] for s in seen}) < len(seen)
    assert not np.array_equal(seen[0][2], seen[-1][2])  # the camera moved: other images


@pytest.mark.parametrize("layout", ["transposed", "slice_of_8", "every_other_row"])
def test_strided_tensors_are_gathered_by_the_kernel(scene, layout):
    """Strided rays and a strided per-ray t_max go through rfw_gather32 (GATHER_PTX): the
    hits equal the contiguous cast's bit for bit; the control: the same memory read as if
    it were contiguous gives other hits."""
    o, d = _rays(3000)
    tmax = np.full(3000, 50.0, np.float32)
    want = scene.cast(o, d, t_max=tmax)

    def lay(a):
        t = torch.from_numpy(np.ascontiguousarray(a)).cuda()
        if layout == "transposed":
            return t.T.contiguous().T if t.ndim == 2 else t
        if layout == "slice_of_8":
            wide = torch.zeros((len(a), 8), device="cuda")
            wide[:, 2:2 + (t.shape[1] if t.ndim == 2 else 1)] = t if t.ndim == 2 else t[:, None]
            return wide[:, 2:5] if t.ndim == 2 else wide[:, 2]
        twice = torch.zeros((2 * len(a), *t.shape[1:]), device="cuda")
        twice[::2] = t
        return twice[::2]

    ot, dt, tt = lay(o), lay(d), lay(tmax)
    assert not ot.is_contiguous() and (layout == "transposed" or not tt.is_contiguous())
    got = scene.cast(ot, dt, t_max=tt)
    for k in want:
        np.testing.assert_array_equal(torch.from_dlpack(got[k]).cpu().numpy(), want[k],
                                      err_msg=k)
    flat = torch.as_strided(ot, ot.shape, (3, 1))  # the same storage read as contiguous
    wrong = scene.cast(flat, dt, t_max=tt)["t"]
    assert not np.array_equal(torch.from_dlpack(wrong).cpu().numpy(), want["t"])
