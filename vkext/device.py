"""``VkDevice``: instance, validation, physical device choice, features, queue and caps.

One object owns the instance, the debug messenger, the logical device and everything other
vkext objects register with it; ``destroy()`` tears them down in reverse order, so that the
validation layer's leak report at ``vkDestroyDevice``/``vkDestroyInstance`` stays empty.
Its ~720 lines are that one object's set-up: the feature chains, the extension command
table and the capability probes depend on each other in the order they run.
"""

from __future__ import annotations

import itertools
import threading
import warnings
from collections import Counter
from types import SimpleNamespace
from typing import Any, NamedTuple

from rfw import env
from rfw.backend import fake_uuid, pick_gpu
from rfw.errors import RfwError

from .consts import IMPORT_ERROR, VALUE_RETURNING, call_api, const, ffi, lib, vk

API_VERSION = (1 << 22) | (3 << 12)  # VK_MAKE_API_VERSION(0, 1, 3, 0)
VALIDATION_LAYER = "VK_LAYER_KHRONOS_validation"


class VkUnavailableError(RfwError, RuntimeError):
    """No usable Vulkan: no loader, no driver, or no device that does Vulkan 1.3."""


class VkMissingFeatureError(RfwError, RuntimeError):
    """The device lacks a capability an operation needs."""


class VkValidationError(AssertionError):
    """The validation layer reported messages (listed in the exception text)."""

    def __init__(self, messages: list[Message]):
        self.messages = list(messages)
        lines = "\n".join(f"  [{m.severity} {m.type}] {m.text}" for m in self.messages)
        super().__init__(f"{len(self.messages)} validation message(s):\n{lines}")


class Message(NamedTuple):
    severity: str  # "error" | "warning" | "info" | "verbose"
    type: str  # "validation" | "performance" | "general"
    text: str


# device extensions vkext knows how to enable: the feature that makes each usable, and the
# extensions it needs in turn (1.2/1.3 core covers spirv_1_4, buffer device address, ...)
EXTENSIONS: dict[str, tuple[str | None, str | None, tuple[str, ...]]] = {
    "VK_KHR_deferred_host_operations": (None, None, ()),
    "VK_KHR_acceleration_structure": ("VkPhysicalDeviceAccelerationStructureFeaturesKHR",
                                      "accelerationStructure",
                                      ("VK_KHR_deferred_host_operations",)),
    "VK_KHR_ray_query": ("VkPhysicalDeviceRayQueryFeaturesKHR", "rayQuery",
                         ("VK_KHR_acceleration_structure",)),
    "VK_KHR_ray_tracing_pipeline": ("VkPhysicalDeviceRayTracingPipelineFeaturesKHR",
                                    "rayTracingPipeline", ("VK_KHR_acceleration_structure",)),
    "VK_EXT_mesh_shader": ("VkPhysicalDeviceMeshShaderFeaturesEXT", "meshShader", ()),
    # memory CUDA maps without a copy (vkext.external)
    "VK_KHR_external_memory_fd": (None, None, ()),
}

# features enabled when the device has them; anything with a cost or a dependency on an
# extension vkext does not enable (robustness, capture replay, shading rate, multiview mesh)
# stays off
WANTED: dict[str, tuple[str, ...]] = {
    "VkPhysicalDeviceFeatures": (
        "fullDrawIndexUint32", "imageCubeArray", "independentBlend", "geometryShader",
        "depthClamp",
        "depthBiasClamp", "fillModeNonSolid", "multiDrawIndirect", "drawIndirectFirstInstance",
        "samplerAnisotropy", "textureCompressionBC", "pipelineStatisticsQuery",
        "vertexPipelineStoresAndAtomics", "fragmentStoresAndAtomics",
        "shaderImageGatherExtended", "shaderStorageImageExtendedFormats",
        "shaderStorageImageReadWithoutFormat", "shaderStorageImageWriteWithoutFormat",
        "shaderUniformBufferArrayDynamicIndexing", "shaderSampledImageArrayDynamicIndexing",
        "shaderStorageBufferArrayDynamicIndexing", "shaderStorageImageArrayDynamicIndexing",
        "shaderFloat64", "shaderInt64", "shaderInt16"),
    "VkPhysicalDeviceVulkan11Features": (
        "storageBuffer16BitAccess", "uniformAndStorageBuffer16BitAccess", "multiview",
        "shaderDrawParameters", "variablePointersStorageBuffer", "variablePointers"),
    "VkPhysicalDeviceVulkan12Features": (
        "samplerMirrorClampToEdge", "drawIndirectCount", "storageBuffer8BitAccess",
        "uniformAndStorageBuffer8BitAccess", "shaderBufferInt64Atomics",
        "shaderSharedInt64Atomics", "shaderFloat16", "shaderInt8", "descriptorIndexing",
        "shaderUniformTexelBufferArrayDynamicIndexing",
        "shaderStorageTexelBufferArrayDynamicIndexing",
        "shaderUniformBufferArrayNonUniformIndexing", "shaderSampledImageArrayNonUniformIndexing",
        "shaderStorageBufferArrayNonUniformIndexing", "shaderStorageImageArrayNonUniformIndexing",
        "descriptorBindingUniformBufferUpdateAfterBind",
        "descriptorBindingSampledImageUpdateAfterBind",
        "descriptorBindingStorageImageUpdateAfterBind",
        "descriptorBindingStorageBufferUpdateAfterBind",
        "descriptorBindingUpdateUnusedWhilePending", "descriptorBindingPartiallyBound",
        "descriptorBindingVariableDescriptorCount", "runtimeDescriptorArray",
        "samplerFilterMinmax", "scalarBlockLayout", "uniformBufferStandardLayout",
        "shaderSubgroupExtendedTypes", "separateDepthStencilLayouts", "hostQueryReset",
        "timelineSemaphore", "bufferDeviceAddress", "vulkanMemoryModel",
        "vulkanMemoryModelDeviceScope", "shaderOutputViewportIndex", "shaderOutputLayer"),
    "VkPhysicalDeviceVulkan13Features": (
        "inlineUniformBlock", "pipelineCreationCacheControl",
        "shaderDemoteToHelperInvocation", "shaderTerminateInvocation", "subgroupSizeControl",
        "computeFullSubgroups", "synchronization2", "shaderZeroInitializeWorkgroupMemory",
        "dynamicRendering", "shaderIntegerDotProduct", "maintenance4"),
    "VkPhysicalDeviceMeshShaderFeaturesEXT": ("taskShader", "meshShader"),
    "VkPhysicalDeviceAccelerationStructureFeaturesKHR": (
        "accelerationStructure", "descriptorBindingAccelerationStructureUpdateAfterBind"),
    "VkPhysicalDeviceRayQueryFeaturesKHR": ("rayQuery",),
    "VkPhysicalDeviceRayTracingPipelineFeaturesKHR": (
        "rayTracingPipeline", "rayTracingPipelineTraceRaysIndirect",
        "rayTraversalPrimitiveCulling"),
}

_STYPE = {
    "VkPhysicalDeviceFeatures2": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2",
    "VkPhysicalDeviceVulkan11Features": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_FEATURES",
    "VkPhysicalDeviceVulkan12Features": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES",
    "VkPhysicalDeviceVulkan13Features": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_3_FEATURES",
    "VkPhysicalDeviceMeshShaderFeaturesEXT":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MESH_SHADER_FEATURES_EXT",
    "VkPhysicalDeviceAccelerationStructureFeaturesKHR":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_FEATURES_KHR",
    "VkPhysicalDeviceRayQueryFeaturesKHR":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_QUERY_FEATURES_KHR",
    "VkPhysicalDeviceRayTracingPipelineFeaturesKHR":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_TRACING_PIPELINE_FEATURES_KHR",
    "VkPhysicalDeviceProperties2": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2",
    "VkPhysicalDeviceVulkan11Properties": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_PROPERTIES",
    "VkPhysicalDeviceVulkan12Properties": "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_PROPERTIES",
    "VkPhysicalDeviceMeshShaderPropertiesEXT":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MESH_SHADER_PROPERTIES_EXT",
    "VkPhysicalDeviceAccelerationStructurePropertiesKHR":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_PROPERTIES_KHR",
    "VkPhysicalDeviceRayTracingPipelinePropertiesKHR":
        "VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_TRACING_PIPELINE_PROPERTIES_KHR",
}

# extension properties worth keeping (the executor sizes dispatches and tables with them)
_EXT_PROPERTIES = {
    "VK_EXT_mesh_shader": ("VkPhysicalDeviceMeshShaderPropertiesEXT", (
        "maxTaskWorkGroupInvocations", "maxTaskWorkGroupSize", "maxTaskWorkGroupCount",
        "maxTaskPayloadSize", "maxMeshWorkGroupInvocations", "maxMeshWorkGroupSize",
        "maxMeshOutputVertices", "maxMeshOutputPrimitives", "maxPreferredTaskWorkGroupInvocations",
        "maxPreferredMeshWorkGroupInvocations")),
    "VK_KHR_acceleration_structure": ("VkPhysicalDeviceAccelerationStructurePropertiesKHR", (
        "maxGeometryCount", "maxInstanceCount", "maxPrimitiveCount",
        "minAccelerationStructureScratchOffsetAlignment")),
    "VK_KHR_ray_tracing_pipeline": ("VkPhysicalDeviceRayTracingPipelinePropertiesKHR", (
        "shaderGroupHandleSize", "maxRayRecursionDepth", "maxShaderGroupStride",
        "shaderGroupBaseAlignment", "shaderGroupHandleAlignment", "maxRayHitAttributeSize")),
}

# extension commands loaded per enabled extension (debug utils ones come from the instance)
COMMANDS: dict[str, tuple[str, ...]] = {
    "VK_EXT_debug_utils": (
        "vkSetDebugUtilsObjectNameEXT", "vkCmdBeginDebugUtilsLabelEXT",
        "vkCmdEndDebugUtilsLabelEXT", "vkCmdInsertDebugUtilsLabelEXT",
        "vkQueueBeginDebugUtilsLabelEXT", "vkQueueEndDebugUtilsLabelEXT",
        "vkCreateDebugUtilsMessengerEXT", "vkDestroyDebugUtilsMessengerEXT"),
    "VK_KHR_external_memory_fd": ("vkGetMemoryFdKHR",),
    "VK_EXT_mesh_shader": ("vkCmdDrawMeshTasksEXT", "vkCmdDrawMeshTasksIndirectEXT",
                           "vkCmdDrawMeshTasksIndirectCountEXT"),
    "VK_KHR_deferred_host_operations": (
        "vkCreateDeferredOperationKHR", "vkDestroyDeferredOperationKHR",
        "vkGetDeferredOperationMaxConcurrencyKHR", "vkGetDeferredOperationResultKHR",
        "vkDeferredOperationJoinKHR"),
    "VK_KHR_acceleration_structure": (
        "vkCreateAccelerationStructureKHR", "vkDestroyAccelerationStructureKHR",
        "vkCmdBuildAccelerationStructuresKHR", "vkGetAccelerationStructureBuildSizesKHR",
        "vkGetAccelerationStructureDeviceAddressKHR", "vkCmdCopyAccelerationStructureKHR",
        "vkCmdWriteAccelerationStructuresPropertiesKHR",
        "vkGetDeviceAccelerationStructureCompatibilityKHR"),
    "VK_KHR_ray_tracing_pipeline": (
        "vkCreateRayTracingPipelinesKHR", "vkGetRayTracingShaderGroupHandlesKHR",
        "vkCmdTraceRaysKHR", "vkCmdTraceRaysIndirectKHR",
        "vkGetRayTracingShaderGroupStackSizeKHR", "vkCmdSetRayTracingPipelineStackSizeKHR"),
}

_DEVICE_TYPES = {  # preference order: lower wins
    "VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU": 0, "VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU": 1,
    "VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU": 2, "VK_PHYSICAL_DEVICE_TYPE_CPU": 3,
}

_LIMITS = ("maxImageDimension2D", "maxImageArrayLayers", "maxMemoryAllocationCount",
           "bufferImageGranularity", "minUniformBufferOffsetAlignment",
           "minStorageBufferOffsetAlignment", "minTexelBufferOffsetAlignment",
           "nonCoherentAtomSize", "optimalBufferCopyOffsetAlignment",
           "optimalBufferCopyRowPitchAlignment", "maxPushConstantsSize",
           "maxComputeSharedMemorySize", "maxComputeWorkGroupInvocations",
           "maxComputeWorkGroupSize", "maxComputeWorkGroupCount", "maxBoundDescriptorSets",
           "maxColorAttachments", "maxSamplerAnisotropy", "timestampComputeAndGraphics",
           "maxStorageBufferRange", "maxUniformBufferRange")


def _str(chars: Any) -> str:
    # the package's enumerate wrappers already hand out str, plain structs char arrays
    return chars if isinstance(chars, str) else ffi.string(chars).decode("utf-8", "replace")


def _version(v: int) -> str:
    return f"{(v >> 22) & 0x7F}.{(v >> 12) & 0x3FF}.{v & 0xFFF}"


def _value(x: Any) -> Any:
    # cffi arrays (work group sizes) become tuples, the rest plain numbers
    if isinstance(x, ffi.CData):
        return tuple(x)
    return x


def _new(struct: str) -> Any:
    p = ffi.new(f"{struct}*")
    p.sType = const(_STYPE[struct])
    return p


def _link(ptrs: list[Any]) -> None:
    for a, b in itertools.pairwise(ptrs):
        a.pNext = b
    if ptrs:
        ptrs[-1].pNext = ffi.NULL


def _handle_int(handle: Any) -> int:
    return int(ffi.cast("uint64_t", handle))


_SEVERITY = {0x1: "verbose", 0x10: "info", 0x100: "warning", 0x1000: "error"}


def _type_name(types: int) -> str:
    names = [n for bit, n in ((4, "performance"), (2, "validation"), (1, "general"))
             if types & bit]
    return "|".join(names) or "general"


if ffi is not None:
    @ffi.callback("PFN_vkDebugUtilsMessengerCallbackEXT")
    def _on_message(severity: int, types: int, data: Any, user: Any) -> int:
        try:
            sink = ffi.from_handle(user)
            text = _str(data.pMessage) if data.pMessage != ffi.NULL else ""
            sink.append(Message(_SEVERITY.get(severity, str(severity)), _type_name(types), text))
        except Exception:  # never raise through the driver
            pass
        return 0  # VK_FALSE: do not abort the call


def physical_uuid(pd: Any) -> str:
    """Vulkan's ``deviceUUID`` of a physical device (``VkPhysicalDeviceIDProperties``), as
    32 lowercase hex digits: the UUID CUDA and NVML name the same GPU by."""
    ids = ffi.new("VkPhysicalDeviceIDProperties*")
    ids.sType = const("VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ID_PROPERTIES")
    head = ffi.new("VkPhysicalDeviceProperties2*")
    head.sType = const("VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2")
    head.pNext = ids
    vk.vkGetPhysicalDeviceProperties2(pd, head)
    return bytes(ffi.buffer(ids.deviceUUID, 16)).hex()


def physical_devices(instance: Any) -> list[tuple[Any, str]]:
    """The instance's physical devices in the driver's order, each with its UUID. With
    ``RFW_FAKE_GPUS=N`` (a test aid): the first one N times, with the synthetic UUIDs
    :func:`rfw.backend.fake_uuid` gives (the driver's own UUID is not theirs)."""
    pds = list(vk.vkEnumeratePhysicalDevices(instance))
    fakes = env.get("RFW_FAKE_GPUS")
    if fakes and pds:
        return [(pds[0], fake_uuid(i)) for i in range(fakes)]
    return [(pd, physical_uuid(pd)) for pd in pds]


def list_devices() -> list[dict[str, Any]]:
    """Every Vulkan device of the machine in the driver's order: ``index``, ``name``,
    ``kind`` (``gpu`` or ``cpu``) and ``uuid``, from an instance made for the look."""
    if vk is None:
        raise VkUnavailableError(f"the Vulkan loader could not be loaded ({IMPORT_ERROR})")
    app = ffi.new("VkApplicationInfo*")
    app.sType = const("VK_STRUCTURE_TYPE_APPLICATION_INFO")
    app.apiVersion = API_VERSION
    info = ffi.new("VkInstanceCreateInfo*")
    info.sType = const("VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO")
    info.pApplicationInfo = app
    try:
        instance = vk.vkCreateInstance(info, None)
    except vk.VkError as e:
        raise VkUnavailableError(f"vkCreateInstance failed ({type(e).__name__}): no usable "
                                 "Vulkan driver is installed") from None
    try:
        out = []
        for index, (pd, uuid) in enumerate(physical_devices(instance)):
            props = vk.vkGetPhysicalDeviceProperties(pd)
            cpu = props.deviceType == vk.VK_PHYSICAL_DEVICE_TYPE_CPU
            out.append({"index": index, "name": _str(props.deviceName),
                        "kind": "cpu" if cpu else "gpu", "uuid": uuid})
        return out
    finally:
        vk.vkDestroyInstance(instance, None)


def compute_queue_choice(families: list[tuple[int, int, int]], graphics: int,
                         prefer: str = "family") -> tuple[int, int] | None:
    """The second queue for async compute (``rfw.graph.queues``), as (family, index), from
    each family's (queue flags, queue count, timestamp valid bits).

    ``prefer="family"``: a compute-only family first (on NVIDIA and AMD its queues feed
    the compute engines that run beside graphics; the compiler plans the ownership
    transfers), else a second queue of the graphics family. ``prefer="graphics"``: that
    second queue first (no ownership transfers: the scene's buffers, made exclusive, are
    read by both queues), else a compute-only family.
    A compute-only family counts where its timestamps work where the graphics family's
    do (the passes on it are timed). None where there is neither.

    ``prefer`` is the run option ``async_queue`` (``RFW_VK_ASYNC_QUEUE``). Measured on an
    NVIDIA H200 (driver 580.159.04; ``benchmarks/bench_async.py``, deferred_ssao_shadows at
    1280x720, SSAO beside the shadow map): the frame's GPU span with async compute on, over
    off, was 0.988x on the compute-only family and 1.203x on a second queue of the graphics
    family (which shares the graphics engine: no overlap, only the semaphores' cost)."""
    def second() -> tuple[int, int] | None:
        return (graphics, 1) if families[graphics][1] > 1 else None

    def family() -> tuple[int, int] | None:
        bits = families[graphics][2]
        for i, (flags, count, valid) in enumerate(families):
            only = flags & vk.VK_QUEUE_COMPUTE_BIT and not flags & vk.VK_QUEUE_GRAPHICS_BIT
            if only and count > 0 and (valid > 0 or not bits):
                return i, 0
        return None

    first, then = (family, second) if prefer == "family" else (second, family)
    return first() or then()


class VkDevice:
    """A Vulkan 1.3 device with the features and extensions rfw can use.

    Parameters
    ----------
    validation
        Enable ``VK_LAYER_KHRONOS_validation`` and collect its messages in ``messages``.
    sync_validation
        With validation: also enable synchronization validation (hazards between accesses).
    prefer
        Substring of the physical device name to pick; otherwise discrete, integrated,
        virtual, CPU, in that order, first of each.
    extensions
        Further device extensions to enable when present (no features are enabled for them).
    debug_utils
        Enable ``VK_EXT_debug_utils`` (labels, object names); default: with validation.
    gpu
        The device's index among the machine's GPUs (or, with none, its CPU devices), in
        the driver's order (the run option ``gpu``, ``RFW_GPU``); None: as ``prefer`` picks.
    async_queue
        Which second queue async compute takes: ``family`` or ``graphics``
        (:func:`compute_queue_choice`; the run option, ``RFW_VK_ASYNC_QUEUE``).
    """

    def __init__(self, validation: bool = False, sync_validation: bool = True,
                 prefer: str | None = None, *, extensions: tuple[str, ...] = (),
                 debug_utils: bool | None = None, label: str = "rfw",
                 gpu: int | None = None, async_queue: str = "family"):
        if vk is None:
            raise VkUnavailableError(f"the Vulkan loader could not be loaded ({IMPORT_ERROR}); "
                                     "install a Vulkan driver (e.g. Mesa lavapipe) and loader")
        self.messages: list[Message] = []
        self.label = label
        self.gpu, self.async_queue = gpu, async_queue
        self.instance = self.device = self.messenger = None
        self._children: dict[int, Any] = {}  # id -> object with destroy(), creation order
        self._sink = ffi.new_handle(self.messages)
        self._keep: list[Any] = []  # cffi memory that must outlive the calls using it
        self.fn = SimpleNamespace()
        # ray casting on this device (vkext.raycast): its lock, and a raycaster per method
        self.raycast_lock = threading.RLock()
        self.raycasters: dict[str, Any] = {}
        try:
            self._create_instance(validation, sync_validation,
                                  validation if debug_utils is None else debug_utils)
            self._pick_physical_device(prefer)
            self._create_device(tuple(extensions))
        except BaseException:
            self.destroy()
            raise

    # -----------------------------------------------------------------------------------------
    # instance

    def _create_instance(self, validation: bool, sync_validation: bool,
                         debug_utils: bool) -> None:
        try:
            version = vk.vkEnumerateInstanceVersion()
        except Exception as e:  # a 1.0 loader has no such command
            raise VkUnavailableError(f"the Vulkan loader is too old for 1.3 ({e})") from None
        if version < API_VERSION:
            raise VkUnavailableError(f"the Vulkan loader supports {_version(version)}, "
                                     "vkext needs 1.3")
        layers = {_str(p.layerName) for p in vk.vkEnumerateInstanceLayerProperties()}
        available = {_str(e.extensionName)
                     for e in vk.vkEnumerateInstanceExtensionProperties(None)}
        enabled_layers: list[str] = []
        if validation and VALIDATION_LAYER in layers:
            enabled_layers.append(VALIDATION_LAYER)
            available |= {_str(e.extensionName)
                          for e in vk.vkEnumerateInstanceExtensionProperties(VALIDATION_LAYER)}
        elif validation:
            warnings.warn(f"{VALIDATION_LAYER} is not installed: running without validation",
                          RuntimeWarning, stacklevel=3)
        self.validation = bool(enabled_layers)
        self.sync_validation = False
        exts = []
        if (debug_utils or self.validation) and "VK_EXT_debug_utils" in available:
            exts.append("VK_EXT_debug_utils")
        self.debug_utils = "VK_EXT_debug_utils" in exts

        chain: list[Any] = []
        if self.validation and sync_validation and "VK_EXT_validation_features" in available:
            exts.append("VK_EXT_validation_features")
            sync = const("VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT")
            features = ffi.new("VkValidationFeatureEnableEXT[1]", [sync])
            vf = ffi.new("VkValidationFeaturesEXT*")
            vf.sType = const("VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT")
            vf.enabledValidationFeatureCount = 1
            vf.pEnabledValidationFeatures = features
            self._keep += [features, vf]
            chain.append(vf)
            self.sync_validation = True
        messenger_info = None
        if self.validation and self.debug_utils:
            # chained into the instance info too: covers vkCreateInstance/vkDestroyInstance
            messenger_info = ffi.new("VkDebugUtilsMessengerCreateInfoEXT*")
            messenger_info.sType = const("VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT")
            messenger_info.messageSeverity = 0x100 | 0x1000  # warning | error
            messenger_info.messageType = 0x1 | 0x2 | 0x4  # general | validation | performance
            messenger_info.pfnUserCallback = _on_message
            messenger_info.pUserData = self._sink
            self._keep.append(messenger_info)
            chain.append(messenger_info)
        _link(chain)

        app = ffi.new("VkApplicationInfo*")
        app.sType = const("VK_STRUCTURE_TYPE_APPLICATION_INFO")
        name = ffi.new("char[]", self.label.encode())
        engine = ffi.new("char[]", b"rfw.vkext")
        app.pApplicationName, app.pEngineName, app.apiVersion = name, engine, API_VERSION
        layer_names = [ffi.new("char[]", s.encode()) for s in enabled_layers]
        ext_names = [ffi.new("char[]", s.encode()) for s in exts]
        layer_array = ffi.new("char*[]", layer_names)
        ext_array = ffi.new("char*[]", ext_names)
        info = ffi.new("VkInstanceCreateInfo*")
        info.sType = const("VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO")
        info.pNext = chain[0] if chain else ffi.NULL
        info.pApplicationInfo = app
        info.enabledLayerCount, info.ppEnabledLayerNames = len(layer_names), layer_array
        info.enabledExtensionCount, info.ppEnabledExtensionNames = len(ext_names), ext_array
        try:
            self.instance = vk.vkCreateInstance(info, None)
        except vk.VkError as e:
            raise VkUnavailableError(f"vkCreateInstance failed ({type(e).__name__}): no usable "
                                     "Vulkan driver is installed") from None
        self.instance_extensions = tuple(exts)
        if self.debug_utils:
            for cmd in COMMANDS["VK_EXT_debug_utils"]:
                setattr(self.fn, cmd, vk.vkGetInstanceProcAddr(self.instance, cmd))
        if messenger_info is not None:
            self.messenger = self.fn.vkCreateDebugUtilsMessengerEXT(self.instance,
                                                                    messenger_info, None)

    # -----------------------------------------------------------------------------------------
    # physical device

    def _pick_physical_device(self, prefer: str | None) -> None:
        candidates = []
        seen = []
        for index, (pd, uuid) in enumerate(physical_devices(self.instance)):
            props = vk.vkGetPhysicalDeviceProperties(pd)
            name = _str(props.deviceName)
            seen.append(f"{name} (Vulkan {_version(props.apiVersion)})")
            family = self._queue_family(pd)
            if props.apiVersion < API_VERSION or family is None:
                continue
            kind = next((rank for n, rank in _DEVICE_TYPES.items()
                         if props.deviceType == getattr(vk, n)), 4)
            candidates.append((kind, index, pd, name, family, uuid))
        if prefer:
            matches = [c for c in candidates if prefer.lower() in c[3].lower()]
            if not matches:
                raise VkUnavailableError(f"no Vulkan 1.3 device matches '{prefer}'; found: "
                                         + (", ".join(seen) or "none"))
            candidates = matches
        if not candidates:
            raise VkUnavailableError("no Vulkan 1.3 device with a graphics+compute queue; found: "
                                     + (", ".join(seen) or "no devices"))
        pick = min(candidates, key=lambda c: (c[0], c[1]))
        if self.gpu is not None:  # that GPU, in the driver's order, or the one with that UUID
            pick = pick_gpu([("cpu" if c[0] == 3 else "gpu", c) for c in
                             sorted(candidates, key=lambda c: c[1])], self.gpu, ", ".join(seen),
                            uuid_of=lambda c: c[5])
        _, self.index, self.physical_device, self.name, self.queue_family, self.uuid = pick

    @staticmethod
    def _queue_family(pd: Any) -> int | None:
        want = vk.VK_QUEUE_GRAPHICS_BIT | vk.VK_QUEUE_COMPUTE_BIT
        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(pd)
        for i, f in enumerate(families):
            if f.queueFlags & want == want and f.queueCount > 0:
                return i
        return None

    # -----------------------------------------------------------------------------------------
    # queues: the graphics+compute one, and a second that runs compute where there is one

    def _pick_compute_queue(self) -> None:
        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(self.physical_device)
        pick = compute_queue_choice([(f.queueFlags, f.queueCount, f.timestampValidBits)
                                     for f in families], self.queue_family,
                                    self.async_queue)
        self.compute_family, self.compute_index = pick or (None, None)

    def _queue_infos(self) -> tuple[Any, int]:
        self._pick_compute_queue()
        same = self.compute_family == self.queue_family
        priorities = ffi.new("float[2]", [1.0, 1.0])
        count = 1 if self.compute_family is None or same else 2
        infos = ffi.new("VkDeviceQueueCreateInfo[]", count)
        families = [(self.queue_family, 2 if same else 1), (self.compute_family, 1)]
        for info, (family, n) in zip(infos, families[:count], strict=True):
            info.sType = const("VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO")
            info.queueFamilyIndex, info.queueCount = family, n
            info.pQueuePriorities = priorities
        self._keep.append(priorities)
        return infos, count

    # -----------------------------------------------------------------------------------------
    # features, extensions, logical device

    def _feature_chain(self, structs: list[str]) -> tuple[Any, dict[str, Any]]:
        head = _new("VkPhysicalDeviceFeatures2")
        nodes = {s: _new(s) for s in structs}
        _link([head, *nodes.values()])
        return head, nodes

    def _create_device(self, extra: tuple[str, ...]) -> None:
        pd = self.physical_device
        present = {_str(e.extensionName) for e in vk.vkEnumerateDeviceExtensionProperties(pd, None)}
        self.available_extensions = frozenset(present)
        known = [e for e in EXTENSIONS if e in present]
        structs = ["VkPhysicalDeviceVulkan11Features", "VkPhysicalDeviceVulkan12Features",
                   "VkPhysicalDeviceVulkan13Features"]
        structs += [EXTENSIONS[e][0] for e in known if EXTENSIONS[e][0]]
        query, supported = self._feature_chain(structs)
        vk.vkGetPhysicalDeviceFeatures2(pd, query)
        supported["VkPhysicalDeviceFeatures"] = query.features

        # an extension is usable when its key feature is there and its dependencies are
        v12 = supported["VkPhysicalDeviceVulkan12Features"]
        usable: list[str] = []
        for ext in known:
            struct, feature, needs = EXTENSIONS[ext]
            ok = feature is None or bool(getattr(supported[struct], feature))
            if ext == "VK_KHR_acceleration_structure":
                ok = ok and bool(v12.bufferDeviceAddress and v12.descriptorIndexing)
            if ok and all(n in usable for n in needs):
                usable.append(ext)
        enabled_exts = usable + [e for e in extra if e in present and e not in usable]
        missing_extra = [e for e in extra if e not in present]
        if missing_extra:
            warnings.warn(f"{self.name} lacks {', '.join(missing_extra)}", RuntimeWarning,
                          stacklevel=3)

        # enable exactly what is wanted and supported
        enable_structs = structs[:3] + [EXTENSIONS[e][0] for e in usable if EXTENSIONS[e][0]]
        enable, nodes = self._feature_chain(enable_structs)
        nodes["VkPhysicalDeviceFeatures"] = enable.features
        self.features: dict[str, frozenset[str]] = {}
        for struct, node in nodes.items():
            on = [f for f in WANTED.get(struct, ()) if getattr(supported[struct], f)]
            for f in on:
                setattr(node, f, 1)
            self.features[struct] = frozenset(on)
        self._feature_keep = (enable, nodes, query, supported)

        queue_info, queue_count = self._queue_infos()
        ext_names = [ffi.new("char[]", s.encode()) for s in enabled_exts]
        ext_array = ffi.new("char*[]", ext_names)
        info = ffi.new("VkDeviceCreateInfo*")
        info.sType = const("VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO")
        info.pNext = enable
        info.queueCreateInfoCount, info.pQueueCreateInfos = queue_count, queue_info
        info.enabledExtensionCount, info.ppEnabledExtensionNames = len(ext_names), ext_array
        try:
            self.device = vk.vkCreateDevice(pd, info, None)
        except vk.VkError as e:
            raise VkUnavailableError(f"vkCreateDevice failed on {self.name} "
                                     f"({type(e).__name__})") from None
        self.queue = vk.vkGetDeviceQueue(self.device, self.queue_family, 0)
        self.compute_queue = None if self.compute_family is None else \
            vk.vkGetDeviceQueue(self.device, self.compute_family, self.compute_index)
        self.extensions = tuple(enabled_exts)
        for ext in enabled_exts:
            for cmd in COMMANDS.get(ext, ()):
                setattr(self.fn, cmd, self._device_command(cmd))
        self._read_properties(enabled_exts)
        self.caps = self._caps()

    def _device_command(self, name: str) -> Any:
        if name in VALUE_RETURNING:  # the package's wrapper would drop the result
            ptr = lib.vkGetDeviceProcAddr(self.device, name.encode())
            if ptr == ffi.NULL:
                raise VkUnavailableError(f"{self.name} has no {name}")
            raw = ffi.cast(f"PFN_{name}", ptr)
            return lambda *args: call_api(raw, *args)
        return vk.vkGetDeviceProcAddr(self.device, name)

    def _read_properties(self, enabled: list[str]) -> None:
        head = _new("VkPhysicalDeviceProperties2")
        v11 = _new("VkPhysicalDeviceVulkan11Properties")
        v12 = _new("VkPhysicalDeviceVulkan12Properties")
        ext = {e: _new(s) for e, (s, _) in _EXT_PROPERTIES.items() if e in enabled}
        _link([head, v11, v12, *ext.values()])
        vk.vkGetPhysicalDeviceProperties2(self.physical_device, head)
        p = head.properties
        self.api_version = _version(p.apiVersion)
        self.driver_name = _str(v12.driverName)
        self.driver_info = _str(v12.driverInfo)
        self.driver = f"{self.driver_name} {self.driver_info}".strip()
        self.vendor_id, self.device_id = p.vendorID, p.deviceID
        self.device_type = next((n.removeprefix("VK_PHYSICAL_DEVICE_TYPE_").lower()
                                 for n in _DEVICE_TYPES if p.deviceType == getattr(vk, n)),
                                "other")
        self.timestamp_period = float(p.limits.timestampPeriod)
        self.limits = {k: _value(getattr(p.limits, k)) for k in _LIMITS}
        self.limits["maxMemoryAllocationSize"] = int(v11.maxMemoryAllocationSize)
        self.extension_properties = {
            e: {k: _value(getattr(node, k)) for k in _EXT_PROPERTIES[e][1]}
            for e, node in ext.items()}
        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(self.physical_device)
        self.timestamp_bits = int(families[self.queue_family].timestampValidBits)
        mem = vk.vkGetPhysicalDeviceMemoryProperties(self.physical_device)
        self.memory_types = [(int(mem.memoryTypes[i].propertyFlags),
                              int(mem.memoryTypes[i].heapIndex))
                             for i in range(mem.memoryTypeCount)]
        self.memory_heaps = [(int(mem.memoryHeaps[i].size), int(mem.memoryHeaps[i].flags))
                             for i in range(mem.memoryHeapCount)]

    def _caps(self) -> frozenset[str]:
        v12 = self.features["VkPhysicalDeviceVulkan12Features"]
        v13 = self.features["VkPhysicalDeviceVulkan13Features"]
        v10 = self.features["VkPhysicalDeviceFeatures"]
        caps = set(self.extensions)
        named = {"buffer_device_address": "bufferDeviceAddress" in v12,
                 # gl_PrimitiveID in a fragment shader (the visibility buffer) needs it
                 "geometry_shader": "geometryShader" in v10,
                 "descriptor_indexing": "descriptorIndexing" in v12
                 and "runtimeDescriptorArray" in v12,
                 "timeline_semaphore": "timelineSemaphore" in v12,
                 # async compute (rfw.graph.queues): a second queue, of this family or not
                 "compute_queue": self.compute_family == self.queue_family
                 and "timelineSemaphore" in v12,
                 "compute_family": self.compute_family not in (None, self.queue_family)
                 and "timelineSemaphore" in v12,
                 "host_query_reset": "hostQueryReset" in v12,
                 "separate_depth_stencil_layouts": "separateDepthStencilLayouts" in v12,
                 "dynamic_rendering": "dynamicRendering" in v13,
                 "synchronization2": "synchronization2" in v13,
                 "timestamp": self.timestamp_bits > 0
                 and bool(self.limits["timestampComputeAndGraphics"]),
                 "debug_utils": self.debug_utils,
                 "validation": self.validation,
                 "sync_validation": self.sync_validation}
        caps |= {k for k, v in named.items() if v}
        return frozenset(caps)

    # -----------------------------------------------------------------------------------------
    # public helpers

    def describe(self) -> dict[str, Any]:
        """Device, driver and API, in the shape of the wgpu backend's ``describe()``."""
        return {"device": self.name, "driver": self.driver, "api": f"Vulkan {self.api_version}",
                "backend": "vk", "uuid": self.uuid}

    def properties(self) -> dict[str, Any]:
        """Everything vkext read about the device, for reports and benchmark records."""
        return {**self.describe(), "device_type": self.device_type,
                "vendor_id": self.vendor_id, "timestamp_period": self.timestamp_period,
                "timestamp_bits": self.timestamp_bits, "limits": dict(self.limits),
                "memory_types": list(self.memory_types), "memory_heaps": list(self.memory_heaps),
                "extensions": list(self.extensions), "caps": sorted(self.caps),
                "extension_properties": self.extension_properties}

    def require(self, *caps: str) -> None:
        """Raise :class:`VkMissingFeatureError` naming every capability the device lacks."""
        missing = [c for c in caps if c not in self.caps]
        if missing:
            raise VkMissingFeatureError(f"{self.name} lacks {', '.join(missing)} (it has: "
                                        f"{', '.join(sorted(self.caps))})")

    def has(self, feature: str) -> bool:
        """Whether a feature (``"dynamicRendering"``, ``"meshShader"``) was enabled."""
        return any(feature in on for on in self.features.values())

    def set_name(self, handle: Any, object_type: str, label: str) -> None:
        """Name a Vulkan object (``object_type`` like ``"IMAGE"``) for validation messages
        and captures; does nothing without debug utils."""
        if not (self.debug_utils and label and self.device is not None):
            return
        name = ffi.new("char[]", label.encode())
        info = ffi.new("VkDebugUtilsObjectNameInfoEXT*")
        info.sType = const("VK_STRUCTURE_TYPE_DEBUG_UTILS_OBJECT_NAME_INFO_EXT")
        info.objectType = const(f"VK_OBJECT_TYPE_{object_type}")
        info.objectHandle = _handle_int(handle)
        info.pObjectName = name
        self.fn.vkSetDebugUtilsObjectNameEXT(self.device, info)

    def buffer_address(self, buffer: Any) -> int:
        """``vkGetBufferDeviceAddress`` (the package's wrapper drops the address)."""
        info = ffi.new("VkBufferDeviceAddressInfo*")
        info.sType = const("VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO")
        info.buffer = buffer
        return int(lib.vkGetBufferDeviceAddress(self.device, info))

    def wait_idle(self) -> None:
        if self.device is not None:
            vk.vkDeviceWaitIdle(self.device)

    # validation messages

    def check_validation(self, *, clear: bool = True) -> None:
        """Raise :class:`VkValidationError` if the validation layer said anything."""
        if self.messages:
            found = list(self.messages)
            if clear:
                self.messages.clear()
            raise VkValidationError(found)

    # objects created by other vkext modules register here, so destroy() can reach them

    def register(self, obj: Any) -> None:
        self._children[id(obj)] = obj

    def unregister(self, obj: Any) -> None:
        self._children.pop(id(obj), None)

    def live_objects(self) -> Counter[str]:
        """Live vkext objects by class: leak tests compare this against a baseline."""
        return Counter(type(o).__name__ for o in self._children.values())

    def destroy(self) -> None:
        """Destroy everything this device created, children first. Safe to call twice."""
        if self.device is not None:
            vk.vkDeviceWaitIdle(self.device)
            for obj in reversed(list(self._children.values())):
                obj.destroy()
            self._children.clear()
            vk.vkDestroyDevice(self.device, None)
            self.device = None
        if self.messenger is not None:
            self.fn.vkDestroyDebugUtilsMessengerEXT(self.instance, self.messenger, None)
            self.messenger = None
        if self.instance is not None:
            vk.vkDestroyInstance(self.instance, None)
            self.instance = None
        self.fn = SimpleNamespace()

    @property
    def alive(self) -> bool:
        return self.device is not None

    def __enter__(self) -> VkDevice:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.destroy()

    def __repr__(self) -> str:
        state = "" if self.alive else ", destroyed"
        return f"<VkDevice {getattr(self, 'name', '?')} ({getattr(self, 'driver', '?')}{state})>"
