"""The vk frame loop's fixed cost: what a frame used to make per frame is made once.

A slot's fence is reused (no fence made after the first frames), a barrier recorded again
reuses the structs made the first time (and a different one gets its own), and the GPU ms a
frame reads from its slot's query memory are what ``TimestampPool.results`` gives."""

from __future__ import annotations

from pathlib import Path

from rfw.config import apply_overrides, build, load_config
from rfw.frame import open_frame
from rfw.graph.sync import State
from vkext import commands
from vkext.commands import barriers
from vkext.consts import vk
from vkext.images import Image

from ..conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[2]


def _frame(vk_device, config: str = "flat"):
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), ["size=32x18"])
    scene = tiny_scene()
    return open_frame(build(cfg), "vk", devices=(vk_device,), scene=scene,
                      camera=scene.default_camera(), size=cfg.size)


def test_frames_make_no_fence_after_their_slots_exist(vk_device, monkeypatch):
    frame = _frame(vk_device)
    made = []
    real = vk.vkCreateFence
    try:
        ex = frame.executors["vk"]
        ex.keep_in_flight(2)
        frame.run(3)
        monkeypatch.setattr(vk, "vkCreateFence", lambda *a: made.append(1) or real(*a))
        frame.clear_timings()
        frame.run(6)
        assert made == []
        assert all(len(t.gpu_ms) == 6 and len(t.cpu_ms) == 6 for t in ex.timings.values())
        # negative control: new slots make their fences, so the count above can see one
        ex.keep_in_flight(3)
        assert len(made) == 3
        frame.run(2)
        assert len(made) == 3
    finally:
        frame.destroy()
    vk_device.check_validation()


def test_gpu_ms_are_the_pools_results(vk_device):
    frame = _frame(vk_device, "deferred")
    try:
        ex = frame.executors["vk"]
        ex.keep_in_flight(1)  # the last frame's queries stay in the one slot
        frame.run(2)
        ts = ex.in_flight.slots[0].timestamps
        order = ex.plan.order
        ns = ts.results(0, 2 * len(order))
        want = [max(0, ns[2 * k + 1] - ns[2 * k]) * 1e-6 for k in range(len(order))]
        got = [ex.timings[name].gpu_ms[-1] for name in order]
        assert got == want
        # negative control: begin and end swapped read as zero, which the frames did not
        swapped = [max(0, ns[2 * k] - ns[2 * k + 1]) * 1e-6 for k in range(len(order))]
        assert got != swapped
    finally:
        frame.destroy()


def test_a_barrier_recorded_again_reuses_its_structs(vk_device, monkeypatch):
    made = []
    real = barriers._dependency
    monkeypatch.setattr(barriers, "_dependency", lambda *a: made.append(a) or real(*a))
    barriers._DEPENDENCIES.clear()
    img = Image(vk_device, 4, 4, "rgba8unorm", {"sampled", "storage"}, label="cache")
    img.allocate()
    general = State("GENERAL", frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_WRITE"}))
    read = State("SHADER_READ_ONLY_OPTIMAL", frozenset({"FRAGMENT_SHADER"}),
                 frozenset({"SHADER_SAMPLED_READ"}))
    try:
        with commands.one_time(vk_device) as cmd:
            commands.barrier(cmd, [(img, "UNDEFINED", general)])
            commands.barrier(cmd, [(img, general, read)])
            for _ in range(3):  # the same barrier again (a layout kept, a read after a read)
                commands.barrier(cmd, [(img, read, read)])
            assert len(made) == 3
            # negative control: another layout is another barrier, made anew
            commands.barrier(cmd, [(img, read, general)])
            assert len(made) == 4
    finally:
        img.destroy()
    vk_device.check_validation()
