"""Build, render and drop a graph many times: live GPU objects return to baseline."""

import gc

import wgpu

from rfw.config import apply_overrides, load_config
from rfw.render import render

from ..conftest import ROOT


def live() -> dict[str, int]:
    gc.collect()
    counts = wgpu.diagnostics.object_counts.get_dict()
    return {k: v["count"] for k, v in counts.items() if k != "total"}


def test_render_and_drop_returns_to_baseline(device, scene):
    cfg = apply_overrides(load_config(ROOT / "configs" / "deferred.toml"),
                          ["size=64x48", "shadow.enabled=true", "shadow.resolution=256"])
    render(cfg, scene=scene, device=device)  # warm up: the device's own objects exist now
    before = live()
    held = render(cfg, scene=scene, device=device)
    during = live()
    # the counters see a render's objects (the g-buffer, shadow map and outputs), so their
    # return to baseline below means something
    assert during["Texture"] > before["Texture"] and during["Buffer"] > before["Buffer"]
    del held
    for _ in range(6):
        result = render(cfg, scene=scene, device=device)
        del result
    after = live()
    grown = {k: (before[k], after[k]) for k in before if after.get(k, 0) > before[k]}
    assert not grown, f"objects still alive after dropping the renders: {grown}"
    new = set(after) - set(before)
    assert not {k for k in new if after[k]}, f"new kinds of objects alive: {new}"
    assert after["Texture"] == before["Texture"] and after["Device"] == before["Device"]
