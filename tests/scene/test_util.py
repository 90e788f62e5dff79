"""Normals and tangents: analytic cases."""

from __future__ import annotations

import numpy as np

from rfw.scene.util import any_tangent, compute_normals, compute_tangents


def test_normals_are_area_weighted():
    # a vertex shared by a big triangle facing +z and a small one facing +x
    p = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 1, 0], [0, 0, 1]], float)
    idx = np.array([0, 1, 2, 0, 3, 4])
    n = compute_normals(p, idx)
    big, small = 16 / 2, 1 / 2
    expected = np.array([small, 0, big]) / np.hypot(small, big)
    np.testing.assert_allclose(n[0], expected, atol=1e-6)
    np.testing.assert_allclose(n[1], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(n[4], [1, 0, 0], atol=1e-6)


def test_unused_and_degenerate_vertices_get_a_unit_normal():
    p = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 5, 5]], float)
    n = compute_normals(p, np.array([0, 1, 2]))
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1)


def test_tangent_follows_u_on_a_rotated_quad():
    # a quad in the xz plane facing +y; u runs along -z, v (down the image) along -x
    p = np.array([[0, 0, 0], [0, 0, -1], [-1, 0, -1], [-1, 0, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    idx = np.array([0, 1, 2, 0, 2, 3])
    n = compute_normals(p, idx)
    np.testing.assert_allclose(n, np.tile([0, 1, 0], (4, 1)), atol=1e-6)
    t = compute_tangents(p, n, uv, idx)
    np.testing.assert_allclose(t[:, :3], np.tile([0, 0, -1], (4, 1)), atol=1e-6)
    # bitangent = cross(n, t) * w must point up the image, i.e. along -dP/dv = +x
    b = np.cross(n, t[:, :3]) * t[:, 3:]
    np.testing.assert_allclose(b, np.tile([1, 0, 0], (4, 1)), atol=1e-6)


def test_tangents_on_a_sphere_are_orthonormal_to_normals():
    theta, phi = np.meshgrid(np.linspace(0.1, 3.0, 12), np.linspace(0, 2 * np.pi, 25))
    p = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta), np.sin(theta) * np.sin(phi)],
                 -1).reshape(-1, 3)
    uv = np.stack([phi / (2 * np.pi), theta / np.pi], -1).reshape(-1, 2)
    rows, cols = 25, 12
    i, j = np.meshgrid(np.arange(cols - 1), np.arange(rows - 1))
    a = (j * cols + i).ravel()
    idx = np.stack([a, a + 1, a + cols + 1, a, a + cols + 1, a + cols], 1).ravel()
    t = compute_tangents(p, p, uv, idx)
    np.testing.assert_allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(np.sum(t[:, :3] * p, axis=1), 0, atol=1e-5)
    assert len(set(t[:, 3])) == 1  # one consistent handedness


def test_any_tangent_is_perpendicular():
    n = np.array([[0, 0, 1], [1, 0, 0], [0.6, 0.8, 0], [0, -1, 0]], float)
    t = any_tangent(n)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1)
    np.testing.assert_allclose(np.sum(t * n, axis=1), 0, atol=1e-12)
