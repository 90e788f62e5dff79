"""Dispatches inside one step are unordered: a pass whose dispatches depend on each other
declares steps (rfw.passes), and the plan's step barriers, not a barrier the vk context adds
between dispatches, order them. No hand-written barrier is left outside the primitives.

Measured on lavapipe (Mesa 25.0.7), deferred_ssao_shadows at 96x54, one frame: the declared
ssao steps give 0 validation messages; collapsed into one step, synchronization validation
reports READ_AFTER_WRITE on ssao.ao_raw (the blur reading what the occlusion dispatch wrote).
Ray casting's batches record the barriers of a tiny plan (vkext.raycast.batch_graph);
without them synchronization validation reports the hits copied out before the trace wrote
them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from passes.ssao.ssao import SSAOPass
from rfw.config import apply_overrides, build, load_config
from rfw.graph import Step, compile
from vkext.backend import render_vk

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "deferred_ssao_shadows.toml"
SIZE = "96x54"

# where barrier() may be called: the primitives, the executor's frame and poison fills, and
# the async compute batches' frame barrier (vkext.queues)
ALLOWED = {"vkext/commands/barriers.py", "vkext/commands/transfers.py", "vkext/executor.py",
           "vkext/poison.py", "vkext/queues.py"}


def _config():
    return apply_overrides(load_config(CONFIG), [f"size={SIZE}"])


def barrier_calls(source: str) -> list[int]:
    """Lines of ``barrier(...)`` calls (a name or an attribute) in ``source``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
            if name == "barrier":
                out.append(node.lineno)
    return out


def test_no_barrier_call_outside_the_primitives():
    found = {}
    for path in sorted([*ROOT.glob("vkext/**/*.py"), *ROOT.glob("passes/**/*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        lines = barrier_calls(path.read_text())
        if lines and rel not in ALLOWED:
            found[rel] = lines
    assert found == {}
    # the primitives do call it: the scan sees calls where they are
    assert barrier_calls((ROOT / "vkext/commands/barriers.py").read_text())


def test_the_scan_finds_a_hand_barrier():
    """Negative control of the scan: both spellings of a call are found."""
    src = "def f(cmd):\n    barrier(cmd, [])\n    commands.barrier(cmd)\n    record_barriers(cmd)\n"
    assert barrier_calls(src) == [2, 3]


def test_ssao_plans_the_barrier_between_its_dispatches():
    built = build(_config())
    plan = compile(built.graph)
    inside = [(b.step, b.resource, b.src.access, b.dst.access) for b in plan.step_barriers
              if b.pass_name == "ssao"]
    assert inside == [(1, "ssao.ao_raw", frozenset({"SHADER_STORAGE_WRITE"}),
                       frozenset({"SHADER_STORAGE_READ"}))]
    assert plan.steps["ssao"] == ("occlusion", "blur")


class _OneStep:
    """A pass context whose pass entered only its first step (later ones are ignored)."""

    def __init__(self, ctx):
        self._ctx = ctx

    def step(self, index: int) -> None:
        if index == 0:
            self._ctx.step(0)

    def __getattr__(self, name):
        return getattr(self._ctx, name)


def _collapse_ssao(monkeypatch) -> None:
    # both dispatches in one step: nothing orders the blur after the occlusion dispatch
    record = SSAOPass.record
    monkeypatch.setattr(SSAOPass, "steps",
                        lambda self: (Step("all", writes=("ao_raw", "ao")),))
    monkeypatch.setattr(SSAOPass, "record", lambda self, ctx: record(self, _OneStep(ctx)))


def test_ssao_steps_satisfy_sync_validation(vk_device, courtyard):
    r = render_vk(_config(), scene=courtyard, device=vk_device, frames=1)
    assert r.timings["validation"]["messages"] == 0, r.timings["validation"]
    image = r.images["fxaa.color"]
    assert image.shape[:2] == (54, 96) and np.ptp(image) > 0


def test_collapsed_ssao_steps_are_a_hazard(courtyard, monkeypatch):
    """Negative control: with the blanket barrier gone, only the declared steps order the
    blur after the occlusion dispatch; collapsed into one step, sync validation sees it."""
    from vkext import VkDevice

    _collapse_ssao(monkeypatch)
    device = VkDevice(validation=True, label="rfw-tests-ssao-steps")
    try:
        if not device.sync_validation:
            pytest.fail("synchronization validation is not available: this control needs it")
        r = render_vk(_config(), scene=courtyard, device=device, frames=1)
        texts = r.timings["validation"]["texts"]
    finally:
        device.destroy()
    assert any("SYNC-HAZARD-READ-AFTER-WRITE" in t and "ssao.ao_raw" in t for t in texts), \
        texts


def test_a_raycast_batch_is_ordered_by_its_plan():
    from vkext.accel.plan import compiled
    from vkext.raycast import batch_graph

    plan = compiled(batch_graph("ray_query"))
    assert plan.order == ("rays", "trace", "hits")
    got = {(b.pass_name, b.resource, tuple(sorted(b.dst.access))) for b in plan.barriers}
    # rays in before the trace reads them, the hits written before they are copied out; the
    # buffers persist, so the next batch's copy and trace wait for this batch's reads
    assert got == {("rays", "rays", ("TRANSFER_WRITE",)),
                   ("trace", "rays", ("SHADER_STORAGE_READ",)),
                   ("trace", "hits", ("SHADER_STORAGE_WRITE",)),
                   ("hits", "hits", ("TRANSFER_READ",))}


def test_raycast_without_its_plan_is_a_hazard(vk_device, monkeypatch):
    """Negative control of tests/vkext/test_raycast.py's zero messages: the plan's barriers
    are what orders a batch's copies and trace. Ray queries only: the synchronization
    validation of layers 1.3.239 sees no vkCmdTraceRaysKHR access (measured: the
    ray_pipeline method without the barriers gives 0 messages)."""
    import rfw
    from vkext import VkDevice
    from vkext.raycast import caster

    method = "ray_query"
    if "VK_KHR_ray_query" not in vk_device.caps:
        pytest.skip("no VK_KHR_ray_query")

    class Silent(caster.PlanRecorder):
        def _record(self, cmd, barriers):
            pass

    monkeypatch.setattr(caster, "PlanRecorder", Silent)
    monkeypatch.setenv("RFW_RAYCAST_MAPPED", "0")  # staged: the copies the plan orders
    device = VkDevice(validation=True, label="rfw-tests-raycast-plan")
    try:
        if not device.sync_validation:
            pytest.fail("synchronization validation is not available: this control needs it")
        v = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
        o = np.float32([[0.2, 0.2, -1]] * 64)
        d = np.float32([[0, 0, 1]] * 64)
        hits = rfw.raycast(v, np.array([[0, 1, 2]]), o, d, device=device, method=method,
                           batch=16)
        texts = [m.text for m in device.messages]
    finally:
        device.messages.clear()
        device.destroy()
    assert np.isfinite(hits["t"]).any()
    assert any("SYNC-HAZARD-READ-AFTER-WRITE" in t and "raycast.rays" in t for t in texts), \
        texts
