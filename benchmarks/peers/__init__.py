"""Peer renderers measured side by side with rfw: same scene, camera and resolution.

One module per peer; ``run.py`` runs one of them in its own process (``rfw bench --peers``
calls it). Raster peers: moderngl (EGL), pyvista/VTK (EGL), pygfx (wgpu). Ray-casting peers:
Open3D, Mitsuba 3, Embree (embreex via trimesh), and rfw's own ``rfw.raycast``.
"""

RASTER = ("moderngl", "pyvista", "pygfx")
RAYCAST = ("open3d", "mitsuba", "embree", "rfw_raycast")
ALL = RASTER + RAYCAST
