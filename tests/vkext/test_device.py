"""Device creation, capabilities, properties, validation plumbing and teardown."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from vkext import VkDevice, VkMissingFeatureError, VkUnavailableError, VkValidationError
from vkext.consts import vk

ROOT = Path(__file__).resolve().parents[2]
FOUR = ("VK_EXT_mesh_shader", "VK_KHR_acceleration_structure", "VK_KHR_ray_query",
        "VK_KHR_ray_tracing_pipeline")


def is_lavapipe(device: VkDevice) -> bool:
    return device.driver_name == "llvmpipe"


def test_caps(vk_device):
    caps = vk_device.caps
    for cap in ("buffer_device_address", "timestamp", "dynamic_rendering", "synchronization2",
                "timeline_semaphore", "descriptor_indexing", "validation", "sync_validation",
                "debug_utils"):
        assert cap in caps, cap
    if is_lavapipe(vk_device):
        assert set(FOUR) <= caps
        assert "VK_KHR_deferred_host_operations" in caps
    else:  # other devices: report, do not judge
        print("caps:", sorted(caps))
    # commands of enabled extensions are loaded, and only those
    if "VK_EXT_mesh_shader" in caps:
        assert callable(vk_device.fn.vkCmdDrawMeshTasksEXT)
    if "VK_KHR_ray_tracing_pipeline" in caps:
        assert callable(vk_device.fn.vkCmdTraceRaysKHR)
    assert callable(vk_device.fn.vkCmdBeginDebugUtilsLabelEXT)
    assert vk_device.has("synchronization2") and vk_device.has("bufferDeviceAddress")


def test_properties(vk_device):
    d = vk_device.describe()
    assert d["backend"] == "vk" and d["device"] == vk_device.name
    assert d["api"].startswith("Vulkan 1.")
    major, minor, _ = map(int, vk_device.api_version.split("."))
    assert (major, minor) >= (1, 3)
    assert vk_device.driver_name and vk_device.driver_info
    assert vk_device.timestamp_period > 0
    limits = vk_device.limits
    for key in ("minUniformBufferOffsetAlignment", "bufferImageGranularity",
                "nonCoherentAtomSize", "maxMemoryAllocationSize"):
        value = limits[key]
        assert value > 0, key
    for key in ("minUniformBufferOffsetAlignment", "bufferImageGranularity"):
        assert limits[key] & (limits[key] - 1) == 0  # powers of two
    assert vk_device.memory_types and vk_device.memory_heaps
    assert vk_device.queue is not None
    props = vk_device.properties()
    assert props["caps"] == sorted(vk_device.caps)
    if is_lavapipe(vk_device):
        assert vk_device.device_type == "cpu"
        assert props["extension_properties"]["VK_KHR_ray_tracing_pipeline"][
            "shaderGroupHandleSize"] == 32


def test_value_returning_commands_return_their_value(vk_device):
    # the package's wrapper of vkGetRayTracingShaderGroupStackSizeKHR etc. drops the result;
    # vkext loads those raw. vkGetDeferredOperationMaxConcurrencyKHR needs no pipeline:
    if "VK_KHR_deferred_host_operations" not in vk_device.caps:
        pytest.skip("no deferred host operations")
    op = vk_device.fn.vkCreateDeferredOperationKHR(vk_device.device, None)
    try:
        assert isinstance(vk_device.fn.vkGetDeferredOperationMaxConcurrencyKHR(
            vk_device.device, op), int)
    finally:
        vk_device.fn.vkDestroyDeferredOperationKHR(vk_device.device, op, None)


def test_destroy_leaves_no_leak_messages():
    with VkDevice(validation=True) as device:
        from vkext import Buffer, Image, TimestampPool, one_time

        img = Image(device, 8, 8, "rgba8unorm", {"sampled"}, label="kept")
        img.allocate()
        img.view()
        buf = Buffer(device, 256, {"storage"}, label="kept.buffer")
        buf.allocate()
        TimestampPool(device, 2)
        with one_time(device):
            pass
        assert device.live_objects()["Image"] == 1
    # destroy() ran: children, device, messenger, instance, all reported clean
    assert not device.alive
    assert device.messages == []
    device.destroy()  # twice is fine


def test_a_leak_is_reported():
    # the negative control of the test above: a raw object vkext does not know about
    device = VkDevice(validation=True)
    raw = vk.vkCreateBuffer(device.device, vk.VkBufferCreateInfo(
        size=64, usage=vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT), None)
    device.set_name(raw, "BUFFER", "leaked")
    device.destroy()
    assert any("leaked" in m.text and "has not been destroyed" in m.text
               for m in device.messages)
    with pytest.raises(VkValidationError, match="VUID-vkDestroyDevice-device-00378"):
        device.check_validation()
    assert device.messages == []


def test_prefer_names_the_device(vk_device):
    with pytest.raises(VkUnavailableError, match=r"no Vulkan 1\.3 device matches 'no-such-gpu'"):
        VkDevice(prefer="no-such-gpu")
    with VkDevice(prefer=vk_device.name.split()[0]) as same:
        assert same.name == vk_device.name
        assert not same.validation and "validation" not in same.caps


def test_missing_feature_is_a_clear_error(vk_device):
    with pytest.raises(VkMissingFeatureError, match="lacks VK_NV_imaginary_extension"):
        vk_device.require("VK_NV_imaginary_extension")


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT,
                          env={**os.environ, **env}, capture_output=True, text=True,
                          timeout=60)


def test_no_loader_raises_not_segfaults():
    r = _run("""
        import sys
        sys.modules["vulkan"] = None  # as if libvulkan.so.1 were absent
        import vkext
        try:
            vkext.VkDevice()
        except vkext.VkUnavailableError as e:
            print("unavailable:", e)
    """)
    assert r.returncode == 0, r.stderr
    assert "unavailable: the Vulkan loader could not be loaded" in r.stdout


def test_no_driver_raises_not_segfaults():
    missing = "/nonexistent/icd.json"
    r = _run("""
        import vkext
        try:
            vkext.VkDevice(validation=True)
        except vkext.VkUnavailableError as e:
            print("unavailable:", e)
    """, VK_ICD_FILENAMES=missing, VK_DRIVER_FILES=missing)
    assert r.returncode == 0, r.stderr
    assert "unavailable:" in r.stdout
