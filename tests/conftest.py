"""Shared fixtures: one wgpu device per session, a tiny scene built in code, the courtyard and
a cache of renders per session, and the same random and clock state for every test; and
the one way the suite runs the ``rfw`` command line in a subprocess (``rfw_cli``)."""

from __future__ import annotations

import functools
import os
import random
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rfw.scene.model import Camera, Instance, Light, Material, Mesh, Scene

ROOT = Path(__file__).resolve().parents[1]


def tree_env() -> dict[str, str]:
    """The environment for a subprocess that runs this tree's rfw: the tree first on
    PYTHONPATH, then whatever PYTHONPATH made rfw's dependencies importable (the GPU
    machine has them there, not installed)."""
    path = [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(path)}


def rfw_cli(*args: object, cwd: Path | str | None = None,
            env: Mapping[str, str | None] | None = None,
            environ: Mapping[str, str] | None = None, tree: bool = False,
            safe_path: bool = False, timeout: float = 300,
            **run: Any) -> subprocess.CompletedProcess:
    """Run ``python -m rfw.cli ARGS`` to the end: its exit code and text output, never an
    exception for a non-zero exit (the tests judge the code and stderr themselves).

    ``env`` sets variables over this process's environment (None unsets one); ``environ``
    is a whole environment instead of this process's (the CLI corpora build their own).
    ``tree`` puts this tree first on PYTHONPATH, as ``tree_env`` does, for runs from a
    folder where Python would not find it. ``safe_path`` runs ``python -P`` as the console
    script does: the working folder is not on sys.path. A run past ``timeout`` seconds
    fails the test instead of hanging the suite. ``run`` goes to subprocess.run as it is
    (input, errors, preexec_fn)."""
    full = None  # this process's environment, as it is
    if env is not None or environ is not None or tree:
        merged = {**(os.environ if environ is None else environ), **(env or {})}
        full = {k: v for k, v in merged.items() if v is not None}
        if tree:
            path = [str(ROOT), *filter(None, [full.get("PYTHONPATH")])]
            full["PYTHONPATH"] = os.pathsep.join(path)
    python = [sys.executable, *(["-P"] if safe_path else []), "-m", "rfw.cli"]
    return subprocess.run([*python, *map(str, args)], cwd=cwd, env=full, capture_output=True,
                          text=True, timeout=timeout, check=False, **run)


def pytest_configure(config):
    """Share the driver's shader cache (below), and compile this tree's modules once, beside
    their sources, before any test starts rfw in a subprocess: with PYTHONDONTWRITEBYTECODE set (as on the CI machines, and as the fault
    corpus sets it for its children) nothing writes them, so each child compiled some 135
    modules again, half a second of every ``rfw`` it ran. Python still reads them."""
    import compileall

    # lavapipe's shader cache where a run with the default HOME keeps it: the runs that get
    # a HOME and XDG_CACHE_HOME of their own (the corpora, the error boundary) compiled every
    # pipeline again, about 0.8 s of a small deferred run; rfw's own caches stay theirs
    os.environ.setdefault("MESA_SHADER_CACHE_DIR", os.environ.get("XDG_CACHE_HOME")
                          or os.path.expanduser("~/.cache"))
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the controller does it, once
        return
    for folder in ("rfw", "passes", "vkext"):
        compileall.compile_dir(ROOT / folder, quiet=1)


SEED = 20261201
# 2027-01-15 08:00:00 UTC: what time.strftime() without a time says during a test
FIXED_TIME = time.gmtime(1_800_000_000)


def box_mesh(sx: float, sy: float, sz: float, name: str = "box") -> Mesh:
    """An axis-aligned box centred on the origin: 24 vertices, outward normals, face uvs."""
    pos, nor, uv, tan, idx = [], [], [], [], []
    corners = [[0, 0], [1, 0], [1, 1], [0, 1]]
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(n, u)
            c = n * 0.5
            quad = [c - u / 2 - v / 2, c + u / 2 - v / 2, c + u / 2 + v / 2, c - u / 2 + v / 2]
            base = len(pos)
            for k, p in enumerate(quad):
                pos.append(p * [sx, sy, sz])
                nor.append(n)
                tan.append([*u, 1.0])
                uv.append(corners[k])
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return Mesh(name, np.array(pos, np.float32), np.array(nor, np.float32),
                np.array(uv, np.float32), np.array(tan, np.float32), np.array(idx, np.uint32))


def tiny_scene() -> Scene:
    """A floor slab and a red cube, a sun that casts a visible shadow and a blue point light."""
    s = Scene("tiny")
    s.materials = [Material("grey", (0.6, 0.6, 0.6, 1.0), roughness=0.6),
                   Material("red", (0.8, 0.1, 0.1, 1.0), roughness=0.3, metallic=0.2)]
    floor = box_mesh(10, 0.2, 10, "floor")
    cube = box_mesh(1, 1, 1, "cube")
    cube.material = 1
    s.meshes = [floor, cube]
    t_floor = np.identity(4, np.float32)
    t_floor[1, 3] = -0.1
    t_cube = np.identity(4, np.float32)
    t_cube[1, 3] = 0.5
    s.instances = [Instance(0, t_floor, "floor"), Instance(1, t_cube, "cube")]
    s.lights = [Light("directional", (1.0, 0.95, 0.9), 2.0, direction=(0.6, -1.0, 0.4)),
                Light("point", (0.2, 0.5, 1.0), 20.0, position=(2.0, 1.5, 2.0))]
    s.cameras = [Camera((3.0, 2.5, 4.0), (0.0, 0.3, 0.0))]
    return s


@pytest.fixture(scope="session")
def device():
    from rfw.backends.wgpu import Device

    return Device()


@pytest.fixture
def scene() -> Scene:
    return tiny_scene()


@pytest.fixture(autouse=True)
def _seeded_rngs():
    # a test that reaches for the global RNGs sees the same numbers whatever ran before it on
    # its xdist worker (rfw itself only uses seeded generators of its own)
    random.seed(SEED)
    np.random.seed(SEED)


@pytest.fixture(autouse=True)
def _fixed_clock(monkeypatch):
    # the wall clock rfw reads is time.strftime() (rfw.bench.runner stamps its records);
    # durations (time.perf_counter) stay real
    real = time.strftime
    monkeypatch.setattr(time, "strftime",
                        lambda fmt, t=None: real(fmt, FIXED_TIME if t is None else t))


@pytest.fixture(scope="session")
def courtyard():
    """The default scene, built once per session (per xdist worker: about a second each
    time) and shared by every test that draws it: read only. A test that changes a scene
    builds its own (``default_scene()``)."""
    from rfw.scene import default_scene

    return default_scene()


@pytest.fixture(scope="session")
def renders(device, courtyard):
    """``get(cfg, scene)`` -> {output: RGBA8 image} for scene "courtyard" or "tiny"; each
    distinct config (compared by value: a mutated config is another render) renders once."""
    from rfw.render import render, to_png_array

    cache: dict[tuple[str, str], dict[str, np.ndarray]] = {}

    def get(cfg, scene: str) -> dict[str, np.ndarray]:
        key = (repr(cfg), scene)
        if key not in cache:
            result = render(cfg, scene=courtyard if scene == "courtyard" else tiny_scene(),
                            device=device)
            formats = {r.name: r.format for r in result.frame.plan.resources}
            cache[key] = {out: to_png_array(img, formats[out])
                          for out, img in result.images.items()}
        return cache[key]

    return get


@functools.cache
def ray_method() -> str:
    """The ray-tracing method of this machine's Vulkan device: ``ray_query`` where it has
    VK_KHR_ray_query (lavapipe), else ``ray_pipeline`` (NVIDIA's Hopper chips have
    pipelines only); the tests that judge traced passes run on whichever there is."""
    from vkext import VkDevice

    device = VkDevice(label="rfw-tests:caps")
    try:
        return "ray_query" if "VK_KHR_ray_query" in device.caps else "ray_pipeline"
    finally:
        device.destroy()
