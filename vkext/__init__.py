"""Raw Vulkan for rfw: device, memory (aliased transient heaps), commands and barriers.

The only package that imports ``vulkan``. Importing it never fails: without a loader,
``VkDevice()`` raises :class:`VkUnavailableError`.
"""

from .allocation import DeviceMemory, PlanMismatchError, VkOutOfMemoryError
from .blocks import BlockAllocator
from .buffers import Buffer, staging_buffer
from .commands import (
    BufferBarrier,
    CommandPool,
    ImageBarrier,
    TimestampPool,
    access_flags,
    barrier,
    image_layout,
    label,
    one_time,
    read_buffer,
    read_image,
    record_barriers,
    stage_flags,
    submit,
    upload_buffer,
    upload_image,
)
from .consts import const
from .device import (
    Message,
    VkDevice,
    VkMissingFeatureError,
    VkUnavailableError,
    VkValidationError,
)
from .images import Image, ImageView, UnsupportedFormatError, image_view
from .memory import Heap, TransientMemory, memory_options, plan_heaps, requirements

__all__ = [
    "BlockAllocator", "Buffer", "BufferBarrier", "CommandPool", "DeviceMemory", "Heap",
    "Image", "ImageBarrier", "ImageView", "Message", "PlanMismatchError", "TimestampPool",
    "TransientMemory", "UnsupportedFormatError", "VkDevice", "VkMissingFeatureError",
    "VkOutOfMemoryError", "VkUnavailableError", "VkValidationError", "access_flags",
    "barrier", "const", "image_layout", "image_view", "label", "memory_options", "one_time",
    "plan_heaps", "read_buffer", "read_image", "record_barriers", "requirements",
    "stage_flags", "staging_buffer", "submit", "upload_buffer", "upload_image",
]
