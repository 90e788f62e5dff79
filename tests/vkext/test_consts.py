"""The constant table against the package's own C declarations, and the sync name mapping."""

from __future__ import annotations

import pytest

from rfw.graph.sync import SHADER_STAGES, state_for
from vkext import access_flags, image_layout, stage_flags
from vkext.consts import SPEC, const, flag_name, lib, vk

pytestmark = pytest.mark.skipif(vk is None, reason="no Vulkan loader")


def test_spec_table_matches_the_c_declarations():
    # the cdef enums come from vulkan.h; VK_WHOLE_SIZE is a #define the cdef lacks
    for name, value in SPEC.items():
        if name == "VK_WHOLE_SIZE":
            assert value == 2**64 - 1
            continue
        assert getattr(lib, name) == value, name


def test_every_none_alias_resolves_to_its_header_value():
    resolved = 0
    for name, value in vars(vk).items():
        if not name.startswith("VK_") or value is not None:
            continue
        try:
            got = const(name)
        except KeyError:
            continue  # aliases nobody needs stay unresolved, loudly
        assert got == getattr(lib, name, got), name
        resolved += 1
    assert resolved > 300


def test_traps_of_the_vulkan_package_are_covered():
    assert vk.VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT_KHR is None
    assert const("VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT_KHR") == 0x20000
    assert const("VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT") == 0x2
    # wrong in the package, right here
    assert vk.VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR != 1000165000
    assert const("VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR") == 1000165000
    assert const("VK_IMAGE_LAYOUT_FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR") == 1000164003
    assert const("VK_WHOLE_SIZE") == 2**64 - 1
    # error codes whose sign the package lost now raise their exception, not KeyError
    from vulkan._vulkan import exception_codes
    assert exception_codes[-1000069000] is vk.VkErrorOutOfPoolMemory
    with pytest.raises(KeyError, match="VK_NOT_A_THING"):
        const("VK_NOT_A_THING")


def test_flag_names_keep_vendor_suffixes_last():
    assert flag_name("VK_PIPELINE_STAGE_2_", "COPY") == "VK_PIPELINE_STAGE_2_COPY_BIT"
    assert flag_name("VK_PIPELINE_STAGE_2_", "TASK_SHADER_EXT") == \
        "VK_PIPELINE_STAGE_2_TASK_SHADER_BIT_EXT"
    assert flag_name("VK_ACCESS_2_", "FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR") == \
        "VK_ACCESS_2_FRAGMENT_SHADING_RATE_ATTACHMENT_READ_BIT_KHR"
    assert stage_flags({"NONE"}) == 0
    assert stage_flags("RAY_TRACING_SHADER_KHR") == \
        vk.VK_PIPELINE_STAGE_2_RAY_TRACING_SHADER_BIT_KHR
    assert stage_flags({"COPY", "TASK_SHADER_EXT"}) == \
        vk.VK_PIPELINE_STAGE_2_COPY_BIT | vk.VK_PIPELINE_STAGE_2_TASK_SHADER_BIT_EXT
    assert access_flags({"SHADER_SAMPLED_READ"}) == vk.VK_ACCESS_2_SHADER_SAMPLED_READ_BIT


def test_every_state_the_compiler_makes_maps_to_vulkan():
    usages = ["sampled", "storage", "color", "depth", "depth_read", "shading_rate", "uniform",
              "indirect", "vertex", "index", "transfer_src", "transfer_dst"]
    for pass_type in SHADER_STAGES:
        for usage in usages:
            for depth, stencil in ((False, False), (True, False), (True, True)):
                s = state_for(usage, pass_type=pass_type, write=True, depth=depth,
                              stencil=stencil)
                assert stage_flags(s.stages) > 0, (usage, pass_type)
                assert access_flags(s.access) > 0
                if s.layout:
                    assert image_layout(s.layout) > 0 or s.layout == "UNDEFINED"
