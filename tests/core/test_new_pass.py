"""``rfw new-pass`` writes GLSL passes that register, compile, pass their own tests and
render the same image on both backends."""

import importlib
import os
import subprocess
import sys

import numpy as np
import pytest

import rfw.registry as registry
from rfw.cli import main
from rfw.graph import GraphError

from ..golden_util import read_png

# the generated pass in a frame: after the G-buffer's albedo (compute) or alone (raster),
# then tonemapped; gain 2 so a pass that ignored its settings shows
CONFIGS = {"--compute": """name = "new_compute"
scene = "default"
size = [64, 36]
outputs = ["tonemap.ldr"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "fx"
use = "my_effect"
inputs = { src = "gbuffer.albedo" }
settings = { gain = 2.0 }

[[pass]]
name = "tonemap"
inputs = { hdr = "fx.dst" }
""", "--raster": """name = "new_raster"
scene = "default"
size = [64, 36]
outputs = ["tonemap.ldr"]

[[pass]]
name = "draw"
use = "my_draw"
settings = { gain = 2.0 }

[[pass]]
name = "tonemap"
inputs = { hdr = "draw.color" }
"""}

# the real CLI, with the generated plugin imported first (it is not installed)
RUN = """import sys
sys.path.insert(0, sys.argv.pop(1))
__import__(sys.argv.pop(1))
from rfw.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("kind", ["--compute", "--raster"])
def test_generated_pass_works(tmp_path, monkeypatch, kind, capsys):
    name = "my_effect" if kind == "--compute" else "my_draw"
    assert main(["new-pass", name, kind, "--dir", str(tmp_path / "plugins")]) == 0
    # the last line says how configs will find it (a folder alone is no plugin)
    said = capsys.readouterr().out.splitlines()
    assert said[-1].startswith("next: ") and "'rfw.passes' entry point" in said[-1]
    assert f"'rfw new-pass {name} --package DIR'" in said[-1]
    assert all(x.startswith("wrote ") for x in said[:-1])
    folder = tmp_path / "plugins" / name
    assert {p.name for p in folder.iterdir()} >= {"__init__.py", f"{name}.py",
                                                 f"test_{name}.py"}
    # the generated test runs as a user would run it; the plugin folder goes in front of
    # the PYTHONPATH that may be what makes rfw importable (no install on the GPU machine)
    path = [str(tmp_path / "plugins"), *filter(None, [os.environ.get("PYTHONPATH")])]
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           str(folder / f"test_{name}.py")], cwd=tmp_path / "plugins",
                          capture_output=True, text=True, check=False,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(path)})
    assert done.returncode == 0, done.stdout + done.stderr
    monkeypatch.syspath_prepend(str(tmp_path / "plugins"))
    try:
        module = importlib.import_module(f"{name}.{name}")
        assert registry.get_pass(name).__module__ == module.__name__
    finally:
        registry._REGISTRY.pop(name, None)


@pytest.mark.parametrize("kind", ["--compute", "--raster"])
def test_generated_pass_renders_the_same_on_both_backends(tmp_path, kind):
    name = "my_effect" if kind == "--compute" else "my_draw"
    plugins = tmp_path / "plugins"
    assert main(["new-pass", name, kind, "--dir", str(plugins)]) == 0
    assert {p.suffix for p in (plugins / name).iterdir()} >= {".glsl"}
    assert not list((plugins / name).glob("*.wgsl"))
    config = tmp_path / "new.toml"
    config.write_text(CONFIGS[kind])
    images = {}
    for backend in ("wgpu", "vk"):
        out = tmp_path / backend
        done = subprocess.run([sys.executable, "-c", RUN, str(plugins), f"{name}.{name}", "run",
                               str(config), "--backend", backend, "--frames", "1", "--out",
                               str(out)], capture_output=True, text=True, check=False)
        assert done.returncode == 0, f"{backend}: {done.stdout}{done.stderr}"
        images[backend] = read_png(out / "tonemap.ldr.png")
    # one SPIR-V on both: the same image, and not an empty one
    assert np.array_equal(images["wgpu"], images["vk"])
    assert len(np.unique(images["vk"].reshape(-1, 4), axis=0)) > 4


def test_bad_names_and_existing_folders(tmp_path):
    from rfw.templates import new_pass

    with pytest.raises(GraphError, match="must be a snake_case identifier"):
        new_pass("My-Pass", tmp_path)
    new_pass("ok", tmp_path)
    with pytest.raises(GraphError, match="already exists"):
        new_pass("ok", tmp_path)
