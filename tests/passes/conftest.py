"""One wgpu device for the pass tests (they also run on their own, without tests/conftest.py)."""

import pytest


@pytest.fixture(scope="session")
def device():
    from rfw.backends.wgpu import Device

    return Device()


@pytest.fixture(scope="module")
def vk_device(request):
    """A validated VkDevice per module (the validation layer must stay silent), for the
    tests that render on both backends through ``backend``."""
    from vkext import VkDevice, VkUnavailableError

    try:
        device = VkDevice(validation=True, label=f"rfw-tests:{request.module.__name__}")
    except VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")
    yield device
    device.destroy()
    device.check_validation()


@pytest.fixture(params=["wgpu", "vk"])
def backend(request, device):
    """``(name, device)`` of each backend in turn."""
    if request.param == "wgpu":
        return "wgpu", device
    return "vk", request.getfixturevalue("vk_device")
