"""Texture format table for the frame-graph compiler.

The compiler needs three things from a format: how many bytes an image of it
occupies (for transient-memory budgeting and aliasing), which aspects it has
(colour, depth, stencil; to pick image layouts and aspect masks), and whether
two spellings name the same physical format (to detect conflicting resource
declarations between the wgpu and Vulkan backends).

Coverage
--------
* every ``wgpu.TextureFormat`` of wgpu-py 0.32.0 (101 names, taken from the
  wheel's ``wgpu/enums.py``);
* every core ``VkFormat`` of Vulkan 1.3 except ``VK_FORMAT_UNDEFINED`` and the
  24 multi-planar YCbCr formats (``*_2PLANE_*``/``*_3PLANE_*``), whose planes
  have different sizes and therefore cannot be described by one texel block.
  The single-plane YCbCr formats (``R10X6_UNORM_PACK16``,
  ``G8B8G8R8_422_UNORM``, ...) are included.  Extension-only formats
  (PVRTC, ASTC 3D, ``A8_UNORM``/``A1B5G5R5`` from 1.4, ...) are not.

Everything here is pure Python (stdlib only) so that graph compilation and
its tests run without a GPU or either backend installed. Most of its ~640 lines are
that table, one line per format, which reads best whole.
"""

from __future__ import annotations

import difflib
import operator
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType

__all__ = [
    "FORMATS",
    "KINDS",
    "FormatInfo",
    "UnknownFormatError",
    "canonical",
    "format_info",
    "image_bytes",
    "max_mips",
]

#: The closed set of values of :attr:`FormatInfo.kind`.
#:
#: ``unorm``/``snorm``
#:     normalised integers (sRGB formats are ``unorm`` with ``srgb=True``);
#: ``uscaled``/``sscaled``
#:     integers converted to float without normalisation (Vulkan only);
#: ``uint``/``sint``
#:     pure integers;
#: ``float``/``ufloat``
#:     signed / unsigned floating point (``ufloat``: B10G11R11, E5B9G9R9, BC6H);
#: ``depth``/``stencil``/``depth-stencil``
#:     formats with a depth and/or stencil aspect instead of colour.
KINDS: frozenset[str] = frozenset(
    {
        "unorm",
        "snorm",
        "uscaled",
        "sscaled",
        "uint",
        "sint",
        "float",
        "ufloat",
        "depth",
        "stencil",
        "depth-stencil",
    }
)

_VK_PREFIX = "VK_FORMAT_"


class UnknownFormatError(ValueError):
    """Raised by :func:`format_info` for a name that is not in :data:`FORMATS`."""


@dataclass(frozen=True)
class FormatInfo:
    """Static description of one texture format.

    Attributes
    ----------
    name : str
        The name as it appears in :data:`FORMATS` (wgpu spelling such as
        ``"rgba8unorm"`` or the full Vulkan name such as
        ``"VK_FORMAT_R8G8B8A8_UNORM"``).
    block_bytes : int
        Bytes per texel block (per texel for uncompressed formats).
    block_width, block_height : int
        Texel-block extent in texels; 1 for uncompressed formats.
    components : int
        Number of distinct channels; a combined depth-stencil format counts 2.
    depth : bool
        The format has a depth aspect.
    stencil : bool
        The format has a stencil aspect.
    compressed : bool
        Block-compressed (BC, ETC2/EAC, ASTC).
    srgb : bool
        Colour channels are sRGB-encoded.
    kind : str
        Numeric interpretation, one of :data:`KINDS`.
    vk : str or None
        Equivalent ``VK_FORMAT_*`` name; the name itself for Vulkan entries,
        ``None`` for wgpu formats whose Vulkan format is implementation-defined
        (``depth24plus``, ``depth24plus-stencil8``).
    wgpu : str or None
        Equivalent wgpu name; the name itself for wgpu entries, ``None`` for
        Vulkan formats that WebGPU does not expose.
    """

    name: str
    block_bytes: int
    block_width: int
    block_height: int
    components: int
    depth: bool
    stencil: bool
    compressed: bool
    srgb: bool
    kind: str
    vk: str | None
    wgpu: str | None

    def __post_init__(self) -> None:
        # a typo in the tables below should fail at import, not in a size estimate
        if self.kind not in KINDS:
            raise ValueError(f"{self.name}: kind {self.kind!r} not in KINDS")
        if min(self.block_bytes, self.block_width, self.block_height, self.components) < 1:
            raise ValueError(f"{self.name}: block sizes and components must be positive")


# ---------------------------------------------------------------------------
# vulkan formats
# ---------------------------------------------------------------------------

# numeric-format token of a vk name -> (kind, srgb)
_VK_NUMERIC: dict[str, tuple[str, bool]] = {
    "UNORM": ("unorm", False),
    "SNORM": ("snorm", False),
    "USCALED": ("uscaled", False),
    "SSCALED": ("sscaled", False),
    "UINT": ("uint", False),
    "SINT": ("sint", False),
    "SRGB": ("unorm", True),
    "SFLOAT": ("float", False),
    "UFLOAT": ("ufloat", False),
}

_SUFFIXES_8 = ("UNORM", "SNORM", "USCALED", "SSCALED", "UINT", "SINT", "SRGB")
_SUFFIXES_16 = ("UNORM", "SNORM", "USCALED", "SSCALED", "UINT", "SINT", "SFLOAT")
_SUFFIXES_WIDE = ("UINT", "SINT", "SFLOAT")

# (bits per channel, channel orders, numeric suffixes): the plain array formats
# VK_FORMAT_R8_UNORM .. VK_FORMAT_R64G64B64A64_SFLOAT
_PER_CHANNEL: tuple[tuple[int, tuple[str, ...], tuple[str, ...]], ...] = (
    (8, ("R", "RG", "RGB", "BGR", "RGBA", "BGRA"), _SUFFIXES_8),
    (16, ("R", "RG", "RGB", "RGBA"), _SUFFIXES_16),
    (32, ("R", "RG", "RGB", "RGBA"), _SUFFIXES_WIDE),
    (64, ("R", "RG", "RGB", "RGBA"), _SUFFIXES_WIDE),
)

_SUFFIXES_PACK32 = ("UNORM", "SNORM", "USCALED", "SSCALED", "UINT", "SINT")

# packed and single-plane ycbcr formats: (name without prefix, bytes, components,
# block width). 422 formats store two texels (sharing chroma) per block.
_PACKED: tuple[tuple[str, int, int, int], ...] = (
    ("R4G4_UNORM_PACK8", 1, 2, 1),
    ("R4G4B4A4_UNORM_PACK16", 2, 4, 1),
    ("B4G4R4A4_UNORM_PACK16", 2, 4, 1),
    ("R5G6B5_UNORM_PACK16", 2, 3, 1),
    ("B5G6R5_UNORM_PACK16", 2, 3, 1),
    ("R5G5B5A1_UNORM_PACK16", 2, 4, 1),
    ("B5G5R5A1_UNORM_PACK16", 2, 4, 1),
    ("A1R5G5B5_UNORM_PACK16", 2, 4, 1),
    *((f"A8B8G8R8_{s}_PACK32", 4, 4, 1) for s in (*_SUFFIXES_PACK32, "SRGB")),
    *((f"A2R10G10B10_{s}_PACK32", 4, 4, 1) for s in _SUFFIXES_PACK32),
    *((f"A2B10G10R10_{s}_PACK32", 4, 4, 1) for s in _SUFFIXES_PACK32),
    ("B10G11R11_UFLOAT_PACK32", 4, 3, 1),
    ("E5B9G9R9_UFLOAT_PACK32", 4, 3, 1),  # shared exponent, not a 4th channel
    # core since 1.3 (VK_EXT_4444_formats)
    ("A4R4G4B4_UNORM_PACK16", 2, 4, 1),
    ("A4B4G4R4_UNORM_PACK16", 2, 4, 1),
    # single-plane ycbcr (core since 1.1); components counts distinct channels
    ("R10X6_UNORM_PACK16", 2, 1, 1),
    ("R10X6G10X6_UNORM_2PACK16", 4, 2, 1),
    ("R10X6G10X6B10X6A10X6_UNORM_4PACK16", 8, 4, 1),
    ("R12X4_UNORM_PACK16", 2, 1, 1),
    ("R12X4G12X4_UNORM_2PACK16", 4, 2, 1),
    ("R12X4G12X4B12X4A12X4_UNORM_4PACK16", 8, 4, 1),
    ("G8B8G8R8_422_UNORM", 4, 3, 2),
    ("B8G8R8G8_422_UNORM", 4, 3, 2),
    ("G10X6B10X6G10X6R10X6_422_UNORM_4PACK16", 8, 3, 2),
    ("B10X6G10X6R10X6G10X6_422_UNORM_4PACK16", 8, 3, 2),
    ("G12X4B12X4G12X4R12X4_422_UNORM_4PACK16", 8, 3, 2),
    ("B12X4G12X4R12X4G12X4_422_UNORM_4PACK16", 8, 3, 2),
    ("G16B16G16R16_422_UNORM", 8, 3, 2),
    ("B16G16R16G16_422_UNORM", 8, 3, 2),
)

# depth/stencil: (name without prefix, bytes, has depth, has stencil)
_DEPTH_STENCIL: tuple[tuple[str, int, bool, bool], ...] = (
    ("D16_UNORM", 2, True, False),
    ("X8_D24_UNORM_PACK32", 4, True, False),
    ("D32_SFLOAT", 4, True, False),
    ("S8_UINT", 1, False, True),
    # the spec's texel block size is 3; no known driver packs it tighter than 4,
    # and over-estimating keeps memory budgets safe
    ("D16_UNORM_S8_UINT", 4, True, True),
    ("D24_UNORM_S8_UINT", 4, True, True),
    # the spec's texel block size is 5, but drivers store it as 8 (d32 plus a
    # padded s8), so budget for 8
    ("D32_SFLOAT_S8_UINT", 8, True, True),
)

# block-compressed, 4x4 blocks: (name without prefix, bytes per block, components)
_BC_ETC: tuple[tuple[str, int, int], ...] = (
    ("BC1_RGB_UNORM_BLOCK", 8, 3),
    ("BC1_RGB_SRGB_BLOCK", 8, 3),
    ("BC1_RGBA_UNORM_BLOCK", 8, 4),
    ("BC1_RGBA_SRGB_BLOCK", 8, 4),
    ("BC2_UNORM_BLOCK", 16, 4),
    ("BC2_SRGB_BLOCK", 16, 4),
    ("BC3_UNORM_BLOCK", 16, 4),
    ("BC3_SRGB_BLOCK", 16, 4),
    ("BC4_UNORM_BLOCK", 8, 1),
    ("BC4_SNORM_BLOCK", 8, 1),
    ("BC5_UNORM_BLOCK", 16, 2),
    ("BC5_SNORM_BLOCK", 16, 2),
    ("BC6H_UFLOAT_BLOCK", 16, 3),
    ("BC6H_SFLOAT_BLOCK", 16, 3),
    ("BC7_UNORM_BLOCK", 16, 4),
    ("BC7_SRGB_BLOCK", 16, 4),
    ("ETC2_R8G8B8_UNORM_BLOCK", 8, 3),
    ("ETC2_R8G8B8_SRGB_BLOCK", 8, 3),
    ("ETC2_R8G8B8A1_UNORM_BLOCK", 8, 4),
    ("ETC2_R8G8B8A1_SRGB_BLOCK", 8, 4),
    ("ETC2_R8G8B8A8_UNORM_BLOCK", 16, 4),
    ("ETC2_R8G8B8A8_SRGB_BLOCK", 16, 4),
    ("EAC_R11_UNORM_BLOCK", 8, 1),
    ("EAC_R11_SNORM_BLOCK", 8, 1),
    ("EAC_R11G11_UNORM_BLOCK", 16, 2),
    ("EAC_R11G11_SNORM_BLOCK", 16, 2),
)

# astc block footprints shared by vulkan and webgpu; every astc block is 128 bits
_ASTC_DIMS: tuple[tuple[int, int], ...] = (
    (4, 4),
    (5, 4),
    (5, 5),
    (6, 5),
    (6, 6),
    (8, 5),
    (8, 6),
    (8, 8),
    (10, 5),
    (10, 6),
    (10, 8),
    (10, 10),
    (12, 10),
    (12, 12),
)
_ASTC_BYTES = 16


def _numeric(name: str) -> tuple[str, bool]:
    """Return ``(kind, srgb)`` from the numeric-format token of a vk name."""
    for token in name.split("_"):
        if token in _VK_NUMERIC:
            return _VK_NUMERIC[token]
    raise ValueError(f"no numeric format token in {name!r}")  # pragma: no cover


def _vk(
    body: str,
    block_bytes: int,
    components: int,
    *,
    block_width: int = 1,
    block_height: int = 1,
    compressed: bool = False,
) -> FormatInfo:
    """Build a colour-format entry from a vk name without its prefix."""
    kind, srgb = _numeric(body)
    name = _VK_PREFIX + body
    return FormatInfo(
        name=name,
        block_bytes=block_bytes,
        block_width=block_width,
        block_height=block_height,
        components=components,
        depth=False,
        stencil=False,
        compressed=compressed,
        srgb=srgb,
        kind=kind,
        vk=name,
        wgpu=None,
    )


def _vk_formats() -> Iterable[FormatInfo]:
    """Yield every supported vk format (``wgpu`` still unset)."""
    for bits, orders, suffixes in _PER_CHANNEL:
        for order in orders:
            body = "".join(f"{channel}{bits}" for channel in order)
            for suffix in suffixes:
                yield _vk(f"{body}_{suffix}", bits * len(order) // 8, len(order))
    for body, nbytes, components, block_width in _PACKED:
        yield _vk(body, nbytes, components, block_width=block_width)
    for body, nbytes, has_depth, has_stencil in _DEPTH_STENCIL:
        kind = "depth-stencil" if has_depth and has_stencil else "depth" if has_depth else "stencil"
        name = _VK_PREFIX + body
        yield FormatInfo(
            name=name,
            block_bytes=nbytes,
            block_width=1,
            block_height=1,
            components=int(has_depth) + int(has_stencil),
            depth=has_depth,
            stencil=has_stencil,
            compressed=False,
            srgb=False,
            kind=kind,
            vk=name,
            wgpu=None,
        )
    for body, nbytes, components in _BC_ETC:
        yield _vk(body, nbytes, components, block_width=4, block_height=4, compressed=True)
    for suffix in ("UNORM", "SRGB", "SFLOAT"):  # sfloat (hdr) is core since 1.3
        for w, h in _ASTC_DIMS:
            yield _vk(
                f"ASTC_{w}x{h}_{suffix}_BLOCK",
                _ASTC_BYTES,
                4,
                block_width=w,
                block_height=h,
                compressed=True,
            )


# ---------------------------------------------------------------------------
# wgpu formats, as equivalents of vk formats
# ---------------------------------------------------------------------------

# wgpu spells plain formats as <channels><bits><numeric>[-srgb]
_WGPU_CHANNELS = {"r": "R", "rg": "RG", "rgba": "RGBA", "bgra": "BGRA"}
_WGPU_NUMERIC = {
    "unorm": "UNORM",
    "snorm": "SNORM",
    "uint": "UINT",
    "sint": "SINT",
    "float": "SFLOAT",
}


def _words(text: str) -> tuple[str, ...]:
    """Split a whitespace-separated name list (keeps long tables compact)."""
    return tuple(text.split())


_WGPU_PLAIN = _words(
    """
    r8unorm r8snorm r8uint r8sint
    r16unorm r16snorm r16uint r16sint r16float
    rg8unorm rg8snorm rg8uint rg8sint
    r32uint r32sint r32float
    rg16unorm rg16snorm rg16uint rg16sint rg16float
    rgba8unorm rgba8unorm-srgb rgba8snorm rgba8uint rgba8sint
    bgra8unorm bgra8unorm-srgb
    rg32uint rg32sint rg32float
    rgba16unorm rgba16snorm rgba16uint rgba16sint rgba16float
    rgba32uint rgba32sint rgba32float
"""
)

# wgpu names that do not follow the plain pattern -> vk name without prefix
# (the same mapping wgpu-hal's vulkan backend uses)
_WGPU_SPECIAL: dict[str, str] = {
    "rgb9e5ufloat": "E5B9G9R9_UFLOAT_PACK32",
    # webgpu names channels from the lsb, vulkan's PACK32 names from the msb
    "rgb10a2uint": "A2B10G10R10_UINT_PACK32",
    "rgb10a2unorm": "A2B10G10R10_UNORM_PACK32",
    "rg11b10ufloat": "B10G11R11_UFLOAT_PACK32",
    "stencil8": "S8_UINT",
    "depth16unorm": "D16_UNORM",
    "depth32float": "D32_SFLOAT",
    "depth32float-stencil8": "D32_SFLOAT_S8_UINT",
    "bc1-rgba-unorm": "BC1_RGBA_UNORM_BLOCK",
    "bc1-rgba-unorm-srgb": "BC1_RGBA_SRGB_BLOCK",
    "bc2-rgba-unorm": "BC2_UNORM_BLOCK",
    "bc2-rgba-unorm-srgb": "BC2_SRGB_BLOCK",
    "bc3-rgba-unorm": "BC3_UNORM_BLOCK",
    "bc3-rgba-unorm-srgb": "BC3_SRGB_BLOCK",
    "bc4-r-unorm": "BC4_UNORM_BLOCK",
    "bc4-r-snorm": "BC4_SNORM_BLOCK",
    "bc5-rg-unorm": "BC5_UNORM_BLOCK",
    "bc5-rg-snorm": "BC5_SNORM_BLOCK",
    "bc6h-rgb-ufloat": "BC6H_UFLOAT_BLOCK",
    "bc6h-rgb-float": "BC6H_SFLOAT_BLOCK",
    "bc7-rgba-unorm": "BC7_UNORM_BLOCK",
    "bc7-rgba-unorm-srgb": "BC7_SRGB_BLOCK",
    "etc2-rgb8unorm": "ETC2_R8G8B8_UNORM_BLOCK",
    "etc2-rgb8unorm-srgb": "ETC2_R8G8B8_SRGB_BLOCK",
    "etc2-rgb8a1unorm": "ETC2_R8G8B8A1_UNORM_BLOCK",
    "etc2-rgb8a1unorm-srgb": "ETC2_R8G8B8A1_SRGB_BLOCK",
    "etc2-rgba8unorm": "ETC2_R8G8B8A8_UNORM_BLOCK",
    "etc2-rgba8unorm-srgb": "ETC2_R8G8B8A8_SRGB_BLOCK",
    "eac-r11unorm": "EAC_R11_UNORM_BLOCK",
    "eac-r11snorm": "EAC_R11_SNORM_BLOCK",
    "eac-rg11unorm": "EAC_R11G11_UNORM_BLOCK",
    "eac-rg11snorm": "EAC_R11G11_SNORM_BLOCK",
    **{f"astc-{w}x{h}-unorm": f"ASTC_{w}x{h}_UNORM_BLOCK" for w, h in _ASTC_DIMS},
    **{f"astc-{w}x{h}-unorm-srgb": f"ASTC_{w}x{h}_SRGB_BLOCK" for w, h in _ASTC_DIMS},
}


def _plain_wgpu_to_vk(name: str) -> str:
    """Translate e.g. ``rgba16float`` to ``R16G16B16A16_SFLOAT``."""
    base, srgb, _ = name.partition("-srgb")
    channels = base.rstrip("abcdefghijklmnopqrstuvwxyz")
    for prefix, order in _WGPU_CHANNELS.items():
        if channels.startswith(prefix) and channels[len(prefix) :].isdigit():
            bits = channels[len(prefix) :]
            numeric = "SRGB" if srgb else _WGPU_NUMERIC[base[len(channels) :]]
            return "".join(f"{c}{bits}" for c in order) + "_" + numeric
    raise ValueError(f"not a plain wgpu format: {name!r}")  # pragma: no cover


def _build() -> dict[str, FormatInfo]:
    """Assemble the full table, linking vk and wgpu equivalents both ways."""
    vk_table = {info.name: info for info in _vk_formats()}
    wgpu_to_vk = {name: _VK_PREFIX + _plain_wgpu_to_vk(name) for name in _WGPU_PLAIN}
    wgpu_to_vk.update({name: _VK_PREFIX + body for name, body in _WGPU_SPECIAL.items()})

    table: dict[str, FormatInfo] = {}
    vk_to_wgpu: dict[str, str] = {}
    for wname, vname in wgpu_to_vk.items():
        # a missing or shared target is a table bug; fail loudly at import
        if vname not in vk_table or vname in vk_to_wgpu:
            raise RuntimeError(f"bad wgpu->vk mapping {wname!r} -> {vname!r}")
        vk_to_wgpu[vname] = wname
        table[wname] = replace(vk_table[vname], name=wname, vk=vname, wgpu=wname)

    # the vulkan format behind depth24plus* is chosen per device (x8_d24 or
    # d32, d24s8 or d32s8), so there is no fixed equivalent; 4 bytes is the
    # common case and what the webgpu spec's byte-size guidance assumes
    for wname, has_stencil in (("depth24plus", False), ("depth24plus-stencil8", True)):
        table[wname] = FormatInfo(
            name=wname,
            block_bytes=4,
            block_width=1,
            block_height=1,
            components=1 + int(has_stencil),
            depth=True,
            stencil=has_stencil,
            compressed=False,
            srgb=False,
            kind="depth-stencil" if has_stencil else "depth",
            vk=None,
            wgpu=wname,
        )

    for vname, info in vk_table.items():
        table[vname] = replace(info, wgpu=vk_to_wgpu.get(vname))
    return table


#: Every supported format, keyed by its wgpu name or full ``VK_FORMAT_*`` name.
FORMATS: Mapping[str, FormatInfo] = MappingProxyType(_build())

# lookup keys: lowercase, vk prefix stripped -> table name (no wgpu name
# collides with a stripped vk name, checked below)
_LOOKUP: dict[str, str] = {}
for _name in FORMATS:
    _key = _name.lower().removeprefix(_VK_PREFIX.lower())
    if _key in _LOOKUP:  # pragma: no cover - table bug
        raise RuntimeError(f"lookup key {_key!r} is ambiguous")
    _LOOKUP[_key] = _name
del _name, _key


# ---------------------------------------------------------------------------
# public functions
# ---------------------------------------------------------------------------


def format_info(name: str) -> FormatInfo:
    """Look a format up by wgpu or Vulkan name.

    Parameters
    ----------
    name : str
        A wgpu name (``"rgba8unorm"``) or a Vulkan name, with or without the
        ``VK_FORMAT_`` prefix and in any case (``"VK_FORMAT_R16G16_SFLOAT"``,
        ``"r16g16_sfloat"``).

    Returns
    -------
    FormatInfo
        The table entry; its ``name`` is the spelling used in :data:`FORMATS`.

    Raises
    ------
    TypeError
        If `name` is not a string.
    UnknownFormatError
        If no format matches; the message suggests up to three close names.
    """
    if not isinstance(name, str):
        raise TypeError(f"format name must be a str, not {type(name).__name__}")
    info = FORMATS.get(name)
    if info is not None:
        return info
    key = name.strip().lower().removeprefix(_VK_PREFIX.lower())
    if key in _LOOKUP:
        return FORMATS[_LOOKUP[key]]
    # match in the same normalised space so 'r16g16_sflot' finds the vk name
    close = [_LOOKUP[k] for k in difflib.get_close_matches(key, _LOOKUP, n=3)]
    message = f"unknown format {name!r}"
    if close:
        # same wording as rfw.graph.errors.did_you_mean, so messages read alike
        message += " (did you mean " + " or ".join(f"'{c}'" for c in close) + "?)"
    raise UnknownFormatError(message)


def _positive(label: str, value: int) -> int:
    """Validate a positive integer argument (numpy integers accepted)."""
    value = operator.index(value)
    if value < 1:
        raise ValueError(f"{label} must be positive, got {value}")
    return value


def max_mips(width: int, height: int) -> int:
    """Length of the full mip chain of a ``width`` x ``height`` image.

    Parameters
    ----------
    width, height : int
        Size of mip level 0 in texels; must be positive.

    Returns
    -------
    int
        ``floor(log2(max(width, height))) + 1``.

    Raises
    ------
    ValueError
        If `width` or `height` is not positive.
    """
    width = _positive("width", width)
    height = _positive("height", height)
    # bit_length is exact where math.log2 rounds for large values
    return max(width, height).bit_length()


def image_bytes(
    fmt: str,
    width: int,
    height: int,
    *,
    mips: int = 1,
    layers: int = 1,
    samples: int = 1,
) -> int:
    """Exact size in bytes of the texel data of a 2D image or image array.

    For each mip level ``m`` the level is ``max(1, width >> m)`` by
    ``max(1, height >> m)`` texels, rounded up to whole texel blocks; the sum
    over levels is multiplied by `layers` and `samples`.  Driver alignment and
    padding are not included.

    Parameters
    ----------
    fmt : str
        Format name, anything :func:`format_info` accepts.
    width, height : int
        Size of mip level 0 in texels.
    mips : int, optional
        Number of mip levels, at most ``max_mips(width, height)``.
    layers : int, optional
        Array layers (6 for a cube map).
    samples : int, optional
        Samples per texel; a power of two.

    Returns
    -------
    int
        Total size in bytes.

    Raises
    ------
    ValueError
        If any size is not positive, `samples` is not a power of two, or
        `mips` exceeds the full chain.
    UnknownFormatError
        If `fmt` is not a known format.
    """
    info = format_info(fmt)
    width = _positive("width", width)
    height = _positive("height", height)
    mips = _positive("mips", mips)
    layers = _positive("layers", layers)
    samples = _positive("samples", samples)
    if samples & (samples - 1):
        raise ValueError(f"samples must be a power of two, got {samples}")
    limit = max_mips(width, height)
    if mips > limit:
        raise ValueError(f"mips={mips} exceeds the full chain of {limit} for {width}x{height}")
    bw, bh = info.block_width, info.block_height
    blocks = 0
    for level in range(mips):
        w = max(1, width >> level)
        h = max(1, height >> level)
        blocks += -(-w // bw) * -(-h // bh)  # ceil division on ints
    return blocks * info.block_bytes * layers * samples


def canonical(name: str) -> str:
    """One key per physical format.

    Parameters
    ----------
    name : str
        Any name :func:`format_info` accepts.

    Returns
    -------
    str
        The full ``VK_FORMAT_*`` name where the format has a fixed Vulkan
        equivalent, else the wgpu name.  Two names denote the same format
        exactly when their canonical keys are equal (``"rgba8unorm"`` and
        ``"VK_FORMAT_R8G8B8A8_UNORM"`` agree; ``"depth24plus"`` matches
        no Vulkan name because its Vulkan format is chosen per device).
    """
    info = format_info(name)
    key = info.vk or info.wgpu
    assert key is not None  # every entry has at least one of the two
    return key
