"""``rfw view``'s overlay and error handling, driven headless under Xvfb through the viewer's
``frames``/``script`` hooks: a small driver script runs a real window in a subprocess, clicks
through the canvas's own events, and prints what the overlay showed as JSON."""

from __future__ import annotations

import json
import os
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ..cli.warm import warm_cli
from ..conftest import ROOT
from .view_xvfb import needs_xvfb, under_xvfb

pytestmark = needs_xvfb


DEFERRED = ROOT / "configs" / "deferred.toml"

# the driver: a Viewer with a hook before each draw; HOOK is the test's part
DRIVER = """
import json, sys
from pathlib import Path
sys.path.insert(0, {tmp!r})
{pre}
from rfw.config import apply_overrides, load_config
from rfw.frame import load_scene_for
from rfw.view import Viewer

cfg = apply_overrides(load_config({config!r}), {sets!r})
v = Viewer(cfg, scene=load_scene_for(cfg), frames={frames}, report_every=0,
           overlay={overlay}, screenshot=Path({shot!r}), backend={backend!r})
draws = [0]
events = []
out = {{}}

def click(x, y, kind):
    v.canvas.submit_event({{"event_type": kind, "x": x, "y": y, "button": 1,
                           "buttons": (1,) if kind == "pointer_down" else (),
                           "modifiers": (), "ntouches": 0, "touches": {{}}}})

def centre(name):
    x0, y0, x1, y1 = v.overlay.rects[name]
    return (x0 + x1) / 2, (y0 + y1) / 2

draw = v.draw
def hooked():
    n = draws[0]
{hook}
    draws[0] += 1
    draw()
v.draw = hooked
v.run()
out["draws"] = draws[0]
out["frames"] = v.frame_count
if v.overlay is not None:
    out["lines"] = v.overlay.lines
    out["rects"] = v.overlay.rects
print("RESULT " + json.dumps(out))
"""


def drive(tmp: Path, hook: str, *, config: Path = DEFERRED, sets=(), frames: int = 8,
          overlay: bool = True, pre: str = "",
          backend: str | None = None) -> tuple[dict, list[str], str]:
    script = tmp / "driver.py"
    script.write_text(DRIVER.format(tmp=str(tmp), config=str(config), sets=list(sets),
                                    frames=frames, overlay=overlay, pre=pre, shot=str(tmp / "shot.png"),
                                    backend=backend,
                                    hook=textwrap.indent(textwrap.dedent(hook), "    ")))
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = under_xvfb([sys.executable, str(script)], env=env, cwd=tmp)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr and "Validation Error" not in done.stderr
    lines = done.stdout.splitlines()
    [result] = [line for line in lines if line.startswith("RESULT ")]
    return json.loads(result[len("RESULT "):]), lines, done.stderr


def run_cli(tmp: Path, size: str, *sets: str, config: Path = DEFERRED,
            args: tuple[str, ...] = ()) -> Path:
    out = tmp / "run"
    done = warm_cli("run", config, "--size", size, "--frames", "1", "--out", out, *args,
                    *(a for s in sets for a in ("--set", s)), cwd=tmp)
    assert done.returncode == 0, done.stdout + done.stderr
    return out


def run_png(tmp: Path, size: str, *sets: str, **kw) -> np.ndarray:
    out = run_cli(tmp, size, *sets, **kw)
    return np.asarray(Image.open(out / "tonemap.ldr.png").convert("RGBA")).astype(int)


def culling_shown(lines: list[str]) -> dict[str, int]:
    """The culling counters an overlay showed: ``culling: a 1, b 2,025, ...`` and the lines
    under it (thousands are written with commas)."""
    start = next(i for i, x in enumerate(lines) if x.startswith("culling:"))
    text = [lines[start][len("culling:"):]]
    text += [x for x in lines[start + 1:] if x.startswith("         ")]
    return {k: int(v.replace(",", "")) for item in ", ".join(text).split(", ")
            for k, v in [item.split()]}


def test_overlay_shows_timings_memory_and_toggles_passes_with_the_mouse(tmp_path):
    # frame 3: a click on the image beside the overlay (no change: the negative control);
    # frame 5: a click on the shadow pass's checkbox turns the pass on. GPU times are read
    # back when the viewer drains, at frame 17 (its stats every 15 frames from the second):
    # with 12 frames the rows still show "gpu -" and the check below fails
    result, lines, _ = drive(tmp_path, """
        if n == 3:
            x1, y1 = v.overlay.rects["window"][2:]
            click(x1 + 20, y1 + 10, "pointer_down")
        if n == 4:
            x1, y1 = v.overlay.rects["window"][2:]
            click(x1 + 20, y1 + 10, "pointer_up")
        if n == 5:
            click(*centre("pass:shadow"), "pointer_move")
            click(*centre("pass:shadow"), "pointer_down")
        if n == 6:
            click(*centre("pass:shadow"), "pointer_up")
    """, sets=["size=640x480"], frames=20)
    graphs = [x for x in lines if x.startswith("graph:")]
    assert graphs == ["graph: gbuffer -> lighting -> tonemap (off: shadow)",
                      "graph: shadow -> gbuffer -> lighting -> tonemap"]
    shown = result["lines"]
    # one row per pass of the plan, with numbers for GPU and CPU ms
    rows = [x.split() for x in shown if x.split()[0] in ("shadow", "gbuffer", "lighting",
                                                          "tonemap") and "gpu" in x]
    assert [r[0] for r in rows] == ["shadow", "gbuffer", "lighting", "tonemap"]
    for r in rows:
        assert r[1] == "gpu" and float(r[2]) >= 0 and r[3] == "cpu" and float(r[4]) > 0
    assert any(x.startswith("memory: transients") and "MiB" in x for x in shown)
    assert any("textures held" in x for x in shown)
    assert any(x.startswith("culling:") for x in shown)
    assert any(x.startswith("graph: frame") for x in shown)  # the frame-time graph
    # the overlay covers its window only: elsewhere the presented pixels are rfw run's
    shot = np.asarray(Image.open(tmp_path / "shot.png")).astype(int)
    expected = run_png(tmp_path, "640x480", "shadow.enabled=true")
    x0, y0, x1, y1 = (round(c) for c in result["rects"]["window"])
    outside = np.ones(shot.shape[:2], bool)
    outside[max(0, y0 - 1):y1 + 2, max(0, x0 - 1):x1 + 2] = False
    assert np.abs(shot - expected)[outside].max() <= 1
    # negative control: inside its window the overlay is drawn (differs from the image)
    assert np.abs(shot - expected)[~outside].max() > 32


def test_variant_buttons_and_groups_listed(tmp_path):
    config = ROOT / "configs" / "deferred_ssao_shadows.toml"
    result, lines, _ = drive(tmp_path, """
        if n == 3:
            click(*centre("variant:shadows=off"), "pointer_move")
            click(*centre("variant:shadows=off"), "pointer_down")
        if n == 4:
            click(*centre("variant:shadows=off"), "pointer_up")
    """, config=config, sets=["size=640x480"], frames=8)
    assert [x for x in lines if x.startswith("variants:")] == [
        "variants: ao=on, >shadows=off, aa=fxaa, view=final"]  # the clicked group is V's now
    listed = [x for x in result["lines"] if x[:2] in ("> ", "  ") and "[" in x]
    # every group is on screen with its options, the one in force in brackets
    assert listed == ["  ao: [on] off", "> shadows: on [off]", "  aa: [fxaa] none taa",
                      "  view: [final] ao normals depth overdraw"]


@pytest.mark.parametrize("backend", [None, "vk"])
def test_broken_shader_is_said_once(tmp_path, backend):
    # the same GLSL file is the shader of the pass on either backend: wgpu compiles it on the
    # next frame, vk when R builds the frame again
    shader = (ROOT / "passes" / "tonemap" / "tonemap.comp.glsl").read_text()
    (tmp_path / "tonemap.comp.glsl").write_text(shader)
    (tmp_path / "hot_tonemap.py").write_text(textwrap.dedent('''
        from passes.tonemap.tonemap import TonemapPass
        from rfw import register_pass

        @register_pass("hot_tonemap")
        class HotTonemapPass(TonemapPass):
            """The tonemap pass with its shader in the test's folder."""
    '''))
    config = tmp_path / "hot.toml"
    config.write_text(DEFERRED.read_text().replace('name = "tonemap"',
                                                   'name = "tonemap"\nuse = "hot_tonemap"'))
    broken = shader.replace("void main", "oops_undeclared; void main", 1)
    assert broken != shader
    # draws 0-2 render; 3-8 find the shader broken (R reloads it at once); 9- render again
    result, lines, _ = drive(tmp_path, f"""
        if n == 3:
            Path({str(tmp_path / "tonemap.comp.glsl")!r}).write_text({broken!r})
            v.key("r")
        if n == 8:  # what the overlay showed on draw 7, a broken one
            out["broken"] = list(v.overlay.lines)
        if n == 9:
            Path({str(tmp_path / "tonemap.comp.glsl")!r}).write_text({shader!r})
            v.key("r")
    """, config=config, sets=["size=32x18"], frames=12, pre="import hot_tonemap",
        backend=backend)
    skipped = [x for x in lines if x.startswith("frame skipped")]
    assert len(skipped) == 1 and "pass 'tonemap'" in skipped[0], lines
    assert "tonemap.comp.glsl:" in skipped[0]  # the file and line of the error
    assert result["draws"] == 12 and result["frames"] == 12 - 6  # six draws were broken
    assert lines.index(skipped[0]) < lines.index("frames render again")
    # broken frames still show the window, with the error in the overlay; fixed, it is gone
    assert skipped[0] in result["broken"] and skipped[0] not in result["lines"]


MESHLET = ROOT / "configs" / "meshlet.toml"


def test_overlay_shows_the_vk_culling_counters_of_the_view(tmp_path):
    # draws 0-9 from the config's camera; draws 11-13 step forward (W): the counters read
    # again at frame 17 are the moved view's
    result, _, _ = drive(tmp_path, """
        if n == 10:
            out["first"] = list(v.overlay.lines)
            v.frame.drain()
            out["samples"], out["drawn"] = len(v.timings()["cull"].cpu_ms), v.frame_count
        if n in (11, 12, 13):
            v.key("w")
    """, config=MESHLET, sets=["size=160x90"], frames=20)
    run = json.loads((run_cli(tmp_path, "160x90", config=MESHLET) / "timings.json").read_text())
    expected = {k: val for k, val in run["culling"].items() if val is not None}
    assert expected["meshlets_drawn"] > 0 and expected["culled_frustum"] > 0
    # what rfw run counted for the same view, to the meshlet
    assert culling_shown(result["first"]) == expected
    assert any(x.strip().startswith("vk: transients allocated") for x in result["first"])
    # negative control: the moved view's counters are told apart
    moved = culling_shown(result["lines"])
    assert moved.keys() == expected.keys() and moved != expected
    assert moved["meshlets_total"] == expected["meshlets_total"]  # the scene's: unchanged
    # the first frame (it compiles the pipelines) is a warm-up, as in rfw run: its times
    # are not among the overlay's
    assert result["drawn"] == 10 and result["samples"] == 10 - 1


def test_overlay_fits_a_small_window_and_scrolls(tmp_path):
    # the overlay's content needs more than 200x120: its window stays inside and scrolls
    small, _, _ = drive(tmp_path, "", sets=["size=200x120"], frames=3)
    x0, y0, x1, y1 = small["rects"]["window"]
    assert min(x0, y0) >= 0 and x1 <= 200 and y1 <= 120
    # negative control: in a large window the same overlay is taller than the small one
    large, _, _ = drive(tmp_path, "", sets=["size=640x480"], frames=3)
    assert large["rects"]["window"][3] > 120
