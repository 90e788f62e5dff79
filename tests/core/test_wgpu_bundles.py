"""The wgpu backend records a pass's scene draws once into a render bundle and replays it.

Counted, not timed: bundle encoders made and scene draws encoded over several frames. A
setting that changes the pipeline, or another scene, records again (negative controls); a
setting that only changes uniform bytes does not, and still reaches the image.
"""

from __future__ import annotations

import numpy as np
import pytest

from rfw.backends.gpu_scene import GpuScene
from rfw.config import apply_overrides, build, load_config
from rfw.frame import open_frame

from ..conftest import ROOT, tiny_scene

SIZE = "size=96x64"


@pytest.fixture
def counted(monkeypatch):
    """Counts of bundle encoders made and instances encoded (GpuScene.draw's return)."""
    import wgpu

    counts = {"encoders": 0, "draws": 0}
    device_cls = wgpu.backends.wgpu_native.GPUDevice
    make = device_cls.create_render_bundle_encoder
    draw = GpuScene.draw

    def counting_make(self, **kw):
        counts["encoders"] += 1
        return make(self, **kw)

    def counting_draw(self, *a, **kw):
        n = draw(self, *a, **kw)
        counts["draws"] += n
        return n

    monkeypatch.setattr(device_cls, "create_render_bundle_encoder", counting_make)
    monkeypatch.setattr(GpuScene, "draw", counting_draw)
    return counts


def _frame(device, name: str, *sets: str, scene=None):
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [SIZE, *sets])
    return open_frame(build(cfg), "wgpu", devices=(device,), scene=scene or tiny_scene())


def _image(frame, output: str) -> np.ndarray:
    return frame.read(output).copy()


def test_scene_draws_are_recorded_once_and_replayed(device, counted):
    # shadow and gbuffer draw the scene: two bundles, encoded in the first frame only
    frame = _frame(device, "deferred_ssao_shadows")
    try:
        ex = frame.executors["wgpu"]
        frame.run(1)
        first = dict(counted)
        image = _image(frame, "fxaa.color")
        frame.run(3)
        assert first == {"encoders": 2, "draws": 2 * len(ex.scene.scene.instances)}
        assert counted == first  # three more frames: replayed, nothing encoded
        assert ex.bundles_recorded == 2
        assert np.array_equal(_image(frame, "fxaa.color"), image)
    finally:
        frame.destroy()


def test_a_pipeline_setting_records_again(device, counted):
    # negative control: the overdraw pass's cull mode is part of its pipeline
    frame = _frame(device, "deferred_ssao_shadows", "view=overdraw")
    try:
        ex = frame.executors["wgpu"]
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "fxaa.color")
        ex.passes["overdraw"].params.cull = "none"
        frame.run(2)
        assert counted["encoders"] == before + 1  # overdraw alone, and once
        assert not np.array_equal(_image(frame, "fxaa.color"), image)  # back faces counted
    finally:
        frame.destroy()


def test_another_scene_records_again(device, counted):
    # negative control: the bundles name the scene's buffers and bind groups
    frame = _frame(device, "deferred")
    try:
        ex = frame.executors["wgpu"]
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "tonemap.ldr")
        moved = tiny_scene()
        moved.instances[1].transform[0, 3] = 1.5  # the cube steps aside
        old = ex.scene
        ex.scene = GpuScene(device.device, moved)
        ex.scene.set_viewport(old.size)
        try:
            frame.run(2)
            assert counted["encoders"] == before + 1
            assert not np.array_equal(_image(frame, "tonemap.ldr"), image)
        finally:
            ex.scene.destroy()
            ex.scene = old
    finally:
        frame.destroy()


def test_a_uniform_setting_reaches_the_replayed_draws(device, counted):
    # forward's ambient is bytes in its u_params buffer, written every frame: no new bundle,
    # and the image is the one a frame built with that setting gives
    frame = _frame(device, "forward")
    fresh = _frame(device, "forward", "forward.ambient=0.25")
    try:
        frame.run(2)
        before, image = counted["encoders"], _image(frame, "tonemap.ldr")
        frame.executors["wgpu"].passes["forward"].params.ambient = 0.25
        frame.run(1)
        assert counted["encoders"] == before
        changed = _image(frame, "tonemap.ldr")
        assert not np.array_equal(changed, image)
        fresh.run(1)
        assert np.array_equal(changed, _image(fresh, "tonemap.ldr"))
    finally:
        frame.destroy()
        fresh.destroy()


def test_replayed_frames_touch_no_shader_file(device, monkeypatch):
    # a pass's program is looked up from memory between looks at its sources (RECHECK_S)
    from pathlib import Path

    from rfw.backends import wgpu_backend

    frame = _frame(device, "deferred_ssao_shadows")
    try:
        frame.run(1)
        stats = []
        real = Path.stat

        def counting_stat(self, *a, **kw):
            stats.append(self)
            return real(self, *a, **kw)

        monkeypatch.setattr(Path, "stat", counting_stat)
        monkeypatch.setattr(wgpu_backend, "RECHECK_S", 1e9)  # however slow the frames are
        frame.run(2)
        assert stats == []
        monkeypatch.setattr(wgpu_backend, "RECHECK_S", 0.0)  # negative control: look always
        frame.run(1)
        assert any(p.suffix == ".glsl" for p in stats)
    finally:
        frame.destroy()


def test_a_cleared_program_cache_is_not_bypassed(device):
    # rfw view's R clears ShaderCache.programs: the next lookup makes the program again
    from rfw.backends.wgpu_backend import ShaderCache
    from rfw.shaders import program_files

    cache = ShaderCache(device)
    paths = program_files(ROOT / "passes" / "tonemap", "tonemap.comp.glsl")
    made = []

    def make():
        made.append(1)
        return cache.program(paths, {}, "compute", {})

    first = cache.recent(("k",), make)
    assert cache.recent(("k",), make) is first and len(made) == 1
    cache.programs.clear()
    again = cache.recent(("k",), make)
    assert len(made) == 2 and again is not first
