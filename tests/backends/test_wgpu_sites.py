"""The wgpu backend keeps, per call site (a pass's n-th dispatch or scene draw), what it looked
up: a frame that binds the same objects looks no program up and makes no bind group.

Counted, not timed. Settings still reach the image (their bytes are written each frame); a
new scene, another bound object or the hot-reload interval makes the lookups again (negative
controls).
"""

from __future__ import annotations

import numpy as np
import pytest

from rfw.backends.wgpu import Executor, context, programs
from rfw.backends.wgpu.context import _same_call
from rfw.backends.wgpu.programs import ShaderCache
from rfw.backends.wgpu.scene import GpuScene
from rfw.config import apply_overrides, build, load_config
from rfw.frame import open_frame
from rfw.passes import Settings

from ..conftest import ROOT, tiny_scene
from ..golden_util import changed_share

SIZE = "size=96x64"


@pytest.fixture
def lookups(monkeypatch):
    """Counts of program lookups (ShaderCache.recent) and bind groups asked for."""
    counts = {"programs": 0, "bind groups": 0}
    recent, bind_group = ShaderCache.recent, Executor.bind_group

    def counting_recent(self, *a, **kw):
        counts["programs"] += 1
        return recent(self, *a, **kw)

    def counting_bind_group(self, *a, **kw):
        counts["bind groups"] += 1
        return bind_group(self, *a, **kw)

    monkeypatch.setattr(ShaderCache, "recent", counting_recent)
    monkeypatch.setattr(Executor, "bind_group", counting_bind_group)
    for module in (programs, context):  # however slow the frames are
        monkeypatch.setattr(module, "RECHECK_S", 1e9)
    return counts


def _frame(device, name: str, *sets: str):
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [SIZE, *sets])
    return open_frame(build(cfg), "wgpu", devices=(device,), scene=tiny_scene())


def test_repeated_calls_look_nothing_up(device, lookups, monkeypatch):
    frame = _frame(device, "deferred_ssao_shadows")
    try:
        frame.run(1)
        assert lookups["programs"] >= 6 and lookups["bind groups"] >= 6
        image = frame.read("fxaa.color").copy()
        lookups.update({"programs": 0, "bind groups": 0})
        frame.run(2)
        assert lookups == {"programs": 0, "bind groups": 0}
        assert np.array_equal(frame.read("fxaa.color"), image)
        # past the hot-reload interval every call looks at its sources, and keeps its
        # program while they are unchanged
        stamps = []
        real = programs._stamps

        def counting_stamps(paths):
            out = real(paths)
            stamps.append(out)
            return out

        for module in (programs, context):
            monkeypatch.setattr(module, "_stamps", counting_stamps)
            monkeypatch.setattr(module, "RECHECK_S", 0.0)
        frame.run(1)
        assert len(stamps) >= 6 and lookups["programs"] == 0
        # negative control: changed sources look the program up again
        for module in (programs, context):
            monkeypatch.setattr(module, "_stamps", lambda paths: ())
        frame.run(1)
        assert lookups["programs"] >= 6
    finally:
        frame.destroy()


def test_another_scene_looks_up_again(device, lookups):
    # negative control: the scene is part of every call (its buffers are bound)
    frame = _frame(device, "deferred")
    try:
        ex = frame.executors["wgpu"]
        frame.run(2)
        lookups.update({"programs": 0, "bind groups": 0})
        old = ex.scene
        ex.scene = GpuScene(device.device, tiny_scene())
        ex.scene.set_viewport(old.size)
        try:
            frame.run(1)
            assert lookups["programs"] >= 3  # gbuffer, lighting, tonemap
        finally:
            ex.scene.destroy()
            ex.scene = old
    finally:
        frame.destroy()


def test_a_setting_reaches_a_repeated_dispatch(device, lookups):
    # tonemap's exposure is bytes in its uniform buffer: no lookup, and the image is the
    # one a frame built with that setting gives
    frame = _frame(device, "deferred")
    fresh = _frame(device, "deferred", "tonemap.exposure=2.0")
    try:
        frame.run(2)
        image = frame.read("tonemap.ldr").copy()
        lookups.update({"programs": 0, "bind groups": 0})
        frame.executors["wgpu"].passes["tonemap"].params.exposure = 2.0
        frame.run(1)
        assert lookups["programs"] == 0
        changed = frame.read("tonemap.ldr").copy()
        assert changed_share(changed, image) > 0.5  # every pixel
        fresh.run(1)
        assert np.array_equal(changed, fresh.read("tonemap.ldr"))
    finally:
        frame.destroy()
        fresh.destroy()


class _Params(Settings):
    exposure: float = 1.0


def test_a_call_holds_for_the_same_objects_only():
    view, other = object(), object()
    hit = (("call",), ("t_hdr", "u_params"), (view, _Params("p")), "found", [], [0.0])
    # settings are data: another object with other values still holds
    assert _same_call(hit, ("call",), {"t_hdr": view, "u_params": _Params("q")}) is hit
    # negative controls: another bound object, another binding name, another call
    assert _same_call(hit, ("call",), {"t_hdr": other, "u_params": _Params("p")}) is None
    assert _same_call(hit, ("call",), {"t_ldr": view, "u_params": _Params("p")}) is None
    assert _same_call(hit, ("other",), {"t_hdr": view, "u_params": _Params("p")}) is None
