"""Vulkan constants the ``vulkan`` package (1.3.275.1) lacks, and the one lookup that uses them.

The package's traps:

* about 490 alias names (``..._KHR``/``..._EXT`` spellings of promoted values) are ``None``;
* 46 core names of promoted extensions are missing (``VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT``,
  ``VK_FORMAT_FEATURE_TRANSFER_SRC_BIT``, ``VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT``, ...);
* about 40 names have *wrong* values, among them ``VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR``,
  ``VK_IMAGE_LAYOUT_FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`` and the default ``sType`` of
  ``VkRayTracingPipelineCreateInfoKHR``/``VkRayTracingShaderGroupCreateInfoKHR`` (pass
  ``sType=const(...)`` explicitly), and five error codes that lost their sign, so the driver's
  real code was missing from the result->exception map (a ``KeyError`` instead of an error);
* ``VK_WHOLE_SIZE`` is -1 (cffi refuses it for a ``VkDeviceSize``);
* wrappers that allocate an output struct leave its ``sType`` 0 (``vkGetDevice*MemoryRequirements``
  with ``VkMemoryRequirements2``): pass your own, with ``sType`` set;
* commands that return a value rather than a VkResult (``vkGetBufferDeviceAddress``) have
  wrappers that drop it: see :data:`VALUE_RETURNING`.

``const(name)`` asks :data:`SPEC` first, then the package; an alias that is ``None`` resolves
through its core name. Values are from the Vulkan registry; a test checks every entry, and
every ``None`` alias, against the enums of the package's own C declarations.

This module also holds the guarded import: without a loader, ``vk`` is ``None`` and
:data:`IMPORT_ERROR` says why, so ``import vkext`` never fails on a machine without Vulkan.
"""

from __future__ import annotations

import re
from typing import Any

try:  # the package dlopens libvulkan at import and raises OSError without a loader
    import vulkan as vk
    from vulkan._vulkan import _callApi as call_api
    from vulkan._vulkan import ffi, lib

    IMPORT_ERROR: BaseException | None = None
except (OSError, ImportError) as e:  # pragma: no cover - exercised in a subprocess test
    vk: Any = None
    ffi: Any = None
    lib: Any = None
    call_api: Any = None
    IMPORT_ERROR = e

# values from the Vulkan registry for names that are None or missing in the package
SPEC: dict[str, int] = {
    # core 1.1/1.2/1.3 names missing from the package
    "VK_BUFFER_CREATE_DEVICE_ADDRESS_CAPTURE_REPLAY_BIT": 0x10,
    "VK_BUFFER_CREATE_PROTECTED_BIT": 0x8,
    "VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT": 0x20000,
    "VK_COMMAND_POOL_CREATE_PROTECTED_BIT": 0x4,
    "VK_DEPENDENCY_DEVICE_GROUP_BIT": 0x4,
    "VK_DEPENDENCY_VIEW_LOCAL_BIT": 0x2,
    "VK_DESCRIPTOR_POOL_CREATE_UPDATE_AFTER_BIND_BIT": 0x2,
    "VK_DESCRIPTOR_SET_LAYOUT_CREATE_UPDATE_AFTER_BIND_POOL_BIT": 0x2,
    "VK_DEVICE_QUEUE_CREATE_PROTECTED_BIT": 0x1,
    "VK_EVENT_CREATE_DEVICE_ONLY_BIT": 0x1,
    "VK_FORMAT_FEATURE_DISJOINT_BIT": 0x400000,
    "VK_FORMAT_FEATURE_SAMPLED_IMAGE_FILTER_MINMAX_BIT": 0x10000,
    "VK_FORMAT_FEATURE_TRANSFER_DST_BIT": 0x8000,
    "VK_FORMAT_FEATURE_TRANSFER_SRC_BIT": 0x4000,
    "VK_FRAMEBUFFER_CREATE_IMAGELESS_BIT": 0x1,
    "VK_IMAGE_ASPECT_PLANE_0_BIT": 0x10,
    "VK_IMAGE_ASPECT_PLANE_1_BIT": 0x20,
    "VK_IMAGE_ASPECT_PLANE_2_BIT": 0x40,
    "VK_IMAGE_CREATE_2D_ARRAY_COMPATIBLE_BIT": 0x20,
    "VK_IMAGE_CREATE_ALIAS_BIT": 0x400,
    "VK_IMAGE_CREATE_BLOCK_TEXEL_VIEW_COMPATIBLE_BIT": 0x80,
    "VK_IMAGE_CREATE_DISJOINT_BIT": 0x200,
    "VK_IMAGE_CREATE_EXTENDED_USAGE_BIT": 0x100,
    "VK_IMAGE_CREATE_PROTECTED_BIT": 0x800,
    "VK_IMAGE_CREATE_SPLIT_INSTANCE_BIND_REGIONS_BIT": 0x40,
    "VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT": 0x2,
    "VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_CAPTURE_REPLAY_BIT": 0x4,
    "VK_MEMORY_HEAP_MULTI_INSTANCE_BIT": 0x2,
    "VK_MEMORY_PROPERTY_PROTECTED_BIT": 0x20,
    "VK_PIPELINE_CACHE_CREATE_EXTERNALLY_SYNCHRONIZED_BIT": 0x1,
    "VK_PIPELINE_CREATE_DISPATCH_BASE_BIT": 0x10,
    "VK_PIPELINE_CREATE_EARLY_RETURN_ON_FAILURE_BIT": 0x200,
    "VK_PIPELINE_CREATE_FAIL_ON_PIPELINE_COMPILE_REQUIRED_BIT": 0x100,
    "VK_PIPELINE_CREATE_VIEW_INDEX_FROM_DEVICE_INDEX_BIT": 0x8,
    "VK_PIPELINE_SHADER_STAGE_CREATE_ALLOW_VARYING_SUBGROUP_SIZE_BIT": 0x1,
    "VK_PIPELINE_SHADER_STAGE_CREATE_REQUIRE_FULL_SUBGROUPS_BIT": 0x2,
    "VK_QUEUE_PROTECTED_BIT": 0x10,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_DRAW_PARAMETER_FEATURES": 1000063000,
    # wrong in the package (it took another extension's number)
    "VK_ERROR_OUT_OF_POOL_MEMORY": -1000069000,
    "VK_ERROR_INVALID_EXTERNAL_HANDLE": -1000072003,
    "VK_ERROR_FRAGMENTATION": -1000161000,
    "VK_ERROR_INVALID_OPAQUE_CAPTURE_ADDRESS": -1000257000,
    "VK_ERROR_NOT_PERMITTED_KHR": -1000174001,
    "VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR": 1000165000,
    "VK_STRUCTURE_TYPE_RAY_TRACING_PIPELINE_CREATE_INFO_KHR": 1000150015,
    "VK_STRUCTURE_TYPE_RAY_TRACING_SHADER_GROUP_CREATE_INFO_KHR": 1000150016,
    "VK_STRUCTURE_TYPE_RAY_TRACING_PIPELINE_INTERFACE_CREATE_INFO_KHR": 1000150018,
    "VK_IMAGE_LAYOUT_FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR": 1000164003,
    "VK_GEOMETRY_INSTANCE_TRIANGLE_FRONT_COUNTERCLOCKWISE_BIT_KHR": 0x2,
    "VK_INDEX_TYPE_NONE_KHR": 1000165000,
    "VK_DESCRIPTOR_TYPE_MUTABLE_EXT": 1000351000,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MUTABLE_DESCRIPTOR_TYPE_FEATURES_EXT": 1000351000,
    "VK_STRUCTURE_TYPE_MUTABLE_DESCRIPTOR_TYPE_CREATE_INFO_EXT": 1000351002,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FRAGMENT_SHADER_BARYCENTRIC_FEATURES_KHR": 1000203000,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RASTERIZATION_ORDER_ATTACHMENT_ACCESS_FEATURES_EXT":
        1000342000,
    "VK_STRUCTURE_TYPE_DEVICE_QUEUE_GLOBAL_PRIORITY_CREATE_INFO_KHR": 1000174000,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_GLOBAL_PRIORITY_QUERY_FEATURES_KHR": 1000388000,
    "VK_STRUCTURE_TYPE_QUEUE_FAMILY_GLOBAL_PRIORITY_PROPERTIES_KHR": 1000388001,
    "VK_QUEUE_GLOBAL_PRIORITY_LOW_EXT": 128,
    "VK_QUEUE_GLOBAL_PRIORITY_MEDIUM_EXT": 256,
    "VK_QUEUE_GLOBAL_PRIORITY_HIGH_EXT": 512,
    "VK_QUERY_SCOPE_COMMAND_BUFFER_KHR": 0,
    "VK_QUERY_SCOPE_RENDER_PASS_KHR": 1,
    "VK_FILTER_CUBIC_EXT": 1000015000,
    "VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_DIVISOR_STATE_CREATE_INFO_KHR": 1000190001,
    "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VERTEX_ATTRIBUTE_DIVISOR_FEATURES_KHR": 1000190002,
    "VK_STRUCTURE_TYPE_CALIBRATED_TIMESTAMP_INFO_KHR": 1000184000,
    "VK_STRUCTURE_TYPE_SUBRESOURCE_LAYOUT_2_KHR": 1000338002,
    "VK_STRUCTURE_TYPE_IMAGE_SUBRESOURCE_2_KHR": 1000338003,
    "VK_STRUCTURE_TYPE_DEVICE_GROUP_PRESENT_CAPABILITIES_KHR": 1000060007,
    "VK_STRUCTURE_TYPE_IMAGE_SWAPCHAIN_CREATE_INFO_KHR": 1000060008,
    "VK_STRUCTURE_TYPE_BIND_IMAGE_MEMORY_SWAPCHAIN_INFO_KHR": 1000060009,
    "VK_STRUCTURE_TYPE_ACQUIRE_NEXT_IMAGE_INFO_KHR": 1000060010,
    "VK_STRUCTURE_TYPE_DEVICE_GROUP_PRESENT_INFO_KHR": 1000060011,
    "VK_STRUCTURE_TYPE_DEVICE_GROUP_SWAPCHAIN_CREATE_INFO_KHR": 1000060012,
    "VK_DEBUG_REPORT_OBJECT_TYPE_SAMPLER_YCBCR_CONVERSION_EXT": 1000156000,
    "VK_DEBUG_REPORT_OBJECT_TYPE_DESCRIPTOR_UPDATE_TEMPLATE_EXT": 1000085000,
    "VK_WHOLE_SIZE": (1 << 64) - 1,  # ~0ULL; the package has -1, which cffi refuses
    # None in the package, and no core spelling to fall back to
    "VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO_INTEL": 1000210000,
    "VK_PIPELINE_COMPILE_REQUIRED": 1000297000,
    "VK_ERROR_VALIDATION_FAILED_EXT": -1000011001,
    "VK_PIPELINE_STAGE_2_TASK_SHADER_BIT_NV": 0x80000,
    "VK_PIPELINE_STAGE_2_MESH_SHADER_BIT_NV": 0x100000,
    "VK_PIPELINE_STAGE_2_RAY_TRACING_SHADER_BIT_NV": 0x200000,
    "VK_PIPELINE_STAGE_2_ACCELERATION_STRUCTURE_BUILD_BIT_NV": 0x2000000,
    "VK_PIPELINE_STAGE_2_SHADING_RATE_IMAGE_BIT_NV": 0x400000,
    "VK_ACCESS_2_ACCELERATION_STRUCTURE_READ_BIT_NV": 0x200000,
    "VK_ACCESS_2_ACCELERATION_STRUCTURE_WRITE_BIT_NV": 0x400000,
    "VK_ACCESS_2_SHADING_RATE_IMAGE_READ_BIT_NV": 0x800000,
    "VK_IMAGE_LAYOUT_SHADING_RATE_OPTIMAL_NV": 1000164003,
    "VK_IMAGE_USAGE_SHADING_RATE_IMAGE_BIT_NV": 0x100,
    "VK_BUFFER_USAGE_RAY_TRACING_BIT_NV": 0x400,
}

# vendor tags that end promoted names: an alias drops one to reach its core spelling
VENDOR_SUFFIXES = ("KHR", "EXT", "NV", "AMD", "INTEL", "ARM", "QCOM", "HUAWEI", "VALVE",
                   "GOOGLE", "NVX", "LUNARG", "MESA", "FB", "SEC", "MSFT", "QNX", "ANDROID")

# commands whose result is a value, not a VkResult: the package's wrappers drop it
VALUE_RETURNING = frozenset({
    "vkGetBufferDeviceAddress", "vkGetBufferOpaqueCaptureAddress",
    "vkGetDeviceMemoryOpaqueCaptureAddress", "vkGetAccelerationStructureDeviceAddressKHR",
    "vkGetDeferredOperationMaxConcurrencyKHR", "vkGetDeferredOperationResultKHR",
    "vkGetRayTracingShaderGroupStackSizeKHR",
})


def const(name: str) -> int:
    """The value of a ``VK_*`` constant, whatever the package did with it."""
    if name in SPEC:
        return SPEC[name]
    if vk is not None:
        value = getattr(vk, name, None)
        if value is not None:
            return value
    head, _, tail = name.rpartition("_")
    if tail in VENDOR_SUFFIXES:  # an alias of a promoted value
        try:
            return const(head)
        except KeyError:
            pass
    raise KeyError(f"unknown Vulkan constant {name} (not in the vulkan package, nor in "
                   "vkext.consts.SPEC: add its value from the registry there)")


def _snake(struct: str) -> str:
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", struct.removeprefix("Vk")).upper()


def new(struct: str, count: int | None = None, **fields: Any) -> Any:
    """``ffi.new`` of a Vulkan struct (or an array of ``count``) with ``sType`` set."""
    stype = const(f"VK_STRUCTURE_TYPE_{_snake(struct)}")
    if count is not None:
        arr = ffi.new(f"{struct}[]", max(1, count))
        for i in range(count):
            arr[i].sType = stype
        return arr
    p = ffi.new(f"{struct}*")
    p.sType = stype
    for k, v in fields.items():
        setattr(p, k, v)
    return p


def flag_name(prefix: str, name: str) -> str:
    """``prefix`` + a synchronization2 short name + ``_BIT``, before any vendor suffix:
    ``("VK_PIPELINE_STAGE_2_", "TASK_SHADER_EXT")`` -> ``..._TASK_SHADER_BIT_EXT``."""
    head, _, tail = name.rpartition("_")
    if head and tail in VENDOR_SUFFIXES:
        return f"{prefix}{head}_BIT_{tail}"
    return f"{prefix}{name}_BIT"


def _complete_result_map() -> None:
    # the wrappers raise exception_codes[result]: a code missing there is a KeyError
    from vulkan._vulkan import exception_codes

    codes = {
        "VK_ERROR_OUT_OF_POOL_MEMORY": "VkErrorOutOfPoolMemory",
        "VK_ERROR_INVALID_EXTERNAL_HANDLE": "VkErrorInvalidExternalHandle",
        "VK_ERROR_FRAGMENTATION": "VkErrorFragmentation",
        "VK_ERROR_INVALID_OPAQUE_CAPTURE_ADDRESS": "VkErrorInvalidOpaqueCaptureAddress",
        "VK_ERROR_NOT_PERMITTED_KHR": "VkErrorNotPermittedKhr",
        "VK_ERROR_VALIDATION_FAILED_EXT": "VkErrorValidationFailedExt",
        "VK_PIPELINE_COMPILE_REQUIRED": "VkPipelineCompileRequired",
    }
    for name, cls in codes.items():
        value = SPEC[name]
        if value in exception_codes:
            continue
        base = vk.VkError if value < 0 else vk.VkException
        exc = getattr(vk, cls, None) or type(cls, (base,), {"__module__": __name__})
        globals()[cls] = exc
        exception_codes[value] = exc


if vk is not None:
    _complete_result_map()
