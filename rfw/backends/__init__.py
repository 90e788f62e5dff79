"""The wgpu backend and what both backends share."""

from .cffi_types import install as _fast_cffi_types

_fast_cffi_types()  # before wgpu-py's FFI makes its first struct (rfw.backends.cffi_types)
