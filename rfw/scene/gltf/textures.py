"""Textures: their images (from a URI or a buffer view, each distinct image decoded once, its
size checked against the limits before its pixels are decoded) and their samplers, in
WebGPU terms."""

from __future__ import annotations

import hashlib
import io
import json
from typing import Any

import numpy as np

from .. import limits
from ..model import Scene, Texture
from .accessors import Accessors
from .file import GltfFile

# samplers in WebGPU terms; the model cannot say "no mipmaps", so the non-mipmapped glTF
# minification filters pick nearest mip selection, the closest to sampling one level
_MAG_FILTERS = {9728: "nearest", 9729: "linear"}
_MIN_FILTERS = {
    9728: ("nearest", "nearest"), 9729: ("linear", "nearest"),
    9984: ("nearest", "nearest"), 9985: ("linear", "nearest"),
    9986: ("nearest", "linear"), 9987: ("linear", "linear"),
}
_WRAPS = {33071: "clamp-to-edge", 33648: "mirror-repeat", 10497: "repeat"}


class Textures:
    """The textures of ``file`` as ``scene.textures``; each (texture, sRGB or not) is made
    once."""

    def __init__(self, file: GltfFile, accessors: Accessors, scene: Scene):
        self.file = file
        self.accessors = accessors
        self.scene = scene
        self.images: dict[int, np.ndarray] = {}
        # one decode per distinct image, however many images, textures or materials name it
        self.decoded: dict[bytes, np.ndarray] = {}
        self.texels = 0  # of the distinct images decoded so far (limits.MAX_TEXELS)
        # (texture, sRGB) -> its index in scene.textures, None for one that is dropped
        self.scene_index: dict[tuple[int, bool], int | None] = {}

    def texture(self, index: Any, srgb: bool, where: str) -> int | None:
        key = (index, srgb)
        if key in self.scene_index:
            return self.scene_index[key]
        tex = self.file.item("textures", index, where)
        twhere = f"textures[{index}]"
        source = tex.source
        webp = (tex.extensions or {}).get("EXT_texture_webp")
        if isinstance(webp, dict) and webp.get("source") is not None:
            source = webp["source"]
        if source is None:
            self.file.warn(f"{twhere} has no source this loader can decode; {where} is dropped")
            self.scene_index[key] = None
            return None
        pixels = self.image(source, f"{twhere}.source")
        sampler = self.sampler(tex.sampler, f"{twhere}.sampler")
        image = self.file.doc.images[source]
        name = tex.name or image.name or (image.uri if image.uri and
                                          not image.uri.startswith("data:") else twhere)
        self.scene_index[key] = len(self.scene.textures)
        self.scene.textures.append(Texture(name=name, pixels=pixels, srgb=srgb, **sampler))
        return self.scene_index[key]

    def sampler(self, index: Any, where: str) -> dict[str, str]:
        if index is None:
            return {}  # glTF: undefined sampler = repeat and auto filtering
        s = self.file.item("samplers", index, where)
        swhere = f"samplers[{index}]"
        out = {}
        if s.magFilter is not None:
            if s.magFilter not in _MAG_FILTERS:
                self.file.fail(swhere, f"magFilter {json.dumps(s.magFilter)} is not 9728 or 9729")
            out["mag_filter"] = _MAG_FILTERS[s.magFilter]
        if s.minFilter is not None:
            if s.minFilter not in _MIN_FILTERS:
                self.file.fail(swhere, f"minFilter {json.dumps(s.minFilter)} is not a glTF filter")
            out["min_filter"], out["mipmap_filter"] = _MIN_FILTERS[s.minFilter]
        for key, value in (("address_u", s.wrapS), ("address_v", s.wrapT)):
            if value is None:
                continue
            if value not in _WRAPS:
                name = "wrapS" if key == "address_u" else "wrapT"
                self.file.fail(swhere, f"{name} {json.dumps(value)} is not 33071, 33648 or 10497")
            out[key] = _WRAPS[value]
        return out

    def image(self, index: Any, where: str) -> np.ndarray:
        if index in self.images:
            return self.images[index]
        img = self.file.item("images", index, where)
        iwhere = f"images[{index}]"
        if img.uri is not None:
            data = self.file.read_uri(img.uri, iwhere)
        elif img.bufferView is not None:
            data = bytes(self.accessors.view(img.bufferView, iwhere)[0])
        else:
            self.file.fail(iwhere, "has neither uri nor bufferView")
        key = hashlib.sha256(data).digest()  # the same bytes under another name or index
        if key not in self.decoded:
            self.decoded[key] = self.decode(data, iwhere)
        self.images[index] = self.decoded[key]
        return self.images[index]

    def decode(self, data: bytes, where: str) -> np.ndarray:
        """RGBA8 pixels of an encoded image; its size is checked against the limits
        (``limits.check_image``) from the header, before the pixels are decoded."""
        from PIL import Image, UnidentifiedImageError  # only needed for textured scenes

        try:
            with limits.pillow_unbounded():  # sizes are checked here, with the file named
                im = Image.open(io.BytesIO(data))
        except UnidentifiedImageError:
            self.file.fail(where, "cannot decode the image: not a format Pillow reads "
                                  f"({len(data)} bytes starting {bytes(data[:8])!r})")
        except (OSError, ValueError, SyntaxError) as e:
            self.file.fail(where, f"cannot decode the image ({type(e).__name__}: {e})")
        with im:
            self.texels = limits.check_image(*im.size, self.texels, file=self.file.source,
                                             where=where)
            try:
                im.load()
                if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                    # 16-bit greyscale: keep the high byte rather than clipping
                    grey = (np.asarray(im, np.uint32) >> 8).astype(np.uint8)
                    im = Image.fromarray(grey, "L")
                rgba = _rgba(im)
            except (OSError, ValueError, SyntaxError, MemoryError) as e:
                self.file.fail(where, f"cannot decode the image ({type(e).__name__}: {e})")
        return np.ascontiguousarray(rgba)


# rows converted at a time: the whole image converted at once held the decoded image, its
# RGBA copy in Pillow and the array at once (2.8 GB for a 16384x16384 RGB PNG, not 1.8)
_RGBA_BAND_TEXELS = 1 << 22


def _rgba(im: Any) -> np.ndarray:
    """A loaded Pillow image as an (H, W, 4) uint8 array, converted band by band."""
    w, h = im.size
    out = np.empty((h, w, 4), np.uint8)
    step = max(1, _RGBA_BAND_TEXELS // max(w, 1))
    for y in range(0, h, step):
        band = im.crop((0, y, w, min(y + step, h))).convert("RGBA")
        out[y:y + band.size[1]] = np.asarray(band)
    return out
