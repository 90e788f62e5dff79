"""Shared fixtures: one wgpu device per session, and a tiny scene built in code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rfw.scene.model import Camera, Instance, Light, Material, Mesh, Scene

ROOT = Path(__file__).resolve().parents[1]


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
    from rfw.backends.wgpu_backend import Device

    return Device()


@pytest.fixture
def scene() -> Scene:
    return tiny_scene()
