"""Small analytic scenes for the pass tests: quads, boxes, a wall, a corner."""

from __future__ import annotations

import functools

import numpy as np

from rfw.scene.model import Camera, Instance, Light, Material, Mesh, Scene


def quad(width: float, height: float) -> Mesh:
    """A quad in the xy plane, centred on the origin, facing +z (counter-clockwise)."""
    w, h = width / 2, height / 2
    pos = np.array([[-w, -h, 0], [w, -h, 0], [w, h, 0], [-w, h, 0]], np.float32)
    nor = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    tan = np.tile(np.array([1, 0, 0, 1], np.float32), (4, 1))
    return Mesh("quad", pos, nor, uv, tan, np.array([0, 1, 2, 0, 2, 3], np.uint32))


def box(sx: float, sy: float, sz: float) -> Mesh:
    """An axis-aligned box centred on the origin: 24 vertices, outward normals."""
    pos, nor, uv, tan, idx = [], [], [], [], []
    for axis in range(3):
        for sign in (-1, 1):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1
            v = np.cross(n, u)
            corners = [n / 2 - u / 2 - v / 2, n / 2 + u / 2 - v / 2, n / 2 + u / 2 + v / 2,
                       n / 2 - u / 2 + v / 2]
            base = len(pos)
            for k, p in enumerate(corners):
                pos.append(p * [sx, sy, sz])
                nor.append(n)
                tan.append([*u, 1.0])
                uv.append([[0, 0], [1, 0], [1, 1], [0, 1]][k])
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return Mesh("box", np.array(pos, np.float32), np.array(nor, np.float32),
                np.array(uv, np.float32), np.array(tan, np.float32), np.array(idx, np.uint32))


def translate(x: float, y: float, z: float) -> np.ndarray:
    m = np.identity(4, np.float32)
    m[:3, 3] = (x, y, z)
    return m


def rotate_x(degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    m = np.identity(4, np.float32)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    return m


def scene(name: str, parts: list[tuple[Mesh, np.ndarray]], camera: Camera,
          lights: list[Light] | None = None) -> Scene:
    """One mesh and one instance per part, all with one grey material."""
    s = Scene(name, materials=[Material("grey", (0.8, 0.8, 0.8, 1.0), roughness=0.6)])
    for k, (mesh, transform) in enumerate(parts):
        s.meshes.append(mesh)
        s.instances.append(Instance(k, np.asarray(transform, np.float32)))
    s.lights = lights or []
    s.cameras = [camera]
    return s


def wall_scene() -> Scene:
    """A plane filling the view, square to the camera's axis."""
    return scene("wall", [(quad(40, 40), np.identity(4))],
                 Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), znear=0.1, zfar=50.0))


def corner_scene() -> Scene:
    """A floor (y = 0) meeting a wall (z = 0): a concave crease along the x axis."""
    floor = rotate_x(-90.0) @ translate(0, -20, 0)  # normal +z turned to +y, z in 0..40
    return scene("corner", [(quad(40, 40), floor), (quad(40, 40), translate(0, 20, 0))],
                 Camera((0.0, 1.5, 3.0), (0.0, 0.3, 0.0), znear=0.1, zfar=50.0))


def tiny_scene() -> Scene:
    """A red cube on a grey slab, a sun and a point light."""
    s = Scene("tiny", materials=[Material("grey", (0.8, 0.8, 0.8, 1), roughness=0.6),
                                 Material("red", (0.9, 0.1, 0.1, 1), roughness=0.3)])
    slab, cube = box(10, 0.2, 10), box(1, 1, 1)
    cube.material = 1
    s.meshes = [slab, cube]
    s.instances = [Instance(0, translate(0, -0.1, 0)), Instance(1, translate(0, 0.5, 0))]
    s.lights = [Light("directional", (1, 0.95, 0.9), 2.0, direction=(0.6, -1.0, 0.4)),
                Light("point", (0.2, 0.5, 1.0), 20.0, position=(2, 1.5, 2))]
    s.cameras = [Camera((3, 2.5, 4), (0, 0.3, 0))]
    return s


# a still surface's motion: last frame's clip position and this frame's are the same product,
# which a GPU's compiler may round apart (NVIDIA H200: 2e-6 px), far below any motion that
# counts (the tests' moves are pixels)
STILL_PX = 1e-4


def still(velocity) -> bool:
    """No motion in ``velocity`` (pixels) beyond :data:`STILL_PX`; True for no pixels."""
    return bool(np.abs(np.asarray(velocity, np.float32)).max(initial=0.0) <= STILL_PX)


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
