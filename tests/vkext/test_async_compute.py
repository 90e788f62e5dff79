"""Async compute on vk (vkext.queues): the plan's batches and timeline semaphores run under
validation with synchronization validation, and give the image the one-queue frame gives.

Lavapipe has one queue: ``async_compute = on`` sends the same batches, waits and signals to
it one after the other (the H200 runs them on a second queue of its graphics family)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, load_config
from rfw.graph.queues import COMPUTE, choose
from vkext import VkDevice
from vkext.backend import render_vk
from vkext.queues import AsyncQueues

from ..cli.warm import warm_cli
from ..golden_util import changed_share
from ..graph.test_queues import SSAO

ROOT = Path(__file__).resolve().parents[2]

SIZE = "96x54"


def _render(device, scene, switch, frames=3, options=None):
    cfg = apply_overrides(load_config(SSAO), [f"size={SIZE}", f"async_compute={switch}"])
    return render_vk(cfg, scene=scene, device=device, frames=frames, options=options)


def test_async_on_and_off_give_the_same_image(vk_device, courtyard):
    on = _render(vk_device, courtyard, "on")
    off = _render(vk_device, courtyard, "off")
    assert on.timings["validation"]["messages"] == 0, on.timings["validation"]
    assert off.timings["validation"]["messages"] == 0, off.timings["validation"]
    q = on.frame.plan.queues
    # lavapipe: one queue; the H200: a second queue of its graphics family
    assert q.mode == choose("on", vk_device.caps)[0] and q.async_passes() == ("ssao",)
    assert off.frame.plan.queues.queues == ("graphics",)
    assert on.frame.plan.order != off.frame.plan.order  # ssao moved up
    assert set(on.images) == set(off.images)
    for name, img in on.images.items():
        assert np.array_equal(img, off.images[name]), name
    # the frame's GPU span, one per frame (warm-up included), from the batches' timestamps
    spans = on.executor.queues.frame_gpu_ms
    assert len(spans) >= 3 and all(ms > 0 for ms in spans)


def test_the_image_changes_when_ssao_is_off(vk_device, courtyard):
    """Negative control of the comparison: the AO term is visible at this size."""
    on = _render(vk_device, courtyard, "on", frames=1)
    cfg = apply_overrides(load_config(SSAO), [f"size={SIZE}", "async_compute=on", "ao=off"])
    no_ao = render_vk(cfg, scene=courtyard, device=vk_device, frames=1)
    name = next(iter(on.images))
    # the change reached the image: 0.094 of the pixels measured on lavapipe
    assert changed_share(on.images[name], no_ao.images[name]) > 0.02


def test_reused_timeline_values_are_reported(courtyard, monkeypatch):
    """Negative control of the semaphore logic under validation: batches that signal the
    values of the frame before (the frame base never advances) break the rule that a
    timeline only grows, and the validation layer says so."""
    real = AsyncQueues.submit

    def stuck(self, last):
        fence = real(self, last)
        self.frames = 0
        return fence

    monkeypatch.setattr(AsyncQueues, "submit", stuck)
    device = VkDevice(validation=True, label="rfw-tests-async-timeline")
    # the batches on one queue, as on lavapipe: a GPU's second queue is left out of a test
    # that breaks the semaphores on purpose
    device.compute_queue = None
    try:
        r = _render(device, courtyard, "on")
        texts = r.timings["validation"]["texts"]
        assert r.timings["validation"]["messages"] > 0
        assert any("imeline" in t or "semaphore" in t.lower() for t in texts), texts
    finally:
        device.messages.clear()
        device.destroy()
        device.messages.clear()


def test_the_runner_is_made_only_for_two_queues(vk_device):
    from rfw.graph import compile
    from vkext.queues import async_queues

    from ..graph.test_queues import _graph

    one = compile(_graph("off"), caps=vk_device.caps)
    assert async_queues(vk_device, one) is None
    two = compile(_graph("on"), caps=vk_device.caps)
    runner = async_queues(vk_device, two)
    try:
        assert runner is not None and COMPUTE in runner.plan.queues
        assert runner.queue["compute"] == (vk_device.compute_queue or vk_device.queue)
    finally:
        runner.destroy()


def test_a_two_family_plan_is_refused_without_that_family(vk_device):
    if vk_device.compute_family not in (None, vk_device.queue_family):
        pytest.skip("this device has a compute-only family")
    from rfw.errors import RfwError
    from rfw.graph import compile
    from vkext.queues import async_queues

    from ..graph.test_queues import _graph

    plan = compile(_graph("on"), caps=("compute_family", *vk_device.caps))
    with pytest.raises(RfwError, match="compute-only queue family"):
        async_queues(vk_device, plan)


def test_the_second_queue_choice():
    from vkext.consts import vk
    from vkext.device import compute_queue_choice

    g, c, t = vk.VK_QUEUE_GRAPHICS_BIT, vk.VK_QUEUE_COMPUTE_BIT, vk.VK_QUEUE_TRANSFER_BIT
    nvidia = [(g | c | t, 16, 64), (t, 2, 64), (c | t, 8, 64)]
    assert compute_queue_choice(nvidia, 0) == (2, 0)  # the compute engines' family first
    assert compute_queue_choice([(g | c | t, 16, 64)], 0) == (0, 1)  # else a second queue
    one_graphics = [(g | c | t, 1, 64), (t, 1, 64), (c | t, 4, 64)]
    assert compute_queue_choice(one_graphics, 0) == (2, 0)
    untimed = [(g | c | t, 1, 64), (c | t, 4, 0)]
    assert compute_queue_choice(untimed, 0) is None  # its passes could not be timed
    assert compute_queue_choice([(g | c | t, 1, 64)], 0) is None  # lavapipe
    # RFW_VK_ASYNC_QUEUE=graphics: the graphics family's second queue first
    assert compute_queue_choice(nvidia, 0, "graphics") == (0, 1)
    assert compute_queue_choice(one_graphics, 0, "graphics") == (2, 0)
    assert compute_queue_choice(untimed, 0, "graphics") is None


def test_a_bad_async_queue_preference_is_one_line(tmp_path):
    r = warm_cli("run", ROOT / "configs" / "flat.toml", "--backend", "vk", "--size", "16x16",
                 "--out", tmp_path / "out", env={"RFW_VK_ASYNC_QUEUE": "fast"})
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "RFW_VK_ASYNC_QUEUE" in lines[0] and "'fast'" in lines[0]
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def test_the_device_reports_its_second_queue(vk_device):
    fam = vk_device.compute_family
    assert ("compute_queue" in vk_device.caps) == (fam == vk_device.queue_family)
    assert ("compute_family" in vk_device.caps) == (fam not in (None, vk_device.queue_family))
    assert (vk_device.compute_queue is None) == (fam is None)


@pytest.mark.parametrize("seed", [1, 2, 5])
def test_async_in_other_orders_with_poison_gives_the_same_image(vk_device, courtyard, seed):
    """Schedule fuzzing (vkext.poison) with the async plan: another valid order, every
    transient poisoned where its lifetime starts, the same image and no validation message
    (the stretched lifetimes keep what the two queues hold apart in every order)."""
    from rfw.options import RunOptions

    base = _render(vk_device, courtyard, "off", frames=1)
    r = _render(vk_device, courtyard, "on", frames=2,
                options=RunOptions(order_seed=seed, poison=True))
    assert r.timings["validation"]["messages"] == 0, r.timings["validation"]
    assert r.frame.plan.queues.async_passes() == ("ssao",)
    for name, img in r.images.items():
        assert np.array_equal(img, base.images[name]), name


def test_rt_shadows_builds_its_tlas_beside_the_gbuffer(vk_device, courtyard):
    """The acceleration-structure build is compute work no raster pass needs before the
    G-buffer: it goes first, on the compute queue's batch, and the image is unchanged."""
    from rfw.config import resolve_auto

    if "VK_KHR_ray_query" not in vk_device.caps:
        pytest.skip("no ray queries: rt_shadows falls back to the shadow map here")
    out = {}
    for switch in ("on", "off"):
        cfg = apply_overrides(load_config(SSAO.parent / "rt_shadows.toml"),
                              [f"size={SIZE}", f"async_compute={switch}"])
        cfg, _ = resolve_auto(cfg, vk_device.caps)
        out[switch] = render_vk(cfg, scene=courtyard, device=vk_device, frames=2)
        assert out[switch].timings["validation"]["messages"] == 0
    assert out["on"].frame.plan.queues.async_passes() == ("accel",)
    for name, img in out["on"].images.items():
        assert np.array_equal(img, out["off"].images[name]), name


def test_barriers_on_a_compute_only_family_name_no_graphics_stage():
    # VUID-vkCmdPipelineBarrier2-srcStageMask-03849, as the H200 reported it on its compute
    # family: a release after a graphics write, recorded on the compute queue
    from rfw.graph.sync import State
    from vkext.queues import GRAPHICS_ACCESS, GRAPHICS_STAGES, on_compute_family

    written = State("COLOR_ATTACHMENT_OPTIMAL", frozenset({"COLOR_ATTACHMENT_OUTPUT"}),
                    frozenset({"COLOR_ATTACHMENT_WRITE"}))
    got = on_compute_family(written)
    assert got.layout == written.layout
    assert got.stages == {"ALL_COMMANDS"} and got.access == {"MEMORY_WRITE"}
    mixed = State(None, frozenset({"FRAGMENT_SHADER", "COMPUTE_SHADER"}),
                  frozenset({"SHADER_SAMPLED_READ", "INPUT_ATTACHMENT_READ"}))
    got = on_compute_family(mixed)
    assert not got.stages & GRAPHICS_STAGES and not got.access & GRAPHICS_ACCESS
    assert got.access == {"SHADER_SAMPLED_READ", "MEMORY_READ"}
    # negative control: what a compute queue can name stays as it is
    compute = State("GENERAL", frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_STORAGE_WRITE"}))
    assert on_compute_family(compute) is compute


def test_a_pass_on_another_family_records_instead_of_replaying(vk_device, monkeypatch):
    # its bundles would come from the graphics family's pool (VUID-vkCmdExecuteCommands-
    # pCommandBuffers-00094 on the H200's compute family): it records every frame
    from vkext.context import VkPassContext

    cfg = apply_overrides(load_config(SSAO), ["async_compute=on", "size=32x18"])
    replayed: list[tuple[str, bool]] = []
    real_can, real_replayed, real_init = (VkPassContext.can_replay, VkPassContext.replayed,
                                          AsyncQueues.__init__)

    def can(self):  # asked before every record: a False here records the pass
        got = real_can(self)
        if not got:
            replayed.append((self.pass_.name, False))
        return got

    def watched(self, full):
        got = real_replayed(self, full)
        replayed.append((self.pass_.name, got))
        return got

    def elsewhere(self, device, plan):  # as on a device whose compute family is its own
        real_init(self, device, plan)
        self.elsewhere = frozenset(p for p, q in plan.queue_of.items() if q == COMPUTE)

    monkeypatch.setattr(VkPassContext, "can_replay", can)
    monkeypatch.setattr(VkPassContext, "replayed", watched)
    monkeypatch.setattr(AsyncQueues, "__init__", elsewhere)
    monkeypatch.setattr(vk_device, "sync_validation", False)  # replay is off under it
    render_vk(cfg, frames=3, device=vk_device)
    assert any(n == "ssao" for n, _ in replayed)
    assert not any(got for n, got in replayed if n == "ssao")
    # negative control: the passes of the graphics family replay from the second frame
    assert any(got for n, got in replayed if n != "ssao")
