"""What one scene may cost: limits checked before anything is allocated.

A small file can ask for a lot: an accessor without a bufferView is ``count`` zeros (glTF
2.0 section 3.6.2.3), one bufferView may feed many meshes, and a PNG of a few kilobytes may
declare 100000x100000 pixels. The glTF loader counts what a scene will hold before it reads
an accessor or decodes an image, and refuses what is over these limits in one line naming
the number, the limit and the element; the backends check textures against the device's own
limits (``check_texture_size``) before uploading.

The limits are the same on every device. Geometry is counted in the host bytes the loader
holds at its peak (measured on lavapipe's host: about 136 bytes per vertex and 76 per
triangle corner), so that no small file makes a run need much more than 2 GB; images in
decoded RGBA8 texels of the scene's distinct images (one image used by many textures counts
once). A scene over a limit can be split, decimated, or its textures downsized.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from .model import SceneError

# host bytes the glTF loader holds per vertex and per triangle corner (index) at its peak
VERTEX_BYTES = 136
INDEX_BYTES = 76
# the geometry of one scene: about 5 million vertices without indices, or 2.4 million
# vertices with 9 million corners (3 million triangles)
MAX_GEOMETRY_BYTES = 1 << 30
# decoded texels of the scene's distinct images: one 16384x16384 image, or sixteen 4096x4096
MAX_TEXELS = 1 << 28
# pixels per side of one image (also ``--size``'s limit, rfw.config.MAX_SIZE)
MAX_IMAGE_SIDE = 16384


def geometry_bytes(vertices: int, indices: int) -> int:
    """The loader's estimate of the host bytes ``vertices`` and ``indices`` need."""
    return vertices * VERTEX_BYTES + indices * INDEX_BYTES


def check_geometry(vertices: int, indices: int, *, file: str, largest: str) -> None:
    """Refuse a scene whose geometry is over ``MAX_GEOMETRY_BYTES``; ``largest`` names the
    element that holds most of it (``meshes[0].primitives[0] (accessors[0], count ...)``)."""
    need = geometry_bytes(vertices, indices)
    if need > MAX_GEOMETRY_BYTES:
        raise SceneError(f"{vertices:,} vertices and {indices:,} indices would need about "
                         f"{_gib(need)} to load, over rfw's limit of "
                         f"{_gib(MAX_GEOMETRY_BYTES)} per scene (the largest: {largest})",
                         file=file, element="meshes")


def check_image(width: int, height: int, texels_before: int, *, file: str,
                where: str) -> int:
    """The scene's texel count with an image of ``width`` x ``height`` added, or a
    SceneError naming ``where`` when a side or the scene's total is over its limit."""
    if max(width, height) > MAX_IMAGE_SIDE:
        raise SceneError(f"{width}x{height} pixels is over the limit of {MAX_IMAGE_SIDE} "
                         f"pixels per side", file=file, element=where)
    total = texels_before + width * height
    if total > MAX_TEXELS:
        raise SceneError(f"{width}x{height} pixels brings the scene's distinct images to "
                         f"{total:,} texels ({_gib(4 * total)} decoded), over the limit of "
                         f"{MAX_TEXELS:,} ({_gib(4 * MAX_TEXELS)}; rfw.scene.limits)",
                         file=file, element=where)
    return total


def check_texture_size(width: int, height: int, limit: int | None, key: str, *,
                       file: str | None, name: str) -> None:
    """Refuse a texture over the device's 2D limit (``key``: maxImageDimension2D on vk,
    max-texture-dimension-2d on wgpu) before the device is asked to make it."""
    if limit and max(width, height) > int(limit):
        raise SceneError(f"texture {name!r} is {width}x{height}, over this device's {key} "
                         f"({int(limit)} pixels per side)", file=file, element="textures")


_PILLOW = threading.Lock()


@contextmanager
def pillow_unbounded() -> Iterator[None]:
    """Pillow's decompression-bomb check off inside (``Image.MAX_IMAGE_PIXELS``): its
    limit of 89 megapixels refuses images rfw writes itself (``--size`` allows 16384x16384),
    and its error names no file. Callers check ``Image.size`` against their own limit
    before ``load()``, which is what decodes."""
    from PIL import Image

    with _PILLOW:
        old, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = old


def _gib(n: int) -> str:
    return f"{n / (1 << 30):.2f} GiB"
