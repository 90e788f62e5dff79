"""``rfw new-pass NAME --package DIR``: an installable distribution, installed for real into a
private folder (no build isolation, no registry), found through its ``rfw.passes`` entry
point, listed by ``rfw passes`` and rendered by ``rfw run``, all in subprocesses."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ..conftest import rfw_cli
from ..golden_util import read_png

ROOT = Path(__file__).resolve().parents[2]

CONFIG = """name = "glow"
scene = "default"
size = [32, 18]
outputs = ["tonemap.ldr"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "fx"
use = "my_glow"
inputs = { src = "gbuffer.albedo" }
settings = { gain = 2.0 }

[[pass]]
name = "tonemap"
inputs = { hdr = "fx.dst" }
"""


def env(*front):
    # the GPU machine makes rfw importable through PYTHONPATH: keep it, behind our folders
    path = [*map(str, front), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(path)}


def rfw(*args, cwd, site=None):
    return rfw_cli(*args, cwd=cwd, environ=env(*([site] if site else [])))


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The generated package and the private folder it was pip-installed into, with the
    command ``new-pass`` printed (kept off the index and out of the environment)."""
    tmp = tmp_path_factory.mktemp("pkg")
    pkg = tmp / "my-glow"
    done = rfw("new-pass", "my_glow", "--package", "my-glow", cwd=tmp)
    assert done.returncode == 0, done.stderr
    [said] = [x for x in done.stdout.splitlines() if x.startswith("install it with: ")]
    command = said.removeprefix("install it with: ").split()
    assert command == ["pip", "install", "--no-build-isolation", "./my-glow"]
    site = tmp / "site"
    private = ["--quiet", "--no-deps", "--no-index", "--target", str(site)]
    done = subprocess.run([sys.executable, "-m", *command, *private], capture_output=True,
                          text=True, check=False, cwd=tmp)
    assert done.returncode == 0, done.stderr
    # negative control: the bare name (what it used to print) is a package name to pip
    bare = subprocess.run([sys.executable, "-m", *command[:-1], "my-glow", *private,
                           "--dry-run"], capture_output=True, text=True, check=False, cwd=tmp)
    assert bare.returncode != 0 and "No matching distribution found for my-glow" in bare.stderr
    return pkg, site


def test_package_layout_and_install(installed):
    pkg, site = installed
    assert {p.relative_to(pkg).as_posix() for p in pkg.rglob("*") if p.is_file()
            and "build" not in p.relative_to(pkg).parts and ".egg-info" not in str(p)} == {
        "pyproject.toml", "README.md", "rfw_my_glow/__init__.py", "rfw_my_glow/my_glow.py",
        "rfw_my_glow/my_glow.comp.glsl", "tests/test_my_glow.py"}
    # the shader went in as package data, the entry point into the metadata
    assert (site / "rfw_my_glow" / "my_glow.comp.glsl").is_file()
    eps = list(site.glob("rfw_my_glow-*.dist-info/entry_points.txt"))
    assert len(eps) == 1
    assert re.search(r"\[rfw\.passes\]\s*my_glow = rfw_my_glow\.my_glow", eps[0].read_text())


def test_installed_pass_is_listed(installed, tmp_path):
    _, site = installed
    done = rfw("passes", "my_glow", cwd=tmp_path, site=site)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "my_glow  (compute; rfw_my_glow.my_glow)",
        "    Scales the color of ``src`` by ``gain``: replace with your technique.",
        "    in  src (texture any): input color",
        "    out dst (texture format of src, like src): output color",
        "    set gain: float = 1.0 in 0..16"]
    # negative control: not installed, not found (one line, a suggestion-free error)
    done = rfw("passes", "my_glow", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr == "rfw: error: passes: unknown pass 'my_glow'\n"


def test_installed_pass_renders_through_rfw_run(installed, tmp_path):
    _, site = installed
    config = tmp_path / "glow.toml"
    config.write_text(CONFIG)
    images = {}
    for gain in ("2.0", "0.5"):
        out = tmp_path / f"out{gain}"
        done = rfw("run", config, "--backend", "wgpu", "--frames", "1", "--set",
                   f"fx.gain={gain}", "--out", out, cwd=tmp_path, site=site)
        assert done.returncode == 0, done.stdout + done.stderr
        images[gain] = read_png(out / "tonemap.ldr.png").astype(np.float32)
    # the plugin's own setting reaches its shader: more gain, a brighter image
    assert images["2.0"][..., :3].mean() > images["0.5"][..., :3].mean() + 10
    # negative control: the same run without the install fails on the pass, in one line
    out = tmp_path / "missing"
    done = rfw("run", config, "--backend", "wgpu", "--frames", "1", "--out", out,
               cwd=tmp_path)
    assert done.returncode == 2
    assert len(done.stderr.splitlines()) == 1 and "unknown pass 'my_glow'" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (out / "tonemap.ldr.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["glow.toml", "out0.5", "out2.0"]


def test_generated_test_passes_against_the_install(installed, tmp_path):
    pkg, site = installed
    # run from elsewhere: the package is imported from the install, not the source tree
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           str(pkg / "tests")], cwd=tmp_path, capture_output=True, text=True,
                          check=False, env=env(site))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 passed" in done.stdout


def test_package_refuses_a_used_folder_and_bad_names(tmp_path):
    used = tmp_path / "used"
    used.mkdir()
    (used / "keep.txt").write_text("mine")
    done = rfw("new-pass", "my_glow", "--package", used, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr == (f"rfw: error: {used}: --package: already exists and is not an "
                           "empty folder: not overwritten\n")
    assert [p.name for p in used.iterdir()] == ["keep.txt"]
    done = rfw("new-pass", "My-Glow", "--package", tmp_path / "new", cwd=tmp_path)
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1
    assert "must be a snake_case identifier" in done.stderr
    assert not (tmp_path / "new").exists()
    done = rfw("new-pass", "my_glow", "--package", tmp_path / "new", "--tests", "t",
               cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr == "rfw: error: new-pass: --tests does not go with --package (its " \
                          "test is in DIR/tests)\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["used"]


def _one_line(done, expected):
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stdout == "" and "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("rfw: error: ")
    assert expected in done.stderr, done.stderr


@pytest.mark.parametrize("name", ["flat", "tonemap"])
def test_registered_ids_are_refused(tmp_path, name):
    # a second class under a built-in id would break every later rfw command
    taken = f"rfw: error: new-pass: pass id '{name}' is already registered (built-in or " \
            "installed): choose another name\n"
    done = rfw("new-pass", name, "--package", tmp_path / "pkg", cwd=tmp_path)
    _one_line(done, taken)
    done = rfw("new-pass", name, "--dir", "p", cwd=tmp_path)
    _one_line(done, taken)
    done = rfw("new-pass", name, cwd=tmp_path)  # the default --dir: ./passes
    _one_line(done, taken)
    assert list(tmp_path.iterdir()) == []
    # negative control: a free id is written, with and without --package
    assert rfw("new-pass", f"{name}_mine", "--dir", "p", cwd=tmp_path).returncode == 0
    assert rfw("new-pass", f"{name}_mine", "--package", "pkg", cwd=tmp_path).returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p", "pkg"]


def test_an_installed_plugin_id_is_refused(installed, tmp_path):
    _, site = installed
    done = rfw("new-pass", "my_glow", "--package", "again", cwd=tmp_path, site=site)
    _one_line(done, "new-pass: pass id 'my_glow' is already registered")
    done = rfw("new-pass", "my_glow", cwd=tmp_path, site=site)
    _one_line(done, "new-pass: pass id 'my_glow' is already registered")
    assert list(tmp_path.iterdir()) == []
    # negative control: where it is not installed, the same id is free
    assert rfw("new-pass", "my_glow", "--package", "again", cwd=tmp_path).returncode == 0
    assert (tmp_path / "again" / "pyproject.toml").is_file()


@pytest.mark.parametrize("package", ["", "  "])
def test_empty_package_is_one_line_not_passes(tmp_path, package):
    done = rfw("new-pass", "my_glow", "--package", package, cwd=tmp_path)
    _one_line(done, "rfw: error: new-pass --package: expected a folder, not an empty name")
    assert list(tmp_path.iterdir()) == []  # no ./passes/my_glow
