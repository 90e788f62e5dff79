"""Zero-copy arrays on lavapipe, where no CUDA device shares memory with Vulkan.

- ``RayScene.cast(..., out="device")`` takes the host path behind the device face: hits are
  ``rfw.interop.DeviceArray`` (``zero_copy`` False, ``device`` "cpu", a CPU ``__dlpack__``)
  bit-identical to the numpy cast; a cast of other rays (the negative control) differs.
- Device arrays handed in where there is no CUDA link, or of the wrong dtype, shape or
  layout, are one RfwError line naming the argument.
- The export itself runs on lavapipe: ``VK_KHR_external_memory_fd`` memory (a memfd there,
  mapped by the test) filled on the GPU; the shared cast's command buffer (ownership
  transfers, the trace into the exported buffers) gives the staged cast's hits bit for bit;
  an image copied into exported memory is read_image's texels. A graph output read through
  ``rfw.interop.read_device`` in ``each_frame`` is the rendered image.
"""

from __future__ import annotations

import gc
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import rfw
from rfw import interop
from rfw.config import apply_overrides, load_config
from rfw.errors import RfwError
from rfw.render import render
from vkext import external
from vkext.commands import one_time, read_image
from vkext.consts import vk
from vkext.images import Image
from vkext.raycast import RayScene as VkRayScene
from vkext.raycast.shared import SharedRays

from .test_ray_scene import _FACES, _TRI

FORWARD = Path(__file__).resolve().parents[2] / "configs" / "forward.toml"


@pytest.fixture(autouse=True)
def _needs_ray_tracing(vk_device):
    if "VK_KHR_acceleration_structure" not in vk_device.caps:
        pytest.skip("no VK_KHR_acceleration_structure")


@pytest.fixture(autouse=True)
def _no_cuda(vk_device, monkeypatch):
    """The host path behind the device face, also where a CUDA device is the same GPU (the
    H200: benchmarks/bench_zerocopy.py checks the CUDA path there): RFW_CUDA=0, the link
    found again for this test and after it."""
    monkeypatch.setenv("RFW_CUDA", "0")
    external._links.pop(vk_device, None)
    yield
    external._links.pop(vk_device, None)


@pytest.fixture
def memfd(vk_device):
    """Skips where the exported fd cannot be mapped by the host (lavapipe's is a memfd;
    NVIDIA's opaque fd is not): the tests that read the export through it."""
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    probe = external.ExportedBuffer(vk_device, 256, ("transfer_dst",), link=None,
                                    label="mappable?")
    try:
        probe.host_view()
    except OSError as e:
        pytest.skip(f"{vk_device.name}'s exported fd cannot be mapped here ({e})")
    finally:
        probe.release()


def _rays(n: int = 200, shift: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    o = np.column_stack([rng.uniform(-0.2, 1.2, (n, 2)) + shift, np.ones(n)]).astype(np.float32)
    d = np.tile(np.float32([0, 0, -1]), (n, 1))
    return o, d


class CudaLike:
    """A CUDA array as a producer describes it (``__cuda_array_interface__``), for the
    checks that read the interface before any driver call."""

    def __init__(self, shape, typestr="<f4", strides=None):
        self.shape, self.typestr, self.strides = shape, typestr, strides

    @property
    def __cuda_array_interface__(self):
        return {"shape": self.shape, "typestr": self.typestr, "data": (0x7000_0000, False),
                "strides": self.strides, "version": 3}


def test_device_hits_on_the_host_path_equal_the_numpy_cast(vk_device):
    o, d = _rays()
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        assert not scene.zero_copy and scene.zero_copy_reason  # no CUDA here
        want = scene.cast(o, d)
        got = scene.cast(o, d, out="device")
        other = scene.cast(*_rays(shift=0.37))
        assert set(got) == set(want)
        for k, a in got.items():
            assert isinstance(a, interop.DeviceArray)
            assert (a.zero_copy, a.device, a.__dlpack_device__()) == (False, "cpu", (1, 0))
            assert not hasattr(a, "__cuda_array_interface__")
            np.testing.assert_array_equal(np.from_dlpack(a), want[k], err_msg=k)
        assert (want["primitive"] >= 0).any() and (want["primitive"] < 0).any()
        assert not np.array_equal(other["t"], want["t"])  # the comparison can fail
        # device arrays back in as rays: the host path reads them through dlpack
        again = scene.cast(interop.DeviceArray.of_host(o), interop.DeviceArray.of_host(d))
        np.testing.assert_array_equal(again["t"], want["t"])
        host = scene.cast(o, d, out="host")
        assert isinstance(host["t"], np.ndarray)


def test_cuda_arrays_without_a_link_are_one_line(vk_device):
    o, d = _rays(4)
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        with pytest.raises(RfwError, match=r"origins is a CUDA array, but this ray scene "
                                           r"cannot share memory with CUDA \(.+\): pass host"):
            scene.cast(CudaLike((4, 3)), d)
        with pytest.raises(RfwError, match="t_max is a CUDA array") as e:
            scene.cast(o, d, t_max=CudaLike((4,)))
        assert "\n" not in str(e.value)
        with pytest.raises(RfwError, match="origins is a CUDA array: out= arrays are filled "
                                           "on the host"):
            scene.cast(CudaLike((4, 3)), d, out={"t": np.empty(4, np.float32)})
        with pytest.raises(RfwError, match="out is 'device', 'host', None or a dict"):
            scene.cast(o, d, out="gpu")
        scene.cast(o, d)  # the control: host rays still cast


@pytest.mark.parametrize(("array", "message"), [
    (CudaLike((4, 3), "<f8"), "origins is a device array of dtype float64; rfw takes "
                              "float32 only"),
    (CudaLike((4, 4)), r"origins is a device array of shape \(4, 4\); it must be \(N, 3\)"),
    (CudaLike((4, 3), strides=(0, 4)), r"strides \(0, 4\) bytes; rfw takes positive "
                                       r"multiples of 4"),
    (CudaLike((4, 3), strides=(12, 6)), r"strides \(12, 6\) bytes"),
])
def test_bad_device_arrays_are_one_line(array, message):
    with pytest.raises(RfwError, match=message):
        interop.device_view("origins", array, 3)


def test_dlpack_keeps_the_memory_alive():
    x = np.arange(12, dtype=np.float32).reshape(4, 3)
    a = interop.DeviceArray.of_host(x.copy())
    y = np.from_dlpack(a)
    del a
    gc.collect()
    np.testing.assert_array_equal(y, x)  # the capsule's owner outlived the array object
    live = len(interop._live)
    del y
    gc.collect()
    assert len(interop._live) == live - 1
    unconsumed = interop.DeviceArray.of_host(x).__dlpack__()
    assert len(interop._live) == live
    del unconsumed  # never consumed: freed by the capsule's destructor
    gc.collect()
    assert len(interop._live) == live - 1


def test_exported_memory_holds_what_the_gpu_wrote(memfd, vk_device):
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    buf = external.ExportedBuffer(vk_device, 4096, ("storage", "transfer_dst"), link=None,
                                  label="test export")
    try:
        for word in (0x3F800000, 0x40490FD0):  # 1.0, then 3.14159 (the control: it changes)
            with one_time(vk_device) as cmd:
                external.ownership(vk_device, cmd, [buf], acquire=True)
                vk.vkCmdFillBuffer(cmd, buf.handle, 0, 4096, word)
                external.ownership(vk_device, cmd, [buf], acquire=False)
            seen = buf.host_view().view(np.uint32)
            assert (seen == word).all()
            del seen
    finally:
        buf.release()
    assert buf.handle is None and buf.fd is None


@pytest.mark.parametrize("method", ["ray_query", "ray_pipeline"])
def test_the_shared_cast_traces_into_exported_buffers(memfd, vk_device, method):
    """The device path's command buffer, on lavapipe's memfds: rays written into the
    exported ray buffer, hits read from the exported hit buffer."""
    need = {"ray_query": "VK_KHR_ray_query", "ray_pipeline": "VK_KHR_ray_tracing_pipeline"}
    if need[method] not in vk_device.caps or external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {need[method]} or {external.EXTENSION}")
    scene = rfw.raycasting._mesh_scene(_TRI, _FACES)
    vscene = VkRayScene(vk_device, scene, method=method)
    o, d = _rays(150)
    n = len(o)
    shared = SharedRays(vscene.caster, vscene.accel.tlas, None, label="test shared")
    try:
        want = vscene.cast(o, d, 0.0, 5.0, hits=("t", "primitive", "instance",
                                                 "barycentrics"))
        shared.reserve(n)
        words = shared.rays.host_view().view(np.float32)
        words[:3 * n], words[3 * n:6 * n] = o.reshape(-1), d.reshape(-1)
        sbt = vscene.caster._table(vscene.accel.hit_records) if method == "ray_pipeline" \
            else None
        for t_max, same in ((5.0, True), (0.5, False)):  # t_max 0.5 misses: the control
            shared.record(n, sbt, False, 0.0, t_max)
            shared.submitter.run()
            hits = shared.hits.host_view()
            got = {"t": hits[:4 * n].view(np.float32),
                   "primitive": hits[4 * n:8 * n].view(np.int32),
                   "instance": hits[8 * n:12 * n].view(np.int32),
                   "barycentrics": hits[12 * n:20 * n].view(np.float32).reshape(n, 2)}
            equal = all(np.array_equal(got[k], want[k]) for k in want)
            assert equal is same, t_max
            del hits, got
        del words
    finally:
        shared.destroy()
        vscene.destroy()


def test_an_image_copied_into_exported_memory(memfd, vk_device):
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    img = Image(vk_device, 24, 16, "rgba16float", ("transfer_src", "transfer_dst", "sampled"),
                label="test image")
    try:
        img.allocate()
        for value in (0.375, 2.25):  # exact in half floats; the second: the export follows
            with one_time(vk_device) as cmd:
                color = vk.VkClearColorValue(float32=[value, 1 - value, 0.125, 1.0])
                rng = vk.VkImageSubresourceRange(aspectMask=vk.VK_IMAGE_ASPECT_COLOR_BIT,
                                                 levelCount=1, layerCount=1)
                barrier = vk.VkImageMemoryBarrier(
                    srcAccessMask=0, dstAccessMask=vk.VK_ACCESS_TRANSFER_WRITE_BIT,
                    oldLayout=vk.VK_IMAGE_LAYOUT_UNDEFINED,
                    newLayout=vk.VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                    srcQueueFamilyIndex=vk.VK_QUEUE_FAMILY_IGNORED,
                    dstQueueFamilyIndex=vk.VK_QUEUE_FAMILY_IGNORED, image=img.handle,
                    subresourceRange=rng)
                vk.vkCmdPipelineBarrier(cmd, vk.VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT,
                                        vk.VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, None, 0,
                                        None, 1, [barrier])
                vk.vkCmdClearColorImage(cmd, img.handle,
                                        vk.VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, color, 1,
                                        [rng])
            export = external.ImageExport(vk_device, img, layout_now="TRANSFER_DST_OPTIMAL",
                                          layout_after="TRANSFER_DST_OPTIMAL", link=None)
            try:
                export.run()
                raw = export.buffer.host_view()
                got = raw.view(np.float16).reshape(16, 24, 4).copy()
                del raw
            finally:
                export.destroy()
            want = read_image(vk_device, img, layout_now="TRANSFER_DST_OPTIMAL")
            np.testing.assert_array_equal(got, want)
            assert got[0, 0, 0] == np.float16(value)
    finally:
        img.destroy()


def test_a_graph_output_through_read_device(vk_device):
    cfg = apply_overrides(load_config(FORWARD), ["size=32x18", "frames=2"])
    cfg = replace(cfg, outputs=["forward.hdr"])
    got = []
    result = render(cfg, device=vk_device, backend="vk",
                    each_frame=lambda k, frame: got.append(
                        interop.read_device(frame, "forward.hdr")))
    assert len(got) == 2
    a = got[-1]
    assert (a.zero_copy, a.device, a.dtype, a.shape) == (False, "cpu", np.float16,
                                                        (18, 32, 4))
    want = result.images["forward.hdr"]
    np.testing.assert_array_equal(np.from_dlpack(a), want)
    assert np.ptp(want[..., :3]) > 0  # a picture, not a cleared image


def test_read_device_wraps_each_host_read(vk_device):
    """``wrap`` (torch.from_dlpack where there is CUDA) gets the read array and its result
    comes back; on the host path it runs on every read (each read is a new copy). The
    control: without it the read is a DeviceArray."""
    cfg = apply_overrides(load_config(FORWARD), ["size=32x18", "frames=3"])
    cfg = replace(cfg, outputs=["forward.hdr"])
    calls, got, plain = [], [], []

    def wrap(a):
        calls.append(a)
        return ("wrapped", np.from_dlpack(a).copy())

    def each(k, frame):
        got.append(interop.read_device(frame, "forward.hdr", wrap=wrap))
        plain.append(interop.read_device(frame, "forward.hdr"))

    result = render(cfg, device=vk_device, backend="vk", each_frame=each)
    assert len(calls) == 3 and len({id(a) for a in calls}) == 3
    assert all(isinstance(a, interop.DeviceArray) and not a.zero_copy for a in calls)
    assert [g[0] for g in got] == ["wrapped"] * 3
    assert all(isinstance(p, interop.DeviceArray) for p in plain)
    np.testing.assert_array_equal(got[-1][1], result.images["forward.hdr"])


def test_exported_memory_lives_as_long_as_its_arrays(vk_device):
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    kept = external.ExportedBuffer(vk_device, 256, ("storage",), link=None, label="kept")
    alone = external.ExportedBuffer(vk_device, 256, ("storage",), link=None, label="alone")
    view = interop.DeviceArray(ptr=0, shape=(64,), dtype=np.float32, ordinal=None,
                               owner=kept)
    kept.release()
    alone.release()  # the control: nothing holds it, so it goes at once
    assert alone.handle is None and kept.handle is not None and kept.held == 1
    del view
    gc.collect()
    assert kept.handle is None and kept.held == 0


def test_the_driver_structs_have_cuda_h_and_dlpack_h_sizes():
    """The ctypes mirrors of the C structs the driver and consumers read (x86-64)."""
    import ctypes

    assert ctypes.sizeof(interop._ExternalMemoryHandleDesc) == 104
    assert ctypes.sizeof(interop._ExternalMemoryBufferDesc) == 88
    assert ctypes.sizeof(interop._DLTensor) == 48
    assert ctypes.sizeof(interop._DLManagedTensor) == 64
    assert interop._ExternalMemoryHandleDesc.size.offset == 24


@pytest.mark.parametrize("make", [
    lambda a: a,                                   # contiguous: one linear copy
    lambda a: np.ascontiguousarray(a.T).T,         # a transposed view
    lambda a: np.pad(a, ((0, 0), (0, 5)))[:, :3],  # a slice of an (N, 8) array
    lambda a: np.pad(a, ((0, 0), (2, 3)))[:, 2:5],  # ... at an offset
    lambda a: a[::2],                              # every other row
])
def test_strided_rays_are_gathered_as_the_kernel_reads_them(make):
    """gather_of's Gather run on host words with the kernel's index arithmetic
    (run_gather_on_host): the gathered buffer is the array made contiguous, and only a
    contiguous array is left to the linear copy; the control: the Gather of a contiguous
    array over the same memory gathers something else."""
    rays = np.arange(60, dtype=np.float32).reshape(20, 3) * 1.5 + 0.25
    view = make(rays)
    base = view.base if view.base is not None else view
    while base.base is not None:
        base = base.base
    words = np.frombuffer(base.tobytes(), np.uint32)
    ptr = view.ctypes.data - base.ctypes.data
    strides = None if view.flags.c_contiguous else view.strides
    g = interop.gather_of(ptr, view.shape, strides, 0)
    assert g.contiguous == (strides is None)
    out = np.zeros(view.size, np.uint32)
    interop.run_gather_on_host(g, words, out)
    np.testing.assert_array_equal(out.view(np.float32).reshape(view.shape), view)
    if strides is not None:
        wrong = np.zeros_like(out)
        interop.run_gather_on_host(interop.gather_of(ptr, view.shape, None, 0), words, wrong)
        assert not np.array_equal(wrong, out)


def test_a_column_stream_and_single_rows():
    col = interop.gather_of(64, (10,), (32,), 0)
    assert (col.rows, col.cols, col.row_stride, col.contiguous) == (10, 1, 8, False)
    one = interop.gather_of(8, (1, 3), (10**6, 4), 0)
    assert one.contiguous and (one.rows, one.cols) == (1, 3)
    assert interop.gather_of(8, (0, 3), (4, 0), 0).rows == 0
    assert interop.GATHER_PTX.endswith(b"\0") and b".entry rfw_gather32(" in interop.GATHER_PTX


def test_strided_rays_on_the_host_path_equal_contiguous_ones(vk_device):
    o, d = _rays(64)
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as scene:
        want = scene.cast(o, d)
        wide = np.pad(o, ((0, 0), (0, 5)))[:, :3]
        got = scene.cast(interop.DeviceArray.of_host(wide), np.ascontiguousarray(d.T).T,
                         out="device")
        for k in want:
            np.testing.assert_array_equal(got[k].numpy(), want[k], err_msg=k)
        moved = scene.cast(np.ascontiguousarray((o + 0.3).T).T, d)  # the control
        assert not np.array_equal(moved["t"], want["t"])


def test_frames_copy_their_outputs_into_exported_memory(memfd, vk_device):
    """export_outputs: each frame's own command buffer copies the output into its slot's
    exported buffer (read here through lavapipe's memfd); the control: the buffer of the
    slot the frame did not use keeps the zeros written into it."""
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    from vkext.commands import texels

    cfg = apply_overrides(load_config(FORWARD), ["size=40x24", "frames=3"])
    cfg = replace(cfg, outputs=["forward.hdr"])
    seen = []

    def each(k, frame):
        ex = frame.executors["vk"]
        if k == 0:
            assert interop.device_outputs(frame, ["forward.hdr"])["forward.hdr"]  # no CUDA
            assert external.export_outputs(ex, ["forward.hdr"],
                                           record_without_cuda=True) is None
            return
        frame.drain()
        fe = ex.frame_exports
        image = ex.image("forward.hdr")
        mine = fe.buffer(fe.last, "forward.hdr")
        other = next((b for (sid, _), b in fe.buffers.items() if sid != id(fe.last)), None)
        want = ex.read("forward.hdr")
        got = texels(np.array(mine.host_view()), image)
        seen.append((np.array_equal(got, want), other is not None and
                     np.array_equal(texels(np.array(other.host_view()), image), want)))
        mine.host_view()[:] = 0  # the next frame on this slot must write it again
        with pytest.raises(RfwError, match="not mapped into CUDA"):
            fe.array("forward.hdr")  # no link here
        assert fe.read_timer() >= 0 and len(fe.gpu_ms) == k

    render(cfg, device=vk_device, backend="vk", each_frame=each)
    assert [s[0] for s in seen] == [True, True]
    assert seen[0][1] is False  # frame 1's slot alone was written (the other never was)


def test_device_rays_are_the_ray_buffer_a_cast_reads_in_place(memfd, vk_device):
    """``SharedRays.device_rays`` on lavapipe's memfd: rays written into the views are what
    the trace reads, with nothing copied in (``in_place``); the controls: a copy of the
    views, and views made for another ray count, are not in place, and other rays written
    into the views give other hits."""
    if external.EXTENSION not in vk_device.extensions:
        pytest.skip(f"no {external.EXTENSION}")
    from rfw.raycasting import _mesh_scene

    scene = _mesh_scene(_TRI, _FACES)
    vscene = VkRayScene(vk_device, scene)
    o, d = _rays(120)
    n = len(o)
    shared = SharedRays(vscene.caster, vscene.accel.tlas, None, label="test device rays")
    try:
        want = vscene.cast(o, d, 0.0, 5.0, hits=("t", "primitive"))
        ro, rd = shared.device_rays(n)
        assert shared.device_rays(n) == (ro, rd)  # made once per buffer and size
        assert shared.in_place(n, ro, rd)
        assert not shared.in_place(n, interop.DeviceArray.of_host(ro.numpy().copy()), rd)
        assert not shared.in_place(n, rd, ro)
        small = shared.device_rays(n // 2)
        assert not shared.in_place(n, *small) and shared.in_place(n // 2, *small)
        sbt = vscene.caster._table(vscene.accel.hit_records) \
            if vscene.method == "ray_pipeline" else None
        ro, rd = shared.device_rays(n)
        for rays, same in ((o, True), (o + np.float32([0.9, 0, 0]), False)):
            ro.numpy()[:], rd.numpy()[:] = rays, d
            shared.record(n, sbt, False, 0.0, 5.0)
            shared.submitter.run()
            hits = shared.hits.host_view()
            got = {"t": hits[:4 * n].view(np.float32), "primitive": hits[4 * n:8 * n].view(
                np.int32)}
            assert all(np.array_equal(got[k], want[k]) for k in want) is same
            del hits, got
        del ro, rd, small
    finally:
        shared.destroy()
        vscene.destroy()


def test_device_rays_without_cuda_are_host_arrays_cast_on_the_host(vk_device):
    """``rfw.RayScene.device_rays`` where nothing is shared with CUDA (lavapipe): host
    arrays behind the DeviceArray face; written and cast they give the numpy cast's hits,
    and other rays written give other hits (the control)."""
    o, d = _rays(90)
    with rfw.RayScene(_TRI, _FACES, device=vk_device) as rs:
        want = rs.cast(o, d)
        ro, rd = rs.device_rays(len(o))
        assert (ro.device, ro.zero_copy, ro.shape, ro.dtype) == ("cpu", False, (90, 3),
                                                                 np.float32)
        for rays, same in ((o, True), (o + np.float32([0.9, 0, 0]), False)):
            ro.numpy()[:], rd.numpy()[:] = rays, d
            got = rs.cast(ro, rd)
            assert all(np.array_equal(got[k], want[k]) for k in want) is same
        with pytest.raises(RfwError, match="n must be positive"):
            rs.device_rays(0)
