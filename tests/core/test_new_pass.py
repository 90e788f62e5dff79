"""``rfw new-pass`` writes passes that register, compile and pass their own tests."""

import importlib
import os
import subprocess
import sys

import pytest

import rfw.registry as registry
from rfw.cli import main
from rfw.graph import GraphError


@pytest.mark.parametrize("kind", ["--compute", "--raster"])
def test_generated_pass_works(tmp_path, monkeypatch, kind, capsys):
    name = "my_effect" if kind == "--compute" else "my_draw"
    assert main(["new-pass", name, kind, "--dir", str(tmp_path / "plugins")]) == 0
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


def test_bad_names_and_existing_folders(tmp_path):
    from rfw.templates import new_pass

    with pytest.raises(GraphError, match="must be a snake_case identifier"):
        new_pass("My-Pass", tmp_path)
    new_pass("ok", tmp_path)
    with pytest.raises(GraphError, match="already exists"):
        new_pass("ok", tmp_path)
