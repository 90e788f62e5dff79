"""One wgpu device for the pass tests (they also run on their own, without tests/conftest.py)."""

import pytest


@pytest.fixture(scope="session")
def device():
    from rfw.backends.wgpu import Device

    return Device()
