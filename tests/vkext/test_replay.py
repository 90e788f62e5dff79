"""Passes recorded once and replayed on vk (``VkPassContext.replay``, ``vkext.bundles``).

Counted, not timed: the dispatches, scene draws and mesh-task draws a frame records. After the
first frame a pass whose settings, resources, scene (and key) are unchanged records nothing;
a changed setting or culling camera records that pass again (negative controls), and every
image equals the one recorded inline each frame (``bundles=False``), bit for bit. Under
synchronization validation passes record every frame (the layer misses hazards between
bundles), so these runs turn the executor's view of it off: the layer still runs, and a
correct plan gives it nothing to report.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rfw.config import apply_overrides, build, load_config
from rfw.options import RunOptions
from vkext.context import VkPassContext
from vkext.executor import VkExecutor
from vkext.fitting import fit_plan
from vkext.scene import VkScene

from ..conftest import tiny_scene
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]


def _frames(vk_device, monkeypatch, config: str, sets: list[str], frames: int, *, scene,
            bundles: bool = True, sync: bool = False, settings=None, camera=None):
    """Run ``frames`` frames on one executor; per frame the first output and what it
    recorded: dispatches per pass, scene draws and mesh-task draws. ``settings``: frame ->
    pass -> settings changed before it; ``camera``: frame -> camera position from then."""
    monkeypatch.setattr(vk_device, "sync_validation", sync)
    counts: Counter = Counter()
    dispatch, draw = VkPassContext.dispatch, VkScene.draw

    def counted_dispatch(self, **kw):
        counts[f"dispatch:{self.pass_.name}"] += 1
        return dispatch(self, **kw)

    def counted_draw(self, *a, **kw):
        counts["scene draws"] += 1
        return draw(self, *a, **kw)

    monkeypatch.setattr(VkPassContext, "dispatch", counted_dispatch)
    monkeypatch.setattr(VkScene, "draw", counted_draw)
    tasks = getattr(vk_device.fn, "vkCmdDrawMeshTasksIndirectEXT", None)
    if tasks is not None:
        def counted_tasks(*a):
            counts["mesh tasks"] += 1
            return tasks(*a)

        monkeypatch.setattr(vk_device.fn, "vkCmdDrawMeshTasksIndirectEXT", counted_tasks)
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), sets)
    built = build(cfg)
    plan, info = fit_plan(built.graph, vk_device, readback=True)
    vscene = VkScene(vk_device, scene)
    ex = None
    out = []
    try:
        vscene.set_viewport(cfg.size)
        ex = VkExecutor(vk_device, plan, built.passes, built.slots, vscene,
                        readback=tuple(plan.outputs), memory_info=info,
                        options=RunOptions(bundles=bundles))
        for k in range(frames):
            for name, values in (settings or {}).get(k, {}).items():
                ex.passes[name].params = ex.passes[name].params.replace(**values)
            if camera and k in camera:
                vscene.camera = replace(vscene.camera, position=camera[k])
                vscene.set_viewport(cfg.size)
            counts.clear()
            ex.run(1)
            out.append((ex.read(plan.outputs[0]).copy(), dict(counts)))
    finally:
        if ex is not None:
            ex.destroy()
        vscene.destroy()
    vk_device.check_validation()
    return out


def _same_images(a, b) -> None:
    for (x, _), (y, _) in zip(a, b, strict=True):
        assert np.array_equal(x, y)


def test_unchanged_passes_record_nothing_after_the_first_frame(vk_device, monkeypatch):
    # one queue: on a device with a compute-only family, async ssao would record every
    # frame there (test_async_compute covers that pass's recording)
    sets = ["size=64x48", "shadow.enabled=true", "async_compute=off"]
    # frame 2 changes the exposure (tonemap records again), frame 3 changes it back (the
    # bundle of frames 0-1 is replayed, with the uniform values it was recorded with)
    change = {2: {"tonemap": {"exposure": 2.0}}, 3: {"tonemap": {"exposure": 1.0}}}
    cached = _frames(vk_device, monkeypatch, "deferred_ssao_shadows", sets, 5,
                     scene=tiny_scene(), settings=change)
    inline = _frames(vk_device, monkeypatch, "deferred_ssao_shadows", sets, 5,
                     scene=tiny_scene(), settings=change, bundles=False)
    first = cached[0][1]
    assert first["scene draws"] == 2  # shadow and gbuffer
    assert {k for k in first if k.startswith("dispatch:")} == {
        "dispatch:ssao", "dispatch:lighting", "dispatch:tonemap", "dispatch:fxaa"}
    assert [c for _, c in cached[1:]] == [{}, {"dispatch:tonemap": 1}, {}, {}]
    # negative control: inline, every frame records every pass again
    assert all(c == first for _, c in inline)
    _same_images(cached, inline)
    # the exposure reached frame 2: 1 of the pixels measured on lavapipe
    assert changed_share(cached[1][0], cached[2][0]) > 0.5
    assert np.array_equal(cached[1][0], cached[3][0])  # and its undoing frame 3


def test_sync_validation_records_every_frame(vk_device, monkeypatch):
    # the layer does not see hazards between bundles: under it, passes do not replay
    # (scene draws still come from their bundles)
    sets = ["size=64x48"]
    checked = _frames(vk_device, monkeypatch, "deferred", sets, 3, scene=tiny_scene(),
                      sync=True)
    assert [c for _, c in checked] == [{"scene draws": 1, "dispatch:lighting": 1,
                                        "dispatch:tonemap": 1},
                                       {"dispatch:lighting": 1, "dispatch:tonemap": 1},
                                       {"dispatch:lighting": 1, "dispatch:tonemap": 1}]
    replayed = _frames(vk_device, monkeypatch, "deferred", sets, 3, scene=tiny_scene())
    assert [c for _, c in replayed][1:] == [{}, {}]
    _same_images(checked, replayed)


@pytest.fixture
def meshlets(vk_device, courtyard):
    if "VK_EXT_mesh_shader" not in vk_device.caps:
        pytest.skip(f"{vk_device.name} has no VK_EXT_mesh_shader")
    return courtyard


def test_meshlet_passes_replay_while_the_camera_moves(vk_device, monkeypatch, meshlets):
    sets = ["size=96x54"]
    moved = {3: (-4.0, 5.0, 14.0)}
    cached = _frames(vk_device, monkeypatch, "meshlet", sets, 5, scene=meshlets,
                     camera=moved)
    inline = _frames(vk_device, monkeypatch, "meshlet", sets, 5, scene=meshlets,
                     camera=moved, bundles=False)
    counts = [c for _, c in cached]
    assert counts[0]["mesh tasks"] > 1 and counts[0]["dispatch:cull"] == 2
    # frame 1 is no longer the first (the visibility clear is not repeated): the culling
    # pass records again; then nothing, the camera's move included (the culling camera is
    # the scene's camera uniforms, copied in by each frame: vkext.scene.copy_camera)
    assert counts[1] == {"dispatch:cull": 2}
    assert counts[2:] == [{}, {}, {}]
    assert all(c["mesh tasks"] == counts[0]["mesh tasks"] for _, c in inline)
    _same_images(cached, inline)
    # the view moved: 0.996 of the pixels measured on lavapipe
    assert changed_share(cached[2][0], cached[3][0]) > 0.3


def test_mesh_draws_are_bundled_under_sync_validation(vk_device, monkeypatch, meshlets):
    # passes record every frame here, but the render pass's commands come from a bundle
    # recorded once; a setting that changes them (the cone flag in the push constants)
    # records it again
    sets = ["size=96x54"]
    change = {2: {"gbuffer": {"cone": False}, "gbuffer_late": {"cone": False}}}
    cached = _frames(vk_device, monkeypatch, "meshlet", sets, 4, scene=meshlets, sync=True,
                     settings=change)
    inline = _frames(vk_device, monkeypatch, "meshlet", sets, 4, scene=meshlets, sync=True,
                     settings=change, bundles=False)
    tasks = [c.get("mesh tasks", 0) for _, c in cached]
    assert tasks[0] > 1 and tasks[1] == 0 and tasks[2] == tasks[0] and tasks[3] == 0
    assert all(c.get("mesh tasks") == tasks[0] for _, c in inline)  # negative control
    _same_images(cached, inline)
