"""The stress scene: many instances of a few small meshes on a grid.

It measures what grows with the instance count (loading, upload, per-instance data, draw
recording), not shading or triangles: each instance is a cube of 12 triangles, so 100,000
instances are 1.2 million triangles. Everything is computed, never random, so the same
count always gives identical arrays.
"""

from __future__ import annotations

import math

import numpy as np

from .model import Camera, Instance, Light, Material, Mesh, Scene

STRESS_INSTANCES = 100_000
MAX_INSTANCES = 1_000_000  # 12 million triangles: beyond that it is no longer a quick test

# four colours, one mesh each, so draws switch materials as well as meshes
_COLORS = ((0.80, 0.25, 0.20, 1.0), (0.25, 0.65, 0.30, 1.0), (0.20, 0.40, 0.85, 1.0),
           (0.90, 0.80, 0.30, 1.0))
_SPACING = 2.0


def _cube(name: str, material: int) -> Mesh:
    """A unit cube (-0.5..0.5) with flat faces: 24 vertices, 12 triangles."""
    positions, normals, uvs, tangents, indices = [], [], [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = sign  # u along the next axis, flipped with the face
            v = np.cross(n, u)
            base = len(positions)
            for du, dv in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
                positions.append(0.5 * n + du * u + dv * v)
                normals.append(n)
                uvs.append((du + 0.5, 0.5 - dv))
                tangents.append((*u, 1.0))
            indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    return Mesh(name, np.asarray(positions, np.float32), np.asarray(normals, np.float32),
                np.asarray(uvs, np.float32), np.asarray(tangents, np.float32),
                np.asarray(indices, np.uint32), material)


def grid_transforms(count: int) -> np.ndarray:
    """``count`` (4, 4) float32 transforms on a square grid in the xz plane, spaced
    ``_SPACING`` apart and centred on the origin; heights, scales and turns about y vary
    with the index by fixed formulas, so no two neighbours look alike."""
    side = max(1, math.ceil(math.sqrt(count)))
    k = np.arange(count)
    row, col = k // side, k % side
    half = (side - 1) * _SPACING / 2
    scale = 0.6 + 0.3 * ((k * 7) % 5) / 4  # 0.6 .. 0.9
    turn = (k * 37 % 360) * (math.pi / 180)
    c, s = np.cos(turn) * scale, np.sin(turn) * scale
    out = np.zeros((count, 4, 4), np.float32)
    out[:, 0, 0], out[:, 0, 2] = c, s
    out[:, 1, 1] = scale * (1.0 + (k * 13 % 7) / 6)  # 1x .. 2x as tall as wide
    out[:, 2, 0], out[:, 2, 2] = -s, c
    out[:, 0, 3] = col * _SPACING - half
    out[:, 1, 3] = out[:, 1, 1] / 2  # every cube stands on y = 0
    out[:, 2, 3] = row * _SPACING - half
    out[:, 3, 3] = 1.0
    return out


def stress(count: int = STRESS_INSTANCES) -> Scene:
    """A grid of ``count`` cubes in four colours, a sun, and a camera over one corner.

    Parameters
    ----------
    count : int
        Instances, 1 to ``MAX_INSTANCES`` (checked where names enter: ``builtin_scene``).

    Returns
    -------
    Scene
        Named ``stress`` for the default count, ``stress:COUNT`` otherwise.
    """
    meshes = [_cube(f"cube{m}", m) for m in range(len(_COLORS))]
    materials = [Material(f"paint{m}", base_color=c, roughness=0.6)
                 for m, c in enumerate(_COLORS)]
    transforms = grid_transforms(count)
    instances = [Instance(k % len(meshes), transforms[k], f"cube {k}") for k in range(count)]
    side = max(1, math.ceil(math.sqrt(count)))
    half = (side - 1) * _SPACING / 2
    # the camera stands outside one corner and looks along the diagonal, low, so the
    # nearest cubes fill the view and the far ones still cover the horizon
    eye = (-half - 6.0, 5.0, half + 6.0)
    target = (-half + 6.0, 0.5, half - 6.0)
    reach = math.sqrt(2.0) * (2 * half + 12.0) + 10.0
    light = Light("directional", (1.0, 0.95, 0.85), 4.0, direction=(0.4, -0.8, -0.45),
                  name="sun")
    name = "stress" if count == STRESS_INSTANCES else f"stress:{count}"
    return Scene(name=name, meshes=meshes, materials=materials, instances=instances,
                 lights=[light], cameras=[Camera(eye, target, yfov=math.radians(60.0),
                                                 znear=0.1, zfar=reach, name="corner")])
