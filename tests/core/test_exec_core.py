"""rfw.exec: the executors' shared half (issue 22), one definition used by both backends."""

from __future__ import annotations

import numpy as np
import pytest

from rfw.exec.samplers import Samplers
from rfw.exec.timing import PassTiming, pass_timings
from rfw.shaders import ShaderError
from tests.vkext.test_executor import ACCUMULATE_GLSL


def test_samplers_are_made_once_per_key_and_checked_first():
    made = []

    def make(filter, address, compare):
        made.append((filter, address, compare))
        return object()

    s = Samplers(make)
    a = s.get("linear", "repeat", None)
    assert s.get("linear", "repeat", None) is a and len(s) == 1
    b = s.get("nearest", "repeat", "less")
    assert b is not a and made == [("linear", "repeat", None), ("nearest", "repeat", "less")]
    assert list(s) == [a, b]
    with pytest.raises(ShaderError, match="filter"):  # refused before the backend is asked
        s.get("cubic", "repeat", None)
    assert len(made) == 2
    s.clear()
    assert len(s) == 0 and s.get("linear", "repeat", None) is not a  # made again


def test_pass_timings_follow_the_plan_order():
    t = pass_timings(("gbuffer", "lighting"))
    assert list(t) == ["gbuffer", "lighting"]
    assert t["gbuffer"] == PassTiming("gbuffer") and t["gbuffer"].gpu_ms == []


def test_both_executors_are_the_core_with_primitives():
    import vkext.executor as vk
    from rfw.backends.wgpu import executor as wg
    from rfw.exec.core import ExecutorCore

    assert issubclass(vk.VkExecutor, ExecutorCore) and issubclass(wg.Executor, ExecutorCore)
    for cls in (vk.VkExecutor, wg.Executor):  # the frame protocol is the core's, unchanged
        for name in ("keep_in_flight", "run", "drain", "begin_frame", "record", "flush",
                     "end_frame", "frame", "sampler", "destroy"):
            assert name not in vars(cls), f"{cls.__name__} overrides {name}"


# history ping-pong: the core swaps x and x@prev before every frame after the first, on
# every backend (vk's test_executor checks the layouts of the same graph)


def _accumulated(device, frames: int) -> np.ndarray:
    from rfw import ComputePass, Settings
    from rfw.backends.wgpu.executor import Executor
    from rfw.graph import GraphBuilder, History, Texture, compile

    class Accumulate(ComputePass):
        """out = the previous frame's out + step."""

        shader = "accumulate.comp.glsl"
        shader_source = ACCUMULATE_GLSL  # vk's history test runs the same shader

        class Params(Settings):
            step: float = 0.125

        def record(self, ctx) -> None:
            ctx.dispatch(threads=ctx.extent("out"), t_prev=ctx.sampled("history"),
                         o_out=ctx.storage("out"), u_params=self.params)

    g = GraphBuilder("history", size=(16, 8))
    g.add_pass("acc", "compute").input("history", "acc.out", History()) \
        .output("out", Texture("rgba16float", usage=("storage",)))
    plan = compile(g.output("acc.out").build())
    ex = Executor(device, plan, {"acc": Accumulate("acc")},
                  {"acc": {"history": "acc.out@prev", "out": "acc.out"}},
                  readback=("acc.out",))
    try:
        ex.run(frames)
        return ex.read("acc.out").astype(np.float32)
    finally:
        ex.destroy()


def test_history_swaps_on_wgpu_too(device, monkeypatch):
    from rfw.backends.wgpu.executor import Executor

    assert np.all(_accumulated(device, 5) == 5 * 0.125)  # one step per frame through the swap
    monkeypatch.setattr(Executor, "_swap", lambda self, a, b: None)
    assert np.all(_accumulated(device, 5) == 0.125)  # negative control: no swap, no history


def test_a_replay_other_than_auto_or_false_is_refused_when_registered():
    from rfw import ComputePass, register_pass
    from rfw.graph import GraphError

    class Sometimes(ComputePass):
        shader_source = "#version 460\nvoid main() {}\n"
        shader = "sometimes.comp.glsl"
        replay = "sometimes"

    with pytest.raises(GraphError, match=r"'replay' must be \"auto\" or False, not 'sometimes'"):
        register_pass("replay_sometimes")(Sometimes)
    Sometimes.replay = "auto"  # negative control: the declared value registers
    assert register_pass("replay_sometimes")(Sometimes) is Sometimes
