"""Pass discovery: built-ins by folder, third-party passes through the entry-point group."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

import rfw.registry as registry
from rfw import get_pass
from rfw.graph import GraphError
from rfw.shaders import program_files
from rfw.testing import run_pass

from ..conftest import ROOT

BUILTIN = {"deferred_lighting", "forward", "gbuffer", "shadow_map", "tonemap"}


def test_builtins_are_found_by_folder():
    assert set(registry.available()) >= BUILTIN
    for pass_id in BUILTIN:
        cls = get_pass(pass_id)
        assert cls.id == pass_id and cls.describe(), pass_id
        assert all(p.is_file() for p in program_files(cls.folder(), cls.shader)), pass_id


def test_unknown_pass_suggests():
    with pytest.raises(GraphError, match=r"unknown pass 'tonemapp' \(did you mean 'tonemap'"):
        get_pass("tonemapp")


def test_third_party_pass_installed_as_a_package(tmp_path, monkeypatch, device):
    # a real install of tests/data/plugin_demo into a private folder, then discovery
    # build from a copy: an in-tree build would leave build/ in the repository
    source = tmp_path / "plugin_demo"
    shutil.copytree(ROOT / "tests" / "data" / "plugin_demo", source)
    target = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--no-build-isolation", "--target", str(target), str(source)],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    monkeypatch.syspath_prepend(str(target))
    registry.reload()
    try:
        cls = get_pass("invert")
        assert cls.__module__ == "rfw_plugin_demo.invert"
        img = np.full((2, 3, 4), 200, np.uint8)
        out = run_pass(cls, {"src": ("rgba8unorm", img)}, device=device)["dst"]
        assert np.all(out == 55)
    finally:
        registry._REGISTRY.pop("invert", None)
        sys.modules.pop("rfw_plugin_demo.invert", None)
        sys.modules.pop("rfw_plugin_demo", None)
