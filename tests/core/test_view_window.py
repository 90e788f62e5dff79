"""``rfw view`` under Xvfb through the real CLI: the presented pixels are the ``rfw run``
image, toggles are transactional, every variant group is reachable, bad input is one line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ..cli.warm import warm_cli
from ..conftest import ROOT
from .view_xvfb import needs_xvfb, under_xvfb

pytestmark = needs_xvfb


SIZE = "48x27"
DEFERRED = str(ROOT / "configs" / "deferred.toml")
SSAO = str(ROOT / "configs" / "deferred_ssao_shadows.toml")


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "RFW_VIEW_FORMAT")}
    env.update(extra)
    return env


def view(tmp: Path, config: str, *args: str, **env: str) -> subprocess.CompletedProcess:
    return under_xvfb([sys.executable, "-m", "rfw.cli", "view", config, "--size", SIZE, *args],
                      env=_env(**env), cwd=tmp)


def run_png(tmp: Path, config: str, *sets: str) -> np.ndarray:
    out = tmp / ("run_" + "_".join(s.replace("=", "-") for s in sets))
    done = warm_cli("run", config, "--size", SIZE, "--frames", "1", "--out", out,
                    *(a for s in sets for a in ("--set", s)), environ=_env(), cwd=tmp)
    assert done.returncode == 0, done.stdout + done.stderr
    [png] = [p for p in out.glob("*.png")]
    return np.asarray(Image.open(png).convert("RGBA")).astype(int)


def shot(tmp: Path, config: str, name: str, *args: str, **env: str) -> tuple[np.ndarray, str]:
    path = tmp / name
    done = view(tmp, config, "--no-overlay", "--screenshot", str(path), *args, **env)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr and "Validation Error" not in done.stderr
    return np.asarray(Image.open(path)).astype(int), done.stdout


def max_diff(a: np.ndarray, b: np.ndarray) -> int:
    assert a.shape == b.shape
    return int(np.abs(a - b).max())


def test_window_shows_the_run_image(tmp_path):
    expected = run_png(tmp_path, DEFERRED)
    seen, _ = shot(tmp_path, DEFERRED, "view.png", "--frames", "3")
    assert max_diff(seen, expected) <= 1
    # negative control: an sRGB swapchain (the old behaviour) encodes a second time, brighter
    srgb, _ = shot(tmp_path, DEFERRED, "srgb.png", "--frames", "3",
                   RFW_VIEW_FORMAT="bgra8unorm-srgb")
    assert max_diff(srgb, expected) > 20
    mid = (expected[..., :3] > 16) & (expected[..., :3] < 240)  # where encoding brightens
    assert (srgb[..., :3][mid] > expected[..., :3][mid]).all()


def test_refused_toggle_rolls_back_and_later_toggles_work(tmp_path):
    # key 2 would disable gbuffer, which lighting reads: refused; key 1 then turns shadow on
    seen, out = shot(tmp_path, DEFERRED, "toggled.png", "--frames", "4", "--keys", "2,1")
    refused = [line for line in out.splitlines() if line.startswith("refused")]
    assert refused == [refused[0]] and "gbuffer.enabled=false" in refused[0]
    assert "pass 'lighting'" in refused[0] and "'gbuffer.albedo'" in refused[0]
    graphs = [line for line in out.splitlines() if line.startswith("graph:")]
    assert graphs == ["graph: gbuffer -> lighting -> tonemap (off: shadow)",
                      "graph: shadow -> gbuffer -> lighting -> tonemap"]
    assert max_diff(seen, run_png(tmp_path, DEFERRED, "shadow.enabled=true")) <= 1
    # negative control: the image without the shadow pass is told apart
    assert max_diff(seen, run_png(tmp_path, DEFERRED)) > 1


def test_every_variant_group_is_reachable(tmp_path):
    # v: ao=off; V: next group (shadows); v: shadows=off; V, V: past aa to the view group;
    # v: view=ao, refused (its source, ssao, is off); v: the option after it, view=normals
    seen, out = shot(tmp_path, SSAO, "variants.png", "--frames", "8",
                     "--keys", "v,V,v,V,V,v,v")
    lines = out.splitlines()
    assert [x for x in lines if x.startswith(("variants:", "variant group:"))] == [
        "variants: >ao=off, shadows=on, aa=fxaa, view=final",
        "variant group: ao=off, >shadows=on, aa=fxaa, view=final",
        "variants: ao=off, >shadows=off, aa=fxaa, view=final",
        "variant group: ao=off, shadows=off, >aa=fxaa, view=final",
        "variant group: ao=off, shadows=off, aa=fxaa, >view=final",
        "variants: ao=off, shadows=off, aa=fxaa, >view=normals"]
    [refused] = [x for x in lines if x.startswith("refused")]
    assert refused.startswith("refused view=ao:") and "ssao" in refused
    assert max_diff(seen, run_png(tmp_path, SSAO, "ao=off", "shadows=off", "view=normals")) <= 1
    # negative control: the final view (what a stuck V would leave) is told apart
    assert max_diff(seen, run_png(tmp_path, SSAO, "ao=off", "shadows=off")) > 1


def test_h_hides_the_overlay(tmp_path):
    expected = run_png(tmp_path, DEFERRED)
    done = view(tmp_path, DEFERRED, "--frames", "3", "--keys", "h",
                "--screenshot", "hidden.png")
    assert done.returncode == 0, done.stdout + done.stderr
    assert max_diff(np.asarray(Image.open(tmp_path / "hidden.png")).astype(int), expected) <= 1
    # negative control: without H the overlay covers the small window's pixels
    done = view(tmp_path, DEFERRED, "--frames", "3", "--screenshot", "shown.png")
    assert done.returncode == 0, done.stdout + done.stderr
    assert max_diff(np.asarray(Image.open(tmp_path / "shown.png")).astype(int), expected) > 32


MESHLET = str(ROOT / "configs" / "meshlet.toml")
MIXED = str(ROOT / "configs" / "deferred_mixed.toml")


def test_vk_window_shows_the_vk_run_image_and_toggles(tmp_path):
    # meshlet.toml pins its passes to vk: the viewer runs them there (GPU culling and all),
    # under the validation layer; key 1 then turns the shadow pass on
    seen, out = shot(tmp_path, MESHLET, "vk.png", "--frames", "4", "--keys", "1",
                     "--validate")
    graphs = [line for line in out.splitlines() if line.startswith("graph:")]
    assert graphs[0].startswith("graph: cull -> gbuffer -> hiz") and graphs[0].endswith(" on vk")
    assert graphs[1].startswith("graph: shadow -> cull")
    assert "validation: 0 messages" in out.splitlines()
    assert max_diff(seen, run_png(tmp_path, MESHLET, "shadow.enabled=true")) <= 1
    # negative control: the image without the shadow pass is told apart
    assert max_diff(seen, run_png(tmp_path, MESHLET)) > 1


def test_mixed_window_shows_the_mixed_run_image(tmp_path):
    # deferred_mixed.toml pins lighting to vk: wgpu and vk with bridges between them
    expected = run_png(tmp_path, MIXED)
    seen, out = shot(tmp_path, MIXED, "mixed.png", "--frames", "3")
    [graph] = [line for line in out.splitlines() if line.startswith("graph:")]
    assert "bridge." in graph and graph.endswith(" on wgpu+vk")
    assert max_diff(seen, expected) <= 1
    # negative control: a camera step (W) before the first frame is told apart
    moved, _ = shot(tmp_path, MIXED, "moved.png", "--frames", "3", "--keys", "w")
    assert max_diff(moved, expected) > 1


@pytest.mark.parametrize(("args", "env", "names"), [
    (["--backend", "nosuch"], {}, "--backend"),
    (["--validate"], {}, "--validate"),  # deferred.toml runs on wgpu: nothing to validate
    (["--screenshot", "shot.jpg"], {}, "--screenshot"),
    (["--screenshot", "nowhere/shot.png"], {}, "--screenshot"),
    ([], {"RFW_VIEW_FORMAT": "rgba16float"}, "RFW_VIEW_FORMAT"),
    ([], {"RFW_VIEW_FORMAT": "rgba8unorm"}, "RFW_VIEW_FORMAT"),  # not offered by the surface
])
def test_bad_view_input_is_one_line(tmp_path, args, env, names):
    done = view(tmp_path, DEFERRED, "--frames", "2", *args, **env)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error:") and names in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written


def test_good_view_input_control(tmp_path):
    # the negative control of the bad-input cases: the same command with good values runs
    done = view(tmp_path, DEFERRED, "--frames", "2", "--screenshot", "shot.png",
                RFW_VIEW_FORMAT="bgra8unorm")
    assert done.returncode == 0, done.stdout + done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shot.png"]


def test_camera_path_is_said_and_its_first_camera_shown(tmp_path):
    keys = ("camera.path.keys=[{position=[6,3,7],target=[0,1,0]},"
            "{position=[-6,3,7],target=[0,1,0]}]")
    seen, out = shot(tmp_path, DEFERRED, "path.png", "--frames", "3", "--set", keys)
    note = "camera.path is not followed by rfw view: it shows the path's first camera"
    assert out.splitlines().count(note) == 1
    first = run_png(tmp_path, DEFERRED, "camera.position=6,3,7", "camera.target=0,1,0")
    assert max_diff(seen, first) <= 1
    # negative control: the static camera (what the path used to be ignored for) differs
    assert max_diff(seen, run_png(tmp_path, DEFERRED)) > 1
    # and without a path nothing is said
    _, plain = shot(tmp_path, DEFERRED, "plain.png", "--frames", "2")
    assert note not in plain


def test_no_screenshot_of_a_failed_last_frame_is_one_line(tmp_path):
    # a tonemap pass whose shader (in the test's folder) does not compile: every frame fails
    shader = (ROOT / "passes" / "tonemap" / "tonemap.comp.glsl").read_text()
    (tmp_path / "tonemap.comp.glsl").write_text(shader.replace("void main", "oops; void main"))
    (tmp_path / "hot_tonemap.py").write_text(
        "from passes.tonemap.tonemap import TonemapPass\n"
        "from rfw import register_pass\n\n\n"
        "@register_pass('hot_tonemap')\n"
        "class HotTonemapPass(TonemapPass):\n"
        "    '''The tonemap pass with its shader in the test's folder.'''\n")
    config = tmp_path / "hot.toml"
    config.write_text(Path(DEFERRED).read_text().replace(
        'name = "tonemap"', 'name = "tonemap"\nuse = "hot_tonemap"'))

    def view_with_plugin(shot_name: str) -> subprocess.CompletedProcess:
        # the real CLI, with the plugin module imported first (as an entry point would)
        code = ("import sys; sys.path.insert(0, sys.argv.pop(1)); import hot_tonemap; "
                "from rfw.cli import main; sys.exit(main(sys.argv[1:]))")
        return under_xvfb([sys.executable, "-c", code, str(tmp_path), "view", str(config),
                           "--size", SIZE, "--frames", "3", "--no-overlay", "--screenshot",
                           shot_name], env=_env(), cwd=tmp_path)

    done = view_with_plugin("broken.png")
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error:") and "--screenshot" in lines[0]
    assert "no screenshot of the last frame: frame skipped: pass 'tonemap'" in lines[0]
    assert not (tmp_path / "broken.png").exists()
    # negative control: the shader fixed, the same command writes its screenshot
    (tmp_path / "tonemap.comp.glsl").write_text(shader)
    done = view_with_plugin("fixed.png")
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "fixed.png").is_file()
