"""rfw.exec: the executors' shared half (issue 22), one definition used by both backends."""

from __future__ import annotations

import pytest

from rfw.exec.samplers import Samplers
from rfw.exec.timing import PassTiming, pass_timings
from rfw.shaders import ShaderError


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
