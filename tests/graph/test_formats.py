"""Tests for rfw.graph.formats (pure Python, no GPU needed)."""

from __future__ import annotations

import dataclasses

import pytest

from rfw.graph.formats import (
    FORMATS,
    KINDS,
    FormatInfo,
    UnknownFormatError,
    canonical,
    format_info,
    image_bytes,
    max_mips,
)


def _words(text: str) -> list[str]:
    """Split a whitespace-separated name list."""
    return text.split()


# wgpu.TextureFormat of wgpu-py 0.32.0, copied from the wheel's wgpu/enums.py so
# this test does not need wgpu installed
WGPU_032_TEXTURE_FORMATS = _words(
    """
    r8unorm r8snorm r8uint r8sint r16unorm r16snorm r16uint r16sint r16float
    rg8unorm rg8snorm rg8uint rg8sint r32uint r32sint r32float
    rg16unorm rg16snorm rg16uint rg16sint rg16float
    rgba8unorm rgba8unorm-srgb rgba8snorm rgba8uint rgba8sint bgra8unorm bgra8unorm-srgb
    rgb9e5ufloat rgb10a2uint rgb10a2unorm rg11b10ufloat rg32uint rg32sint rg32float
    rgba16unorm rgba16snorm rgba16uint rgba16sint rgba16float
    rgba32uint rgba32sint rgba32float
    stencil8 depth16unorm depth24plus depth24plus-stencil8 depth32float depth32float-stencil8
    bc1-rgba-unorm bc1-rgba-unorm-srgb bc2-rgba-unorm bc2-rgba-unorm-srgb
    bc3-rgba-unorm bc3-rgba-unorm-srgb bc4-r-unorm bc4-r-snorm bc5-rg-unorm bc5-rg-snorm
    bc6h-rgb-ufloat bc6h-rgb-float bc7-rgba-unorm bc7-rgba-unorm-srgb
    etc2-rgb8unorm etc2-rgb8unorm-srgb etc2-rgb8a1unorm etc2-rgb8a1unorm-srgb
    etc2-rgba8unorm etc2-rgba8unorm-srgb eac-r11unorm eac-r11snorm eac-rg11unorm eac-rg11snorm
    astc-4x4-unorm astc-4x4-unorm-srgb astc-5x4-unorm astc-5x4-unorm-srgb
    astc-5x5-unorm astc-5x5-unorm-srgb astc-6x5-unorm astc-6x5-unorm-srgb
    astc-6x6-unorm astc-6x6-unorm-srgb astc-8x5-unorm astc-8x5-unorm-srgb
    astc-8x6-unorm astc-8x6-unorm-srgb astc-8x8-unorm astc-8x8-unorm-srgb
    astc-10x5-unorm astc-10x5-unorm-srgb astc-10x6-unorm astc-10x6-unorm-srgb
    astc-10x8-unorm astc-10x8-unorm-srgb astc-10x10-unorm astc-10x10-unorm-srgb
    astc-12x10-unorm astc-12x10-unorm-srgb astc-12x12-unorm astc-12x12-unorm-srgb
"""
)

# core VkFormat names of Vulkan 1.3 (from vulkan==1.3.275.1), without the
# VK_FORMAT_ prefix, minus UNDEFINED and the 24 multi-planar ycbcr formats
VK13_CORE_FORMATS = _words(
    """
    R4G4_UNORM_PACK8 R4G4B4A4_UNORM_PACK16 B4G4R4A4_UNORM_PACK16 R5G6B5_UNORM_PACK16
    B5G6R5_UNORM_PACK16 R5G5B5A1_UNORM_PACK16 B5G5R5A1_UNORM_PACK16 A1R5G5B5_UNORM_PACK16
    R8_UNORM R8_SNORM R8_USCALED R8_SSCALED R8_UINT R8_SINT R8_SRGB
    R8G8_UNORM R8G8_SNORM R8G8_USCALED R8G8_SSCALED R8G8_UINT R8G8_SINT R8G8_SRGB
    R8G8B8_UNORM R8G8B8_SNORM R8G8B8_USCALED R8G8B8_SSCALED R8G8B8_UINT R8G8B8_SINT R8G8B8_SRGB
    B8G8R8_UNORM B8G8R8_SNORM B8G8R8_USCALED B8G8R8_SSCALED B8G8R8_UINT B8G8R8_SINT B8G8R8_SRGB
    R8G8B8A8_UNORM R8G8B8A8_SNORM R8G8B8A8_USCALED R8G8B8A8_SSCALED R8G8B8A8_UINT
    R8G8B8A8_SINT R8G8B8A8_SRGB
    B8G8R8A8_UNORM B8G8R8A8_SNORM B8G8R8A8_USCALED B8G8R8A8_SSCALED B8G8R8A8_UINT
    B8G8R8A8_SINT B8G8R8A8_SRGB
    A8B8G8R8_UNORM_PACK32 A8B8G8R8_SNORM_PACK32 A8B8G8R8_USCALED_PACK32
    A8B8G8R8_SSCALED_PACK32 A8B8G8R8_UINT_PACK32 A8B8G8R8_SINT_PACK32 A8B8G8R8_SRGB_PACK32
    A2R10G10B10_UNORM_PACK32 A2R10G10B10_SNORM_PACK32 A2R10G10B10_USCALED_PACK32
    A2R10G10B10_SSCALED_PACK32 A2R10G10B10_UINT_PACK32 A2R10G10B10_SINT_PACK32
    A2B10G10R10_UNORM_PACK32 A2B10G10R10_SNORM_PACK32 A2B10G10R10_USCALED_PACK32
    A2B10G10R10_SSCALED_PACK32 A2B10G10R10_UINT_PACK32 A2B10G10R10_SINT_PACK32
    R16_UNORM R16_SNORM R16_USCALED R16_SSCALED R16_UINT R16_SINT R16_SFLOAT
    R16G16_UNORM R16G16_SNORM R16G16_USCALED R16G16_SSCALED R16G16_UINT R16G16_SINT
    R16G16_SFLOAT
    R16G16B16_UNORM R16G16B16_SNORM R16G16B16_USCALED R16G16B16_SSCALED R16G16B16_UINT
    R16G16B16_SINT R16G16B16_SFLOAT
    R16G16B16A16_UNORM R16G16B16A16_SNORM R16G16B16A16_USCALED R16G16B16A16_SSCALED
    R16G16B16A16_UINT R16G16B16A16_SINT R16G16B16A16_SFLOAT
    R32_UINT R32_SINT R32_SFLOAT R32G32_UINT R32G32_SINT R32G32_SFLOAT
    R32G32B32_UINT R32G32B32_SINT R32G32B32_SFLOAT
    R32G32B32A32_UINT R32G32B32A32_SINT R32G32B32A32_SFLOAT
    R64_UINT R64_SINT R64_SFLOAT R64G64_UINT R64G64_SINT R64G64_SFLOAT
    R64G64B64_UINT R64G64B64_SINT R64G64B64_SFLOAT
    R64G64B64A64_UINT R64G64B64A64_SINT R64G64B64A64_SFLOAT
    B10G11R11_UFLOAT_PACK32 E5B9G9R9_UFLOAT_PACK32
    D16_UNORM X8_D24_UNORM_PACK32 D32_SFLOAT S8_UINT D16_UNORM_S8_UINT D24_UNORM_S8_UINT
    D32_SFLOAT_S8_UINT
    BC1_RGB_UNORM_BLOCK BC1_RGB_SRGB_BLOCK BC1_RGBA_UNORM_BLOCK BC1_RGBA_SRGB_BLOCK
    BC2_UNORM_BLOCK BC2_SRGB_BLOCK BC3_UNORM_BLOCK BC3_SRGB_BLOCK
    BC4_UNORM_BLOCK BC4_SNORM_BLOCK BC5_UNORM_BLOCK BC5_SNORM_BLOCK
    BC6H_UFLOAT_BLOCK BC6H_SFLOAT_BLOCK BC7_UNORM_BLOCK BC7_SRGB_BLOCK
    ETC2_R8G8B8_UNORM_BLOCK ETC2_R8G8B8_SRGB_BLOCK ETC2_R8G8B8A1_UNORM_BLOCK
    ETC2_R8G8B8A1_SRGB_BLOCK ETC2_R8G8B8A8_UNORM_BLOCK ETC2_R8G8B8A8_SRGB_BLOCK
    EAC_R11_UNORM_BLOCK EAC_R11_SNORM_BLOCK EAC_R11G11_UNORM_BLOCK EAC_R11G11_SNORM_BLOCK
    ASTC_4x4_UNORM_BLOCK ASTC_4x4_SRGB_BLOCK ASTC_5x4_UNORM_BLOCK ASTC_5x4_SRGB_BLOCK
    ASTC_5x5_UNORM_BLOCK ASTC_5x5_SRGB_BLOCK ASTC_6x5_UNORM_BLOCK ASTC_6x5_SRGB_BLOCK
    ASTC_6x6_UNORM_BLOCK ASTC_6x6_SRGB_BLOCK ASTC_8x5_UNORM_BLOCK ASTC_8x5_SRGB_BLOCK
    ASTC_8x6_UNORM_BLOCK ASTC_8x6_SRGB_BLOCK ASTC_8x8_UNORM_BLOCK ASTC_8x8_SRGB_BLOCK
    ASTC_10x5_UNORM_BLOCK ASTC_10x5_SRGB_BLOCK ASTC_10x6_UNORM_BLOCK ASTC_10x6_SRGB_BLOCK
    ASTC_10x8_UNORM_BLOCK ASTC_10x8_SRGB_BLOCK ASTC_10x10_UNORM_BLOCK ASTC_10x10_SRGB_BLOCK
    ASTC_12x10_UNORM_BLOCK ASTC_12x10_SRGB_BLOCK ASTC_12x12_UNORM_BLOCK ASTC_12x12_SRGB_BLOCK
    G8B8G8R8_422_UNORM B8G8R8G8_422_UNORM
    R10X6_UNORM_PACK16 R10X6G10X6_UNORM_2PACK16 R10X6G10X6B10X6A10X6_UNORM_4PACK16
    G10X6B10X6G10X6R10X6_422_UNORM_4PACK16 B10X6G10X6R10X6G10X6_422_UNORM_4PACK16
    R12X4_UNORM_PACK16 R12X4G12X4_UNORM_2PACK16 R12X4G12X4B12X4A12X4_UNORM_4PACK16
    G12X4B12X4G12X4R12X4_422_UNORM_4PACK16 B12X4G12X4R12X4G12X4_422_UNORM_4PACK16
    G16B16G16R16_422_UNORM B16G16R16G16_422_UNORM
    A4R4G4B4_UNORM_PACK16 A4B4G4R4_UNORM_PACK16
    ASTC_4x4_SFLOAT_BLOCK ASTC_5x4_SFLOAT_BLOCK ASTC_5x5_SFLOAT_BLOCK ASTC_6x5_SFLOAT_BLOCK
    ASTC_6x6_SFLOAT_BLOCK ASTC_8x5_SFLOAT_BLOCK ASTC_8x6_SFLOAT_BLOCK ASTC_8x8_SFLOAT_BLOCK
    ASTC_10x5_SFLOAT_BLOCK ASTC_10x6_SFLOAT_BLOCK ASTC_10x8_SFLOAT_BLOCK
    ASTC_10x10_SFLOAT_BLOCK ASTC_12x10_SFLOAT_BLOCK ASTC_12x12_SFLOAT_BLOCK
"""
)

# vk names the project's configs and passes use
PROJECT_VK_NAMES = [
    "VK_FORMAT_B8G8R8A8_UNORM",
    "VK_FORMAT_R16G16_SFLOAT",
    "VK_FORMAT_D32_SFLOAT",
    "VK_FORMAT_R16G16B16A16_SFLOAT",
    "VK_FORMAT_B10G11R11_UFLOAT_PACK32",
    "VK_FORMAT_R32_UINT",
    "VK_FORMAT_R32_SFLOAT",
]


# --- coverage -------------------------------------------------------------


def test_wgpu_constant_is_complete_and_unique() -> None:
    assert len(WGPU_032_TEXTURE_FORMATS) == 101
    assert len(set(WGPU_032_TEXTURE_FORMATS)) == 101


@pytest.mark.parametrize("name", WGPU_032_TEXTURE_FORMATS)
def test_every_wgpu_032_format_is_known(name: str) -> None:
    info = FORMATS[name]
    assert info.name == name
    assert info.wgpu == name


def test_wgpu_names_are_exactly_the_032_list() -> None:
    wgpu_names = {n for n in FORMATS if not n.startswith("VK_FORMAT_")}
    assert wgpu_names == set(WGPU_032_TEXTURE_FORMATS)


def test_matches_installed_wgpu() -> None:
    wgpu = pytest.importorskip("wgpu")
    installed = {
        getattr(wgpu.TextureFormat, attr)
        for attr in dir(wgpu.TextureFormat)
        if not attr.startswith("_")
    }
    installed = {v for v in installed if isinstance(v, str)}
    missing = installed - set(FORMATS)
    assert not missing, f"formats in installed wgpu but not in the table: {sorted(missing)}"


def test_every_vk13_core_format_is_known() -> None:
    assert len(VK13_CORE_FORMATS) == len(set(VK13_CORE_FORMATS)) == 214
    vk_names = {n for n in FORMATS if n.startswith("VK_FORMAT_")}
    assert vk_names == {"VK_FORMAT_" + n for n in VK13_CORE_FORMATS}


def test_vk_names_exist_in_vulkan_package() -> None:
    try:
        import vulkan  # needs the vulkan loader at import time
    except Exception:
        pytest.skip("vulkan package not importable")
    for name in FORMATS:
        if name.startswith("VK_FORMAT_"):
            assert hasattr(vulkan, name), name


@pytest.mark.parametrize("name", PROJECT_VK_NAMES)
def test_project_vk_names_load(name: str) -> None:
    info = format_info(name)
    assert info.name == name
    assert info.vk == name
    assert format_info(name.removeprefix("VK_FORMAT_").lower()) is info


# --- table consistency ----------------------------------------------------


def test_table_is_read_only() -> None:
    with pytest.raises(TypeError):
        FORMATS["foo"] = FORMATS["r8unorm"]  # type: ignore[index]
    with pytest.raises(dataclasses.FrozenInstanceError):
        FORMATS["r8unorm"].block_bytes = 2  # type: ignore[misc]


@pytest.mark.parametrize("name", sorted(FORMATS))
def test_entry_invariants(name: str) -> None:
    info = FORMATS[name]
    assert isinstance(info, FormatInfo)
    assert info.name == name
    assert info.kind in KINDS
    assert info.block_bytes >= 1 and info.components >= 1
    if info.compressed:
        assert (info.block_width, info.block_height) != (1, 1)
        assert not (info.depth or info.stencil)
    if info.depth or info.stencil:
        expected = (
            "depth-stencil"
            if info.depth and info.stencil
            else ("depth" if info.depth else "stencil")
        )
        assert info.kind == expected
        assert info.components == int(info.depth) + int(info.stencil)
    else:
        assert info.kind not in {"depth", "stencil", "depth-stencil"}
    # srgb shows up in the name in both spellings
    assert info.srgb == ("srgb" in name.lower())
    # equivalents point back at each other and agree on everything but names
    if info.vk is not None and info.vk != name:
        other = FORMATS[info.vk]
        assert other.wgpu == name
        strip = {"name": "", "vk": None, "wgpu": None}
        assert dataclasses.replace(other, **strip) == dataclasses.replace(info, **strip)
    if info.wgpu is not None and info.wgpu != name:
        assert FORMATS[info.wgpu].vk == name


@pytest.mark.parametrize(
    ("name", "nbytes", "bw", "bh"),
    [
        ("rgba8unorm", 4, 1, 1),
        ("rgba16float", 8, 1, 1),
        ("rgba32float", 16, 1, 1),
        ("r16unorm", 2, 1, 1),
        ("rgb9e5ufloat", 4, 1, 1),
        ("rg11b10ufloat", 4, 1, 1),
        ("rgb10a2uint", 4, 1, 1),
        ("stencil8", 1, 1, 1),
        ("depth16unorm", 2, 1, 1),
        ("depth24plus", 4, 1, 1),
        ("depth24plus-stencil8", 4, 1, 1),
        ("depth32float", 4, 1, 1),
        ("depth32float-stencil8", 8, 1, 1),
        ("bc1-rgba-unorm", 8, 4, 4),
        ("bc4-r-snorm", 8, 4, 4),
        ("bc6h-rgb-float", 16, 4, 4),
        ("bc7-rgba-unorm-srgb", 16, 4, 4),
        ("etc2-rgb8unorm", 8, 4, 4),
        ("etc2-rgb8a1unorm", 8, 4, 4),
        ("etc2-rgba8unorm", 16, 4, 4),
        ("eac-r11unorm", 8, 4, 4),
        ("eac-rg11snorm", 16, 4, 4),
        ("astc-12x10-unorm", 16, 12, 10),
        ("VK_FORMAT_R4G4_UNORM_PACK8", 1, 1, 1),
        ("VK_FORMAT_R5G6B5_UNORM_PACK16", 2, 1, 1),
        ("VK_FORMAT_R8G8B8_SRGB", 3, 1, 1),
        ("VK_FORMAT_R16G16B16_SFLOAT", 6, 1, 1),
        ("VK_FORMAT_R64G64B64A64_SFLOAT", 32, 1, 1),
        ("VK_FORMAT_A2R10G10B10_SNORM_PACK32", 4, 1, 1),
        ("VK_FORMAT_B10G11R11_UFLOAT_PACK32", 4, 1, 1),
        ("VK_FORMAT_E5B9G9R9_UFLOAT_PACK32", 4, 1, 1),
        ("VK_FORMAT_D16_UNORM", 2, 1, 1),
        ("VK_FORMAT_X8_D24_UNORM_PACK32", 4, 1, 1),
        ("VK_FORMAT_S8_UINT", 1, 1, 1),
        ("VK_FORMAT_D24_UNORM_S8_UINT", 4, 1, 1),
        ("VK_FORMAT_D32_SFLOAT_S8_UINT", 8, 1, 1),
        ("VK_FORMAT_BC1_RGB_UNORM_BLOCK", 8, 4, 4),
        ("VK_FORMAT_BC2_UNORM_BLOCK", 16, 4, 4),
        ("VK_FORMAT_BC3_SRGB_BLOCK", 16, 4, 4),
        ("VK_FORMAT_BC5_UNORM_BLOCK", 16, 4, 4),
        ("VK_FORMAT_ASTC_10x8_SFLOAT_BLOCK", 16, 10, 8),
        ("VK_FORMAT_A4B4G4R4_UNORM_PACK16", 2, 1, 1),
        ("VK_FORMAT_G8B8G8R8_422_UNORM", 4, 2, 1),
        ("VK_FORMAT_R10X6G10X6B10X6A10X6_UNORM_4PACK16", 8, 1, 1),
    ],
)
def test_block_sizes(name: str, nbytes: int, bw: int, bh: int) -> None:
    info = format_info(name)
    assert (info.block_bytes, info.block_width, info.block_height) == (nbytes, bw, bh)


def test_astc_blocks_are_16_bytes_with_footprint_from_name() -> None:
    astc = [n for n in FORMATS if "astc" in n.lower()]
    assert len(astc) == 28 + 42  # 28 wgpu + 3 x 14 vk
    for name in astc:
        info = FORMATS[name]
        dims = name.lower().split("astc")[1].strip("-_").split("-")[0].split("_")[0]
        w, h = (int(v) for v in dims.split("x"))
        assert (info.block_bytes, info.block_width, info.block_height) == (16, w, h)
        assert info.compressed


def test_aspects_and_kinds() -> None:
    d24s8 = format_info("VK_FORMAT_D24_UNORM_S8_UINT")
    assert (d24s8.depth, d24s8.stencil, d24s8.kind, d24s8.components) == (
        True,
        True,
        "depth-stencil",
        2,
    )
    s8 = format_info("stencil8")
    assert (s8.depth, s8.stencil, s8.kind) == (False, True, "stencil")
    d32 = format_info("depth32float")
    assert (d32.depth, d32.stencil, d32.kind) == (True, False, "depth")
    assert format_info("rgba16float").kind == "float"
    assert format_info("rg11b10ufloat").kind == "ufloat"
    assert format_info("bc6h-rgb-ufloat").kind == "ufloat"
    assert format_info("VK_FORMAT_ASTC_4x4_SFLOAT_BLOCK").kind == "float"
    assert format_info("VK_FORMAT_R8_USCALED").kind == "uscaled"
    srgb = format_info("bgra8unorm-srgb")
    assert (srgb.kind, srgb.srgb) == ("unorm", True)
    assert format_info("rgba8snorm").kind == "snorm"
    assert format_info("r32uint").kind == "uint"
    assert format_info("rg8sint").kind == "sint"


# --- equivalence ----------------------------------------------------------

EQUIVALENTS = [
    ("rgba8unorm", "VK_FORMAT_R8G8B8A8_UNORM"),
    ("rgba8unorm-srgb", "VK_FORMAT_R8G8B8A8_SRGB"),
    ("bgra8unorm", "VK_FORMAT_B8G8R8A8_UNORM"),
    ("rg16float", "VK_FORMAT_R16G16_SFLOAT"),
    ("rgba16float", "VK_FORMAT_R16G16B16A16_SFLOAT"),
    ("r32uint", "VK_FORMAT_R32_UINT"),
    ("r32float", "VK_FORMAT_R32_SFLOAT"),
    ("rg11b10ufloat", "VK_FORMAT_B10G11R11_UFLOAT_PACK32"),
    ("rgb9e5ufloat", "VK_FORMAT_E5B9G9R9_UFLOAT_PACK32"),
    ("rgb10a2unorm", "VK_FORMAT_A2B10G10R10_UNORM_PACK32"),
    ("depth32float", "VK_FORMAT_D32_SFLOAT"),
    ("depth16unorm", "VK_FORMAT_D16_UNORM"),
    ("stencil8", "VK_FORMAT_S8_UINT"),
    ("depth32float-stencil8", "VK_FORMAT_D32_SFLOAT_S8_UINT"),
    ("bc1-rgba-unorm-srgb", "VK_FORMAT_BC1_RGBA_SRGB_BLOCK"),
    ("bc6h-rgb-float", "VK_FORMAT_BC6H_SFLOAT_BLOCK"),
    ("etc2-rgb8a1unorm", "VK_FORMAT_ETC2_R8G8B8A1_UNORM_BLOCK"),
    ("eac-rg11unorm", "VK_FORMAT_EAC_R11G11_UNORM_BLOCK"),
    ("astc-6x5-unorm-srgb", "VK_FORMAT_ASTC_6x5_SRGB_BLOCK"),
]


@pytest.mark.parametrize(("wgpu_name", "vk_name"), EQUIVALENTS)
def test_vk_wgpu_equivalence_both_ways(wgpu_name: str, vk_name: str) -> None:
    assert format_info(wgpu_name).vk == vk_name
    assert format_info(vk_name).wgpu == wgpu_name
    assert canonical(wgpu_name) == canonical(vk_name) == vk_name


def test_every_wgpu_name_except_depth24plus_has_a_vk_equivalent() -> None:
    without = {n for n in WGPU_032_TEXTURE_FORMATS if FORMATS[n].vk is None}
    assert without == {"depth24plus", "depth24plus-stencil8"}


def test_vk_only_formats_have_no_wgpu_name() -> None:
    for name in ("VK_FORMAT_R8G8B8_UNORM", "VK_FORMAT_R64_SFLOAT", "VK_FORMAT_X8_D24_UNORM_PACK32"):
        assert format_info(name).wgpu is None
        assert canonical(name) == name


def test_canonical() -> None:
    assert canonical("rgba8unorm") == canonical("VK_FORMAT_R8G8B8A8_UNORM")
    assert canonical("r8g8b8a8_unorm") == "VK_FORMAT_R8G8B8A8_UNORM"
    assert canonical("rgba8unorm") != canonical("rgba8unorm-srgb")
    assert canonical("rgba8unorm") != canonical("bgra8unorm")
    # implementation-defined depth formats never alias a fixed vk format
    assert canonical("depth24plus") == "depth24plus"
    assert canonical("depth24plus-stencil8") == "depth24plus-stencil8"
    assert canonical("depth24plus") != canonical("VK_FORMAT_X8_D24_UNORM_PACK32")
    assert canonical("depth24plus-stencil8") != canonical("VK_FORMAT_D24_UNORM_S8_UINT")


def test_canonical_groups_have_two_members_at_most() -> None:
    groups: dict[str, list[str]] = {}
    for name in FORMATS:
        groups.setdefault(canonical(name), []).append(name)
    assert max(len(g) for g in groups.values()) == 2
    assert len(groups) == len(FORMATS) - 99  # 99 wgpu names share a vk entry


# --- lookup ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ("r16g16_sfloat", "VK_FORMAT_R16G16_SFLOAT"),
        ("R16G16_SFLOAT", "VK_FORMAT_R16G16_SFLOAT"),
        ("vk_format_r16g16_sfloat", "VK_FORMAT_R16G16_SFLOAT"),
        ("astc_4x4_srgb_block", "VK_FORMAT_ASTC_4x4_SRGB_BLOCK"),
        ("VK_FORMAT_ASTC_4X4_SRGB_BLOCK", "VK_FORMAT_ASTC_4x4_SRGB_BLOCK"),
        ("RGBA8UNORM", "rgba8unorm"),
        ("rgba8unorm", "rgba8unorm"),
    ],
)
def test_lookup_is_case_and_prefix_insensitive(query: str, expected: str) -> None:
    assert format_info(query).name == expected


def test_unknown_format_suggests_close_matches() -> None:
    with pytest.raises(UnknownFormatError) as excinfo:
        format_info("rgba8unrom")
    message = str(excinfo.value)
    assert message.startswith("unknown format 'rgba8unrom' (did you mean 'rgba8unorm'")
    assert message.endswith("?)")
    assert message.count("'") <= 2 * 4  # the name plus three suggestions at most
    assert isinstance(excinfo.value, ValueError)


def test_unknown_vk_format_suggests_vk_name() -> None:
    with pytest.raises(UnknownFormatError, match=r"did you mean 'VK_FORMAT_R16G16_SFLOAT'"):
        format_info("r16g16_sflot")


def test_unknown_format_without_suggestion() -> None:
    with pytest.raises(UnknownFormatError) as excinfo:
        format_info("zzzzzzzz")
    assert str(excinfo.value) == "unknown format 'zzzzzzzz'"


def test_non_string_name() -> None:
    with pytest.raises(TypeError):
        format_info(37)  # type: ignore[arg-type]


# --- sizes ----------------------------------------------------------------


def test_image_bytes_known_values() -> None:
    assert image_bytes("rgba8unorm", 1920, 1080) == 8294400
    # 5x5 texels -> 2x2 blocks of 8 bytes
    assert image_bytes("bc1-rgba-unorm", 5, 5) == 4 * 8
    # 13x11 astc-6x5 -> ceil(13/6)=3 by ceil(11/5)=3 blocks of 16 bytes
    assert image_bytes("astc-6x5-unorm", 13, 11) == 3 * 3 * 16
    assert image_bytes("astc-6x5-unorm", 12, 10) == 2 * 2 * 16
    # full chain of 4x4 rgba8: 4x4 + 2x2 + 1x1 texels
    assert image_bytes("rgba8unorm", 4, 4, mips=3) == 64 + 16 + 4 == 84
    assert image_bytes("VK_FORMAT_R16G16B16A16_SFLOAT", 2, 2) == 32
    assert image_bytes("VK_FORMAT_G8B8G8R8_422_UNORM", 5, 2) == 3 * 2 * 4


def test_image_bytes_layers_and_samples_multiply() -> None:
    base = image_bytes("rgba16float", 640, 480, mips=4)
    assert image_bytes("rgba16float", 640, 480, mips=4, layers=6) == 6 * base
    assert image_bytes("rgba16float", 640, 480, mips=4, samples=4) == 4 * base
    assert image_bytes("rgba16float", 640, 480, mips=4, layers=3, samples=8) == 24 * base


def test_image_bytes_mip_chain_of_compressed_and_non_square() -> None:
    # bc7 256x64, full chain of 9: every level at least one 16-byte block
    levels = [(256 >> m or 1, 64 >> m or 1) for m in range(9)]
    expected = sum(-(-w // 4) * -(-h // 4) * 16 for w, h in levels)
    assert image_bytes("bc7-rgba-unorm", 256, 64, mips=9) == expected
    # non-square rgba8 1x8 full chain: 8 + 4 + 2 + 1 texels
    assert image_bytes("rgba8unorm", 1, 8, mips=4) == (8 + 4 + 2 + 1) * 4


def test_image_bytes_accepts_any_lookup_spelling() -> None:
    assert image_bytes("r32_sfloat", 10, 10) == image_bytes("r32float", 10, 10) == 400


@pytest.mark.parametrize(
    "kwargs",
    [
        {"width": 0, "height": 4},
        {"width": 4, "height": 0},
        {"width": -1, "height": 4},
        {"width": 4, "height": 4, "mips": 0},
        {"width": 4, "height": 4, "layers": 0},
        {"width": 4, "height": 4, "samples": 0},
        {"width": 4, "height": 4, "samples": -2},
        {"width": 4, "height": 4, "samples": 3},
        {"width": 4, "height": 4, "mips": 4},
        {"width": 1, "height": 1, "mips": 2},
    ],
)
def test_image_bytes_rejects_bad_arguments(kwargs: dict[str, int]) -> None:
    with pytest.raises(ValueError):
        image_bytes("rgba8unorm", **kwargs)


def test_image_bytes_unknown_format() -> None:
    with pytest.raises(UnknownFormatError):
        image_bytes("rgba8", 4, 4)


def test_max_mips() -> None:
    assert max_mips(1, 1) == 1
    assert max_mips(4, 4) == 3
    assert max_mips(1920, 1080) == 11
    assert max_mips(1, 1024) == 11
    assert max_mips(1025, 3) == 11
    assert max_mips(2**40, 1) == 41
    image_bytes("rgba8unorm", 1920, 1080, mips=max_mips(1920, 1080))
    with pytest.raises(ValueError):
        max_mips(0, 4)
    with pytest.raises(ValueError):
        max_mips(4, -4)
