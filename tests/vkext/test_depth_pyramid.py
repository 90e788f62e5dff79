"""The depth pyramid on both backends: every mip equals a NumPy max-reduction, with the
barriers between its levels planned by the graph (declared steps), none written by the pass."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from passes.depth_pyramid import depth_pyramid
from passes.depth_pyramid.depth_pyramid import DepthPyramidPass
from rfw.graph import GraphBuilder, GraphError, SizeRule, Texture, compile
from vkext.commands import read_image
from vkext.executor import VkExecutor

# odd sizes on purpose: the last texel of a level takes the third source row/column
W, H, LEVELS = 37, 23, 5


def reference(depth: np.ndarray, levels: int, *, odd_edges: bool = True) -> list[np.ndarray]:
    """Each level the max over its 2x2 source texels; on an odd edge the last texel also
    takes the third row/column (``odd_edges=False`` drops that: a wrong pyramid)."""
    out = [depth]
    for _ in range(1, levels):
        src = out[-1]
        h, w = max(1, src.shape[0] // 2), max(1, src.shape[1] // 2)
        level = np.empty((h, w), np.float32)
        for y in range(h):
            for x in range(w):
                y1 = src.shape[0] if odd_edges and y == h - 1 else min(2 * y + 2, src.shape[0])
                x1 = src.shape[1] if odd_edges and x == w - 1 else min(2 * x + 2, src.shape[1])
                level[y, x] = src[2 * y:y1, 2 * x:x1].max()
        out.append(level)
    return out


def depth_image(seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random((H, W), dtype=np.float32)


def plan_and_pass():
    p = DepthPyramidPass("hiz", levels=LEVELS)
    ins, outs = p.declare()
    g = GraphBuilder("pyramid", size=(W, H))
    g.external("in.depth", Texture("r32float", size=SizeRule.fixed(W, H)))
    b = g.add_pass("hiz", p.type, steps=p.steps(), settings=p.params.as_dict())
    b.input("depth", "in.depth", ins["depth"])
    b.output("pyramid", outs["pyramid"].with_(size=SizeRule.like("in.depth")))
    g.output("hiz.pyramid")
    return compile(g.build()), p, {"hiz": {"depth": "in.depth", "pyramid": "hiz.pyramid"}}


def run_wgpu(depth: np.ndarray) -> list[np.ndarray]:
    from rfw.backends.wgpu import Device, Executor

    plan, p, slots = plan_and_pass()
    device = Device()
    ex = Executor(device, plan, {"hiz": p}, slots, None, readback=("hiz.pyramid",))
    try:
        ex.upload("in.depth", depth[..., None])
        ex.run(1)
        tex, out = ex.texture("hiz.pyramid"), []
        for lv in range(LEVELS):
            w, h = max(1, W >> lv), max(1, H >> lv)
            data = device.device.queue.read_texture(
                {"texture": tex, "mip_level": lv, "origin": (0, 0, 0)},
                {"offset": 0, "bytes_per_row": w * 4}, (w, h, 1))
            out.append(np.frombuffer(data, np.float32).reshape(h, w))
        return out
    finally:
        ex.destroy()


def run_vk(vk_device, depth: np.ndarray) -> list[np.ndarray]:
    plan, p, slots = plan_and_pass()
    ex = VkExecutor(vk_device, plan, {"hiz": p}, slots, readback=("hiz.pyramid",))
    try:
        ex.upload("in.depth", depth[..., None])
        ex.run(1)
        # the pass leaves the pyramid in the state it writes it in
        state = next(b.dst for b in plan.barriers if b.resource == "hiz.pyramid")
        return [read_image(vk_device, ex.image("hiz.pyramid"), layout_now=state,
                           mip=lv)[..., 0] for lv in range(LEVELS)]
    finally:
        ex.destroy()


def test_reference_is_conservative_and_can_fail():
    depth = depth_image()
    pyramid = reference(depth, LEVELS)
    # every level-0 pixel p lies in level L's texel min(p >> L, size - 1), never farther
    ys, xs = np.mgrid[0:H, 0:W]
    for lv, level in enumerate(pyramid):
        cover = level[np.minimum(ys >> lv, level.shape[0] - 1),
                      np.minimum(xs >> lv, level.shape[1] - 1)]
        assert (cover >= depth).all()
    # negative control: without the odd-edge rule the last column's texels miss pixels
    wrong = reference(depth, LEVELS, odd_edges=False)
    assert any((a != b).any() for a, b in zip(pyramid, wrong, strict=True))


def test_plan_has_the_level_barriers():
    plan, _, _ = plan_and_pass()
    assert [(b.step, b.mips) for b in plan.step_barriers] == \
        [(lv, (lv - 1, 1)) for lv in range(1, LEVELS)]


def test_the_pass_writes_no_barrier_and_runs_on_both_backends():
    src = inspect.getsource(depth_pyramid)
    assert "barrier(" not in src and "vkext" not in src
    assert DepthPyramidPass.backend is None


def test_same_pyramid_on_wgpu_and_vk(vk_device):
    depth = depth_image()
    want = reference(depth, LEVELS)
    got_vk = run_vk(vk_device, depth)
    got_wgpu = run_wgpu(depth)
    for lv in range(LEVELS):
        np.testing.assert_array_equal(got_vk[lv], want[lv], err_msg=f"vk mip {lv}")
        np.testing.assert_array_equal(got_wgpu[lv], want[lv], err_msg=f"wgpu mip {lv}")


def skipping_pass() -> DepthPyramidPass:
    """A pyramid pass that skips step 1 (its barrier would be missing)."""
    p = DepthPyramidPass("hiz", levels=LEVELS)
    p.record = lambda ctx: (ctx.step(0), ctx.step(2))
    return p


SKIPPED = r"pass 'hiz' enters step 2 after step 0: steps are entered in order \(step 1 next\)"


def test_steps_are_entered_in_order_on_vk(vk_device):
    plan, _, slots = plan_and_pass()
    ex = VkExecutor(vk_device, plan, {"hiz": skipping_pass()}, slots, readback=("hiz.pyramid",))
    try:
        with pytest.raises(GraphError, match=SKIPPED):
            ex.run(1)
    finally:
        ex.destroy()


def test_steps_are_entered_in_order_on_wgpu():
    from rfw.backends.wgpu import Device, Executor

    plan, _, slots = plan_and_pass()
    ex = Executor(Device(), plan, {"hiz": skipping_pass()}, slots, None,
                  readback=("hiz.pyramid",))
    try:
        with pytest.raises(GraphError, match=SKIPPED):
            ex.run(1)
    finally:
        ex.destroy()


def test_vk_records_each_level_barrier_as_it_enters_the_level(vk_device, monkeypatch):
    from vkext import context

    recorded: list[tuple] = []
    real = context.record_barriers

    def spy(cmd, barriers, resources):
        recorded.extend((b.step, b.resource, b.mips) for b in barriers)
        return real(cmd, barriers, resources)

    monkeypatch.setattr(context, "record_barriers", spy)
    run_vk(vk_device, depth_image())
    assert recorded == [(lv, "hiz.pyramid", (lv - 1, 1)) for lv in range(1, LEVELS)]


def test_without_the_planned_barriers_sync_validation_reports_the_hazard(vk_device,
                                                                         monkeypatch):
    """Negative control for the test above: the level barriers are what orders the levels."""
    from vkext import context
    from vkext.device import VkValidationError

    if not vk_device.sync_validation:
        pytest.fail("synchronization validation is not available: this control needs it")
    vk_device.check_validation()
    monkeypatch.setattr(context, "record_barriers", lambda cmd, barriers, resources: 0)
    run_vk(vk_device, depth_image())
    with pytest.raises(VkValidationError, match="READ_AFTER_WRITE"):
        vk_device.check_validation()  # clears them: the module's device stays usable
