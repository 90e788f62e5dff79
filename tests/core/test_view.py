"""``rfw view`` in a real window under Xvfb: frames render, keys toggle passes, timings print."""

import os
import shutil
import subprocess
import sys

import pytest

from ..conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("xvfb-run") is None,
                                reason="needs xvfb-run (scripts/setup-system.sh installs it)")


def test_view_window_under_xvfb(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 1 0\n"
                   "f 1 3 2\nf 1 4 3\nf 1 2 5\nf 2 3 5\n")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "rfw.cli",
         "view", str(ROOT / "configs" / "deferred.toml"), "--scene", str(obj),
         # P after two frames of the new graph (its first, which compiles, is a warm-up
         # whose times are dropped); H twice: frames pass
         "--size", "96x64", "--frames", "7", "--keys", "1,h,h,p,1"],
        capture_output=True, text=True, timeout=180, env=env, check=False)
    out = done.stdout
    assert done.returncode == 0, done.stdout + done.stderr
    graphs = [line for line in out.splitlines() if line.startswith("graph:")]
    # start without the shadow pass, key 1 switches it on, the second 1 off again
    assert graphs == ["graph: gbuffer -> lighting -> tonemap (off: shadow)",
                      "graph: shadow -> gbuffer -> lighting -> tonemap",
                      "graph: gbuffer -> lighting -> tonemap (off: shadow)"]
    assert any(line.startswith("frame ") and "gbuffer" in line for line in out.splitlines())
    assert "closed after 7 frames" in out
    assert "Traceback" not in done.stderr and "Validation Error" not in done.stderr
