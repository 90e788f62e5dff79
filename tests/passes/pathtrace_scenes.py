"""Scenes with closed-form radiance for the path tracer's tests, and the radiance itself."""

from __future__ import annotations

import numpy as np

from rfw.scene.model import Camera, Instance, Light, Material, Mesh, Scene

SKY = np.array([0.03, 0.035, 0.045])  # rfw.backends.scene_data's ambient: the sky's radiance


def sphere(rings: int = 48) -> Mesh:
    """A unit sphere at the origin, smooth normals (rings x 2 rings quads)."""
    th, ph = np.meshgrid(np.linspace(0, np.pi, rings + 1), np.linspace(0, 2 * np.pi, 2 * rings + 1),
                         indexing="ij")
    p = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    w = 2 * rings + 1
    quads = [(i * w + j, i * w + j + 1, (i + 1) * w + j, (i + 1) * w + j + 1)
             for i in range(rings) for j in range(2 * rings)]
    idx = np.array([[a, b, c, b, d, c] for a, b, c, d in quads], np.uint32).reshape(-1)
    uv = np.zeros((len(p), 2), np.float32)
    tan = np.tile(np.array([1, 0, 0, 1], np.float32), (len(p), 1))
    return Mesh("sphere", p.astype(np.float32), p.astype(np.float32), uv, tan, idx)


def sphere_scene(material: Material, lights: list[Light] | None = None) -> Scene:
    """One unit sphere seen from (0, 0, 3); no light but the sky (a dark sun stands in for
    the default one a scene without lights gets)."""
    return Scene("sphere", meshes=[sphere()], materials=[material],
                 instances=[Instance(0, np.identity(4, np.float32))],
                 lights=lights or [Light("directional", (1, 1, 1), 0.0)],
                 cameras=[Camera((0, 0, 3), (0, 0, 0), yfov=np.radians(45))])


def sphere_cosines(size: int) -> np.ndarray:
    """n.v at the point each pixel centre of ``sphere_scene``'s camera sees (nan: the sky)."""
    cam = Camera((0, 0, 3), (0, 0, 0), yfov=np.radians(45))
    inv = np.linalg.inv(cam.projection(1.0).astype(np.float64) @ cam.view())
    c = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(c, -c)
    far = np.stack([x, y, np.ones_like(x), np.ones_like(x)], -1) @ inv.T
    d = far[..., :3] / far[..., 3:] - np.array([0, 0, 3.0])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0, 0, 3.0])
    b = d @ o
    disc = b * b - (o @ o - 1)
    t = -b - np.sqrt(np.where(disc > 0, disc, np.nan))
    n = o + t[..., None] * d
    return np.einsum("...i,...i", n, -d)


def directional_albedo(nov: np.ndarray, base: float, metallic: float, roughness: float,
                       specular: float = 1.0, steps: int = 256) -> np.ndarray:
    """The integral of pbr.glsl's BRDF times n.l over the hemisphere (with the specular
    factor of KHR_materials_specular), for view cosines ``nov``: what a convex object of
    the material reflects of a uniform sky of radiance 1. Midpoint rule in (cos theta, phi)
    at 65 view cosines, interpolated linearly between them."""
    table = np.linspace(0.0, 1.0, 65)
    table[0] = 1e-3
    return np.interp(nov, table, _albedo(table, base, metallic, roughness, specular, steps))


def _albedo(nov: np.ndarray, base: float, metallic: float, roughness: float,
            specular: float, steps: int) -> np.ndarray:
    a = roughness * roughness
    mu = (np.arange(steps) + 0.5) / steps
    phi = (np.arange(2 * steps) + 0.5) / (2 * steps) * 2 * np.pi
    mu_l, ph = np.meshgrid(mu, phi, indexing="ij")
    sin_l = np.sqrt(1 - mu_l ** 2)
    out = []
    for c in np.atleast_1d(nov):
        v = np.array([np.sqrt(1 - c * c), 0.0, c])
        lx, ly, lz = sin_l * np.cos(ph), sin_l * np.sin(ph), mu_l
        hx, hy, hz = lx + v[0], ly, lz + v[2]
        hn = np.sqrt(hx * hx + hy * hy + hz * hz)
        noh, voh = hz / hn, (hx * v[0] + hz * v[2]) / hn
        d = a * a / (np.pi * (noh * noh * (a * a - 1) + 1) ** 2)
        gv = lz * np.sqrt(c * c * (1 - a * a) + a * a)
        gl = c * np.sqrt(lz * lz * (1 - a * a) + a * a)
        vis = 0.5 / np.maximum(gv + gl, 1e-5)
        schlick = (1 - voh) ** 5
        f = (1 - metallic) * specular * (0.04 + 0.96 * schlick) + metallic * (base + (1 - base) * schlick)
        diffuse = (1 - metallic) * (1 - f) * base / np.pi
        integrand = (d * vis * f + diffuse) * lz
        out.append(integrand.mean() * 2 * np.pi)  # d(omega) = d(mu) d(phi)
    return np.array(out)
