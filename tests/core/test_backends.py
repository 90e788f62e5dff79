"""Backends and passes are plug-ins: the ``rfw.backends`` and ``rfw.passes`` entry-point
groups, ``rfw run --backend NAME``, a third-party backend installed as a package, and every
built-in pass listed in rfw's pyproject.toml."""

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rfw.backend as backend
import rfw.plugins as plugins
from rfw.errors import RfwError

from ..cli.warm import warm_cli
from ..conftest import ROOT

CONFIG = ROOT / "configs" / "deferred.toml"


def test_builtin_backends_are_installed():
    assert backend.installed()[:2] == ["wgpu", "vk"]
    for name in ("wgpu", "vk"):
        b = backend.get_backend(name)
        assert b.name == name and all(hasattr(b, m) for m in backend.MEMBERS)
    with pytest.raises(RfwError, match=r"unknown backend 'vkk' \(did you mean 'vk'\?\); "
                                       r"installed: wgpu, vk"):
        backend.get_backend("vkk")


def test_unknown_backend_on_the_command_line_is_one_line(tmp_path):
    done = warm_cli("run", CONFIG, "--backend", "metal", "--out", tmp_path / "out", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == "rfw: error: --backend: unknown backend 'metal'; " \
                                  "installed: wgpu, vk"
    assert not (tmp_path / "out" / "timings.json").exists()


@pytest.fixture(scope="module")
def demo_site(tmp_path_factory):
    """tests/data/backend_demo installed for real into a private folder (built from a copy:
    an in-tree build would leave build/ in the repository)."""
    tmp = tmp_path_factory.mktemp("backend_demo")
    source = tmp / "backend_demo"
    shutil.copytree(ROOT / "tests" / "data" / "backend_demo", source)
    site = tmp / "site"
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--no-build-isolation", "--target", str(site), str(source)],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return site


def _with_demo(site):
    path = os.pathsep.join(filter(None, [str(site), str(ROOT), os.environ.get("PYTHONPATH")]))
    return {"PYTHONPATH": path}


def test_third_party_backend_runs_through_the_cli(demo_site, tmp_path):
    log = tmp_path / "calls.log"
    env = {**_with_demo(demo_site), "RFW_BACKEND_DEMO_LOG": str(log)}
    out = tmp_path / "out"
    done = warm_cli("run", CONFIG, "--backend", "paint", "--size", "40x24", "--frames", "3",
                    "--out", out, cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr
    timings = json.loads((out / "timings.json").read_text())
    assert (timings["backend"], timings["device"], timings["frames"]) == ("paint", "canvas", 3)
    # rfw's driver recorded the painter's timings for every pass of the plan
    assert [p["name"] for p in timings["passes"]] == ["gbuffer", "lighting", "tonemap"]
    assert all(p["gpu_ms"] == 1.0 and p["cpu_ms"] == 0.5 for p in timings["passes"])
    image = np.asarray(Image.open(out / "tonemap.ldr.png"))
    assert image.shape == (24, 40, 4)
    assert np.all(image == zlib.crc32(b"tonemap") % 256)
    # one device made and destroyed, after the executor and the scene
    assert log.read_text().split() == ["make_device", "fit", "executor", "executor.destroy",
                                       "scene.destroy", "destroy_device"]
    # the same run under the installed name of another backend lists the painter too
    done = warm_cli("run", CONFIG, "--backend", "pain", "--out", out, cwd=tmp_path, env=env)
    assert done.returncode == 2
    assert "(did you mean 'paint'?); installed: wgpu, vk, broken, paint" in done.stderr


def test_a_backend_missing_members_is_one_line(demo_site, tmp_path):
    done = warm_cli("run", CONFIG, "--backend", "broken", "--out", tmp_path / "out", cwd=tmp_path,
                    env=_with_demo(demo_site))
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("rfw: error: --backend: backend 'broken' "
                           "(rfw_backend_demo:Broken) lacks make_device, describe, caps, fit")


def test_third_party_backend_in_process(demo_site, monkeypatch):
    from rfw.config import apply_overrides, load_config
    from rfw.render import render

    monkeypatch.syspath_prepend(str(demo_site))
    backend.reload()
    try:
        cfg = apply_overrides(load_config(CONFIG), ["size=20x12"])
        result = render(cfg, backend="paint", frames=2)
        assert result.timings["backend"] == "paint"
        assert type(result.executor).__name__ == "PaintExecutor"
        assert result.images["tonemap.ldr"].shape == (12, 20, 4)
    finally:
        backend.reload()
        for name in [m for m in sys.modules if m.startswith("rfw_backend_demo")]:
            del sys.modules[name]


def test_a_run_on_another_backend_never_loads_vulkan(demo_site, tmp_path):
    # the driver loads the backends a run names, nothing else: vkext (and the vulkan
    # bindings) stay out of a frame that does not use them
    code = ("import sys; from rfw.config import apply_overrides, load_config; "
            "from rfw.render import render; "
            f"cfg = apply_overrides(load_config({str(CONFIG)!r}), ['size=20x12']); "
            "r = render(cfg, backend=sys.argv[1]); "
            "print(r.timings['backend'], 'vkext' in sys.modules, 'vulkan' in sys.modules)")
    for name, loaded in (("paint", "False False"), ("vk", "True True")):  # vk: the control
        done = subprocess.run([sys.executable, "-c", code, name], cwd=tmp_path,
                              capture_output=True, text=True, check=False,
                              env={**os.environ, **_with_demo(demo_site)})
        assert done.returncode == 0, done.stderr
        assert done.stdout.split() == [name, *loaded.split()]


# ---------------------------------------------------------------------------------------------
# built-in passes: listed in pyproject.toml, found through the rfw.passes entry points


def pass_folders(root: Path) -> set[str]:
    """Folders of ``root`` holding a module of their own name: the passes."""
    return {p.name for p in root.iterdir() if (p / f"{p.name}.py").is_file()}


def unlisted(root: Path, listed: dict[str, str]) -> list[str]:
    """Pass folders of ``root`` that no entry point names as ``passes.<id>.<id>``."""
    modules = set(listed.values())
    return sorted(n for n in pass_folders(root) if f"passes.{n}.{n}" not in modules)


def _pyproject_passes() -> dict[str, str]:
    with (ROOT / "pyproject.toml").open("rb") as f:
        return tomllib.load(f)["project"]["entry-points"]["rfw.passes"]


def test_every_pass_folder_is_listed_in_pyproject():
    listed = _pyproject_passes()
    assert len(pass_folders(ROOT / "passes")) >= 16
    assert unlisted(ROOT / "passes", listed) == [], "add them to pyproject.toml's rfw.passes"
    # and installed: an editable install made before the list grew would miss them (a tree
    # run uninstalled reads pyproject.toml itself)
    installed = {ep.name: ep.value for ep in plugins.entry_points("rfw.passes")}
    assert unlisted(ROOT / "passes", installed) == [], "pip install -e . again"


def test_an_unlisted_pass_folder_is_found(tmp_path):
    # the negative control: a new pass folder, and a folder that holds no pass
    shutil.copytree(ROOT / "passes" / "tonemap", tmp_path / "tonemap")
    shutil.copytree(ROOT / "passes" / "tonemap", tmp_path / "my_effect")
    (tmp_path / "my_effect" / "tonemap.py").rename(tmp_path / "my_effect" / "my_effect.py")
    (tmp_path / "notes").mkdir()
    assert unlisted(tmp_path, _pyproject_passes()) == ["my_effect"]


def test_builtins_register_through_the_entry_points():
    import rfw.registry as registry

    found = registry.available()
    for name, value in _pyproject_passes().items():
        assert any(cls.__module__ == value for cls in found.values()), name


def test_a_source_tree_reads_the_groups_from_pyproject(monkeypatch):
    # rfw run from a tree that was never installed (PYTHONPATH=. on the GPU machine): no
    # metadata for rfw, so the groups come from its pyproject.toml
    monkeypatch.setattr(plugins, "_installed", lambda: False)
    monkeypatch.setattr(plugins.importlib.metadata, "entry_points", lambda group: [])
    eps = plugins.entry_points("rfw.backends")
    assert {ep.name: ep.value for ep in eps} == {"wgpu": "rfw.backends.wgpu.backend:WgpuBackend",
                                               "vk": "vkext.backend:VkBackend"}
    assert {ep.name: ep.value for ep in plugins.entry_points("rfw.passes")} == \
        _pyproject_passes()
    # installed rfw: only what is installed (here, nothing)
    monkeypatch.setattr(plugins, "_installed", lambda: True)
    assert plugins.entry_points("rfw.backends") == []
