"""Scene draws recorded once and replayed (vkext.bundles): after the first frame a frame
records no Python per draw, settings still reach the GPU, and a changed pipeline state
records again. Every image equals the one recorded inline each frame (bundles=False),
bit for bit; validation on, zero messages.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rfw.config import apply_overrides, build, load_config
from rfw.options import RunOptions
from vkext.executor import VkExecutor
from vkext.fitting import fit_plan
from vkext.scene import VkScene

from ..conftest import tiny_scene
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]


def _frames(vk_device, monkeypatch, config: str, sets: list[str], frames: int, *,
            scene, settings=None, bundles: bool = True, swap_scene=None):
    """Run ``frames`` frames on one executor; per frame the output image and the scene draw
    calls recorded (``VkScene.draw`` calls, instances). ``settings``: frame -> pass ->
    settings changed before it records; ``swap_scene``: frame -> a scene to draw from then."""
    calls: list[int] = []
    draw = VkScene.draw

    def counted(self, *args, **kwargs):
        n = draw(self, *args, **kwargs)
        calls.append(n)
        return n

    monkeypatch.setattr(VkScene, "draw", counted)
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), sets)
    built = build(cfg)
    plan, info = fit_plan(built.graph, vk_device, readback=True)
    scenes = [VkScene(vk_device, scene)]
    ex = None
    out = []
    try:
        scenes[0].set_viewport(cfg.size)
        ex = VkExecutor(vk_device, plan, built.passes, built.slots, scenes[0],
                        readback=tuple(plan.outputs), memory_info=info,
                        options=RunOptions(bundles=bundles))
        for k in range(frames):
            for name, values in (settings or {}).get(k, {}).items():
                ex.passes[name].params = ex.passes[name].params.replace(**values)
            if swap_scene and k in swap_scene:
                scenes.append(VkScene(vk_device, swap_scene[k]))
                scenes[-1].set_viewport(cfg.size)
                ex.scene = scenes[-1]
            before = len(calls)
            ex.run(1)
            out.append((ex.read(plan.outputs[0]).copy(), calls[before:]))
    finally:
        if ex is not None:
            ex.destroy()
        for s in scenes:
            s.destroy()
    vk_device.check_validation()
    return out


def test_later_frames_record_no_draw(vk_device, monkeypatch, courtyard):
    sets = ["shadow.enabled=true", "size=96x54"]
    cached = _frames(vk_device, monkeypatch, "forward", sets, 3, scene=courtyard)
    inline = _frames(vk_device, monkeypatch, "forward", sets, 3, scene=courtyard,
                     bundles=False)
    # the shadow and forward passes record their draws in the first frame only
    first = cached[0][1]
    assert len(first) == 2 and min(first) > 300
    assert [calls for _, calls in cached] == [first, [], []]
    # negative control: recorded inline, every frame records every draw again
    assert [calls for _, calls in inline] == [first] * 3
    for (a, _), (b, _) in zip(cached, inline, strict=True):
        assert np.array_equal(a, b)
    assert cached[0][0][..., :3].std() > 10  # a picture, not a cleared target


def test_a_setting_reaches_the_gpu_without_recording_again(vk_device, monkeypatch):
    sets = ["shadow.enabled=true", "size=64x48"]
    change = {1: {"forward": {"ambient": 0.0, "shadow_bias": 0.02}}}
    cached = _frames(vk_device, monkeypatch, "forward", sets, 2, scene=tiny_scene(),
                     settings=change)
    inline = _frames(vk_device, monkeypatch, "forward", sets, 2, scene=tiny_scene(),
                     settings=change, bundles=False)
    assert [calls for _, calls in cached] == [[2, 2], []]
    # the uniform values are rewritten each frame: frame 1 shows the new settings
    # the change reached the image: 0.35 of the pixels measured on lavapipe
    assert changed_share(cached[0][0], cached[1][0]) > 0.1
    for (a, _), (b, _) in zip(cached, inline, strict=True):
        assert np.array_equal(a, b)


def test_a_changed_pipeline_state_records_again(vk_device, monkeypatch):
    sets = ["view=overdraw", "ao=off", "size=64x48"]
    change = {1: {"overdraw": {"cull": "none"}}}
    cached = _frames(vk_device, monkeypatch, "deferred_ssao_shadows", sets, 3,
                     scene=tiny_scene(), settings=change)
    inline = _frames(vk_device, monkeypatch, "deferred_ssao_shadows", sets, 3,
                     scene=tiny_scene(), settings=change, bundles=False)
    # the debug view culls every other scene pass: frame 1 records the overdraw pass again,
    # whose pipeline culls nothing now
    assert [calls for _, calls in cached] == [[2], [2], []]
    assert [calls for _, calls in inline] == [[2], [2], [2]]
    # back faces drawn too: more fragments per pixel (a stale bundle would repeat frame 0)
    # the change reached the image: 0.62 of the pixels measured on lavapipe
    assert changed_share(cached[0][0], cached[1][0]) > 0.2
    for (a, _), (b, _) in zip(cached, inline, strict=True):
        assert np.array_equal(a, b)


def test_another_scene_records_again(vk_device, monkeypatch, courtyard):
    sets = ["size=64x48"]
    cached = _frames(vk_device, monkeypatch, "deferred", sets, 3, scene=tiny_scene(),
                     swap_scene={1: courtyard})
    calls = [calls for _, calls in cached]
    assert calls[0] == [2] and len(calls[1]) == 1 and calls[1][0] > 300 and calls[2] == []
    # the change reached the image: 0.81 of the pixels measured on lavapipe
    assert changed_share(cached[0][0], cached[1][0]) > 0.25
    assert np.array_equal(cached[1][0], cached[2][0])
