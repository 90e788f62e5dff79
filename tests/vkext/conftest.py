"""One validated VkDevice per module; every test must leave the validation layer silent."""

from __future__ import annotations

import pytest

from vkext import VkDevice, VkUnavailableError


@pytest.fixture(scope="module")
def vk_device():
    try:
        device = VkDevice(validation=True, label="rfw-tests")
    except VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")
    yield device
    device.destroy()
    # leaks show up as messages at vkDestroyDevice / vkDestroyInstance
    device.check_validation()


@pytest.fixture(autouse=True)
def _validation_silent(request):
    yield
    if "vk_device" in request.fixturenames:
        request.getfixturevalue("vk_device").check_validation()


@pytest.fixture
def private_spirv_cache(tmp_path, monkeypatch):
    """A SPIR-V cache of the test's own: shaders compile afresh, nothing shared is touched."""
    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
