"""Recording and submitting commands: barriers from rfw states, command pools and one-time
submits, debug labels, timestamps, uploads and readbacks.

Modules: :mod:`.barriers` (synchronization2 names, :func:`barrier`, :func:`record_barriers`),
:mod:`.pools` (:class:`CommandPool`, :func:`submit`, :func:`one_time`), :mod:`.labels`,
:mod:`.timestamps` (:class:`TimestampPool`), :mod:`.transfers` (recorded copies, ``upload_*``
and ``read_*``).
"""

from .barriers import (
    GLOBAL,
    NONE,
    BufferBarrier,
    ImageBarrier,
    access_flags,
    as_state,
    barrier,
    image_layout,
    record_barriers,
    stage_flags,
)
from .labels import begin_label, end_label, label
from .pools import FENCE_TIMEOUT_NS, CommandPool, one_time, submit
from .timestamps import TimestampPool
from .transfers import (
    ANY_ACCESS,
    COPY_READ,
    COPY_WRITE,
    HOST_READ,
    TRANSFER_DST,
    TRANSFER_SRC,
    copy_buffer_to_image,
    copy_image_out,
    copy_image_to_buffer,
    copy_into_buffers,
    copy_into_uniforms,
    copy_to_host,
    read_buffer,
    read_image,
    readback_bytes,
    record_image_bands,
    record_upload,
    texels,
    upload_buffer,
    upload_image,
    written_for_host,
)

__all__ = [
    "ANY_ACCESS",
    "COPY_READ",
    "COPY_WRITE",
    "FENCE_TIMEOUT_NS",
    "GLOBAL",
    "HOST_READ",
    "NONE",
    "TRANSFER_DST",
    "TRANSFER_SRC",
    "BufferBarrier",
    "CommandPool",
    "ImageBarrier",
    "TimestampPool",
    "access_flags",
    "as_state",
    "barrier",
    "begin_label",
    "copy_buffer_to_image",
    "copy_image_out",
    "copy_image_to_buffer",
    "copy_into_buffers",
    "copy_into_uniforms",
    "copy_to_host",
    "end_label",
    "image_layout",
    "label",
    "one_time",
    "read_buffer",
    "read_image",
    "readback_bytes",
    "record_barriers",
    "record_image_bands",
    "record_upload",
    "stage_flags",
    "submit",
    "texels",
    "upload_buffer",
    "upload_image",
    "written_for_host",
]
