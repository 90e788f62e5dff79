"""A vk frame keeps the cameras it began with while the next ones are set (no drain): each
frame copies its slot's own camera bytes into the camera uniforms (``VkScene.copy_camera``).

The queue is held (a batch waits for a timeline value only the host signals), so the frame
is certainly still waiting on the GPU when the next camera is written; then it is let go."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from rfw.config import apply_overrides, build, load_config
from rfw.frame import open_frame
from vkext.consts import const, ffi, vk

from ..conftest import tiny_scene
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = "tonemap.ldr"


def _config():
    return apply_overrides(load_config(ROOT / "configs" / "deferred.toml"),
                           ["shadow.enabled=true", "size=64x36"])


def _turned(cam):
    x, y, z = cam.position
    return replace(cam, position=(x + 3.0, y + 1.0, z - 2.0))


class _Hold:
    """Hold the device's queue: a batch waiting for value 1 of a timeline semaphore."""

    def __init__(self, device):
        self.device = device
        kind = vk.VkSemaphoreTypeCreateInfo(semaphoreType=vk.VK_SEMAPHORE_TYPE_TIMELINE,
                                            initialValue=0)
        self.sem = vk.vkCreateSemaphore(device.device, vk.VkSemaphoreCreateInfo(pNext=kind),
                                        None)
        wait = ffi.new("VkSemaphoreSubmitInfo*")
        wait.sType = const("VK_STRUCTURE_TYPE_SEMAPHORE_SUBMIT_INFO")
        wait.semaphore, wait.value = self.sem, 1
        wait.stageMask = const("VK_PIPELINE_STAGE_2_ALL_COMMANDS_BIT")
        info = ffi.new("VkSubmitInfo2*")
        info.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO_2")
        info.waitSemaphoreInfoCount, info.pWaitSemaphoreInfos = 1, wait
        vk.vkQueueSubmit2(device.queue, 1, info, ffi.NULL)

    def release(self):
        vk.vkSignalSemaphore(self.device.device,
                             vk.VkSemaphoreSignalInfo(semaphore=self.sem, value=1))

    def destroy(self):
        self.device.wait_idle()
        vk.vkDestroySemaphore(self.device.device, self.sem, None)


def _static(vk_device, scene, cam) -> np.ndarray:
    frame = open_frame(build(_config()), "vk", devices=(vk_device,), scene=scene, camera=cam,
                       size=_config().size)
    try:
        frame.run(2)
        return frame.read(OUTPUT).copy()
    finally:
        frame.destroy()


def _held(vk_device, scene, first, second) -> tuple[np.ndarray, np.ndarray, int]:
    """Frames from ``first`` (the second one held on the GPU while ``second`` is set), then
    one from ``second``: the held frame's image, the last one's and the frames in flight
    when ``second`` was set."""
    frame = open_frame(build(_config()), "vk", devices=(vk_device,), scene=scene,
                       camera=first, size=_config().size)
    hold = None
    try:
        ex = frame.executors["vk"]
        ex.keep_in_flight(2)
        frame.run(1)  # pipelines and bundles made, done
        hold = _Hold(vk_device)
        frame.step(last=False)  # from ``first``, waiting behind the hold
        frame.set_camera(second)
        busy = ex.in_flight.busy
        hold.release()
        held = frame.read(OUTPUT).copy()
        frame.step(last=True)
        after = frame.read(OUTPUT).copy()
    finally:
        frame.destroy()
        if hold is not None:
            hold.destroy()
    vk_device.check_validation()
    return held, after, busy


def test_a_frame_in_flight_keeps_its_camera(vk_device):
    scene = tiny_scene()
    a = scene.default_camera()
    b = _turned(a)
    want_a, want_b = _static(vk_device, scene, a), _static(vk_device, scene, b)
    assert changed_share(want_a, want_b) > 0.2  # the cameras see differently (58 %)
    held, after, busy = _held(vk_device, scene, a, b)
    assert busy == 1  # the camera was set while the held frame waited: no drain
    assert np.array_equal(held, want_a)
    assert np.array_equal(after, want_b)


def test_a_camera_written_at_once_reaches_the_frame_in_flight(vk_device, monkeypatch):
    """Negative control: the camera written straight into the uniforms the frames read (as
    vk did, without the drain that made it safe) shows in the held frame."""
    from vkext.scene import VkScene

    set_viewport = VkScene.set_viewport

    def write_at_once(self, size):
        set_viewport(self, size)
        self.dynamic_uniforms.write(np.frombuffer(self.camera_blob, np.uint8), 0)

    scene = tiny_scene()
    a = scene.default_camera()
    b = _turned(a)
    want_a, want_b = _static(vk_device, scene, a), _static(vk_device, scene, b)
    monkeypatch.setattr(VkScene, "set_viewport", write_at_once)
    monkeypatch.setattr(VkScene, "copy_camera", lambda self, cmd, source: None)
    held, _, busy = _held(vk_device, scene, a, b)
    assert busy == 1
    assert np.array_equal(held, want_b) and changed_share(held, want_a) > 0.2  # 58 %
