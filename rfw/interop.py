"""Arrays shared with PyTorch, CuPy and JAX: :class:`DeviceArray`, the CUDA driver through
ctypes (:func:`cuda`), and reading what callers hand in (:func:`device_view`).

A :class:`DeviceArray` is either a view of GPU memory that Vulkan exported and CUDA imported
(``zero_copy`` True, ``device`` ``"cuda:N"``: ``__cuda_array_interface__`` v3 and a CUDA
``__dlpack__``), or, where no CUDA device shares memory with the Vulkan device (lavapipe, the
wgpu backend, no ``libcuda.so.1``), a numpy array behind the same face (``zero_copy`` False,
``device`` ``"cpu"``: a CPU ``__dlpack__``, no ``__cuda_array_interface__``). Either way
``torch.from_dlpack(a)``, ``cupy.asarray(a)`` (CUDA) or ``numpy.from_dlpack(a)`` (CPU) take it
without a copy, and the memory stays alive as long as any of them holds it.

Ordering: a zero-copy array is handed out after the GPU work writing it finished (a Vulkan
fence the host waited on), so any CUDA stream may read it at once (the interface names no
stream). Device arrays handed *in* are read after ``cuCtxSynchronize``: all work queued on
the caller's context (any stream) lands before Vulkan reads it.

rfw imports no backend here: ``vkext.external`` exports Vulkan memory and calls
:meth:`CudaDriver.import_memory`. Every driver call is checked; a failure raises
:class:`RfwError` naming the call and its ``CUresult``.
"""

from __future__ import annotations

import ctypes
import threading
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import RfwError

# dlpack's device types (dlpack.h)
KDL_CPU, KDL_CUDA = 1, 2
_DL_CODES = {"i": 0, "u": 1, "f": 2}  # kDLInt, kDLUInt, kDLFloat
_CU_POINTER_ATTRIBUTE_MEMORY_TYPE, _CU_POINTER_ATTRIBUTE_DEVICE_ORDINAL = 2, 9
_CU_MEMORYTYPE_DEVICE = 2
_CU_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD = 1
_CUDA_EXTERNAL_MEMORY_DEDICATED = 1

# host copies the arrays of this module made, by kind (a zero-copy pipeline keeps
# device_to_host at 0; benchmarks/bench_zerocopy.py reads it)
copies = {"device_to_host": 0, "host_to_device": 0, "device_to_device": 0}


# ---------------------------------------------------------------------------------------------
# the CUDA driver


class _MemHandle(ctypes.Union):
    _fields_ = [("fd", ctypes.c_int), ("win32", ctypes.c_void_p * 2),
                ("nvSciBufObject", ctypes.c_void_p)]


class _ExternalMemoryHandleDesc(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("handle", _MemHandle), ("size", ctypes.c_ulonglong),
                ("flags", ctypes.c_uint), ("reserved", ctypes.c_uint * 16)]


class _ExternalMemoryBufferDesc(ctypes.Structure):
    _fields_ = [("offset", ctypes.c_ulonglong), ("size", ctypes.c_ulonglong),
                ("flags", ctypes.c_uint), ("reserved", ctypes.c_uint * 16)]


class _Uuid(ctypes.Structure):
    _fields_ = [("bytes", ctypes.c_ubyte * 16)]


class CudaDriver:
    """``libcuda.so.1`` through ctypes: the few calls sharing memory needs, each checked
    (:meth:`call` raises :class:`RfwError` naming the call and the ``CUresult``)."""

    def __init__(self, library: str = "libcuda.so.1"):
        try:
            self.lib = ctypes.CDLL(library)
        except OSError as e:
            raise RfwError(f"CUDA is not available: cannot load {library} ({e})") from None
        self._contexts: dict[int, ctypes.c_void_p] = {}
        self._fns: dict[str, Any] = {}
        self._gathers: dict[int, ctypes.c_void_p] = {}  # the gather kernel, by device
        self._lock = threading.Lock()
        # driver calls by name since load (what a cast costs: benchmarks count them)
        self.calls: dict[str, int] = {}
        self.call("cuInit", ctypes.c_uint(0))

    def call(self, name: str, *args: Any) -> None:
        fn = self._fns.get(name)
        if fn is None:
            fn = getattr(self.lib, name, None)
            if fn is None:
                raise RfwError(f"CUDA: {name} is missing from the driver")
            fn.restype = ctypes.c_int
            self._fns[name] = fn
        self.calls[name] = self.calls.get(name, 0) + 1
        result = fn(*args)
        if result != 0:
            raise RfwError(f"CUDA: {name} failed with CUresult {result} ({self.error(result)})")

    def error(self, result: int) -> str:
        text = ctypes.c_char_p()
        fn = getattr(self.lib, "cuGetErrorName", None)
        if fn is None or fn(ctypes.c_int(result), ctypes.byref(text)) != 0 or not text.value:
            return "unknown"
        return text.value.decode()

    def devices(self) -> int:
        n = ctypes.c_int()
        self.call("cuDeviceGetCount", ctypes.byref(n))
        return n.value

    def uuid(self, ordinal: int) -> bytes:
        dev, uuid = ctypes.c_int(), _Uuid()
        self.call("cuDeviceGet", ctypes.byref(dev), ctypes.c_int(ordinal))
        name = "cuDeviceGetUuid_v2" if hasattr(self.lib, "cuDeviceGetUuid_v2") \
            else "cuDeviceGetUuid"
        self.call(name, ctypes.byref(uuid), dev)
        return bytes(uuid.bytes)

    def ordinal_of_uuid(self, uuid: bytes) -> int | None:
        """The CUDA device whose UUID is Vulkan's ``deviceUUID``, or None."""
        for i in range(self.devices()):
            if self.uuid(i) == bytes(uuid):
                return i
        return None

    def context(self, ordinal: int) -> ctypes.c_void_p:
        """The device's primary context (the one PyTorch and CuPy use), retained once."""
        with self._lock:
            ctx = self._contexts.get(ordinal)
            if ctx is None:
                dev, ctx = ctypes.c_int(), ctypes.c_void_p()
                self.call("cuDeviceGet", ctypes.byref(dev), ctypes.c_int(ordinal))
                self.call("cuDevicePrimaryCtxRetain", ctypes.byref(ctx), dev)
                self._contexts[ordinal] = ctx
            return ctx

    def push(self, ordinal: int) -> _Current:
        """``with driver.push(i):`` calls in device ``i``'s primary context."""
        return _Current(self, ordinal)

    def import_memory(self, fd: int, size: int, ordinal: int) -> tuple[int, int]:
        """Import an opaque fd of a dedicated Vulkan allocation of ``size`` bytes: returns
        (external memory handle, device pointer); CUDA owns ``fd`` from then on."""
        desc = _ExternalMemoryHandleDesc()
        desc.type = _CU_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD
        desc.handle.fd = fd
        desc.size = size
        desc.flags = _CUDA_EXTERNAL_MEMORY_DEDICATED
        ext, ptr = ctypes.c_void_p(), ctypes.c_ulonglong()
        with self.push(ordinal):
            self.call("cuImportExternalMemory", ctypes.byref(ext), ctypes.byref(desc))
            buf = _ExternalMemoryBufferDesc()
            buf.offset, buf.size, buf.flags = 0, size, 0
            try:
                self.call("cuExternalMemoryGetMappedBuffer", ctypes.byref(ptr), ext,
                          ctypes.byref(buf))
            except RfwError:
                self.call("cuDestroyExternalMemory", ext)
                raise
        return int(ext.value), int(ptr.value)

    def free_import(self, ext: int, ptr: int, ordinal: int) -> None:
        with self.push(ordinal):
            self.call("cuMemFree_v2", ctypes.c_ulonglong(ptr))
            self.call("cuDestroyExternalMemory", ctypes.c_void_p(ext))

    def synchronize(self, ordinal: int) -> None:
        with self.push(ordinal):
            self.call("cuCtxSynchronize")

    def gather(self, g: Gather, ordinal: int, stream: int = 0) -> None:
        """Queue ``g`` on ``stream`` of device ``ordinal``'s context (current): a contiguous
        source is one ``cuMemcpyDtoDAsync``, any other one launch of :data:`GATHER_PTX`."""
        if g.rows * g.cols == 0:
            return
        if g.contiguous:
            self.call("cuMemcpyDtoDAsync_v2", ctypes.c_ulonglong(g.dst),
                      ctypes.c_ulonglong(g.src), ctypes.c_size_t(g.rows * g.cols * 4),
                      ctypes.c_void_p(stream))
            return
        args = [ctypes.c_uint64(x) for x in (g.dst, g.src, g.rows * g.cols, g.cols,
                                             g.row_stride, g.col_stride)]
        params = (ctypes.c_void_p * len(args))(*(ctypes.addressof(x) for x in args))
        blocks = min(-(-g.rows * g.cols // _GATHER_BLOCK), _GATHER_GRID)
        self.call("cuLaunchKernel", self._gather_function(ordinal), ctypes.c_uint(blocks),
                  ctypes.c_uint(1), ctypes.c_uint(1), ctypes.c_uint(_GATHER_BLOCK),
                  ctypes.c_uint(1), ctypes.c_uint(1), ctypes.c_uint(0),
                  ctypes.c_void_p(stream), params, None)

    def _gather_function(self, ordinal: int) -> ctypes.c_void_p:
        """:data:`GATHER_PTX`'s kernel in device ``ordinal``'s context (current), loaded
        (the driver compiles the PTX for its GPU) on first use."""
        fn = self._gathers.get(ordinal)
        if fn is None:
            module, fn = ctypes.c_void_p(), ctypes.c_void_p()
            self.call("cuModuleLoadData", ctypes.byref(module), ctypes.c_char_p(GATHER_PTX))
            self.call("cuModuleGetFunction", ctypes.byref(fn), module, b"rfw_gather32")
            self._gathers[ordinal] = fn
        return fn

    def copy_htod(self, dst: int, src: np.ndarray, ordinal: int) -> None:
        src = np.ascontiguousarray(src)
        with self.push(ordinal):
            self.call("cuMemcpyHtoD_v2", ctypes.c_ulonglong(dst),
                      ctypes.c_void_p(src.ctypes.data), ctypes.c_size_t(src.nbytes))
        copies["host_to_device"] += 1

    def copy_dtoh(self, dst: np.ndarray, src: int, ordinal: int) -> None:
        with self.push(ordinal):
            self.call("cuMemcpyDtoH_v2", ctypes.c_void_p(dst.ctypes.data),
                      ctypes.c_ulonglong(src), ctypes.c_size_t(dst.nbytes))
        copies["device_to_host"] += 1

    def pointer(self, ptr: int) -> tuple[int, int]:
        """(memory type, device ordinal) of a pointer: type 2 is device memory."""
        kind, ordinal = ctypes.c_uint(), ctypes.c_int()
        self.call("cuPointerGetAttribute", ctypes.byref(kind),
                  ctypes.c_int(_CU_POINTER_ATTRIBUTE_MEMORY_TYPE), ctypes.c_ulonglong(ptr))
        self.call("cuPointerGetAttribute", ctypes.byref(ordinal),
                  ctypes.c_int(_CU_POINTER_ATTRIBUTE_DEVICE_ORDINAL), ctypes.c_ulonglong(ptr))
        return int(kind.value), int(ordinal.value)


class _Current:
    def __init__(self, driver: CudaDriver, ordinal: int):
        self.driver, self.ordinal = driver, ordinal

    def __enter__(self) -> None:
        self.driver.call("cuCtxPushCurrent_v2", self.driver.context(self.ordinal))

    def __exit__(self, *exc: Any) -> None:
        popped = ctypes.c_void_p()
        self.driver.call("cuCtxPopCurrent_v2", ctypes.byref(popped))


_driver: CudaDriver | None = None
_driver_error: str | None = None
_driver_lock = threading.Lock()


def cuda() -> CudaDriver:
    """The process's :class:`CudaDriver`, loaded on first use; raises :class:`RfwError`
    (the same one line each time) where there is no CUDA."""
    global _driver, _driver_error
    with _driver_lock:
        if _driver is None and _driver_error is None:
            try:
                _driver = CudaDriver()
            except RfwError as e:
                _driver_error = e.message
        if _driver is None:
            raise RfwError(_driver_error or "CUDA is not available")
        return _driver


# ---------------------------------------------------------------------------------------------
# dlpack capsules (dlpack.h's unversioned DLManagedTensor)


class _DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int), ("device_id", ctypes.c_int)]


class _DLDataType(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16)]


class _DLTensor(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device", _DLDevice), ("ndim", ctypes.c_int),
                ("dtype", _DLDataType), ("shape", ctypes.POINTER(ctypes.c_int64)),
                ("strides", ctypes.POINTER(ctypes.c_int64)), ("byte_offset", ctypes.c_uint64)]


class _DLManagedTensor(ctypes.Structure):
    pass


_DELETER = ctypes.CFUNCTYPE(None, ctypes.POINTER(_DLManagedTensor))
_DLManagedTensor._fields_ = [("dl_tensor", _DLTensor), ("manager_ctx", ctypes.c_void_p),
                             ("deleter", _DELETER)]

_CAPSULE_DESTRUCTOR = ctypes.CFUNCTYPE(None, ctypes.c_void_p)
_capsule_new = ctypes.pythonapi["PyCapsule_New"]  # [] makes a function object of our own
_capsule_new.restype, _capsule_new.argtypes = ctypes.py_object, [
    ctypes.c_void_p, ctypes.c_char_p, _CAPSULE_DESTRUCTOR]
_capsule_valid = ctypes.pythonapi["PyCapsule_IsValid"]
_capsule_valid.restype, _capsule_valid.argtypes = ctypes.c_int, [ctypes.c_void_p,
                                                                  ctypes.c_char_p]
_capsule_pointer = ctypes.pythonapi["PyCapsule_GetPointer"]
_capsule_pointer.restype, _capsule_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object,
                                                                       ctypes.c_char_p]
_capsule_address = ctypes.pythonapi["PyCapsule_GetPointer"]  # of a capsule being destroyed
_capsule_address.restype, _capsule_address.argtypes = ctypes.c_void_p, [ctypes.c_void_p,
                                                                       ctypes.c_char_p]
_NAME = b"dltensor"

# what a capsule's tensor keeps alive, by the address of its DLManagedTensor, until its
# consumer calls the deleter (or the unconsumed capsule is collected)
_live: dict[int, tuple[Any, ...]] = {}
_live_lock = threading.Lock()


@_DELETER
def _delete(managed: Any) -> None:
    address = ctypes.cast(managed, ctypes.c_void_p).value
    with _live_lock:
        _live.pop(address, None)


@_CAPSULE_DESTRUCTOR
def _destroy_capsule(capsule: int) -> None:
    # a capsule still named "dltensor" was never consumed: its tensor is released here
    if _capsule_valid(capsule, _NAME):
        address = _capsule_address(capsule, _NAME)
        with _live_lock:
            _live.pop(address, None)


def _capsule(owner: Any, ptr: int, shape: tuple[int, ...], dtype: np.dtype,
             device: tuple[int, int]) -> Any:
    """A dlpack capsule of C-contiguous memory at ``ptr`` that keeps ``owner`` alive."""
    return _capsule_of(_template(ptr, shape, dtype, device), owner)


def _template(ptr: int, shape: tuple[int, ...], dtype: np.dtype,
              device: tuple[int, int]) -> tuple[bytes, Any]:
    """The bytes of a DLManagedTensor of ``ptr`` and the dims array its shape points at
    (kept alive by whoever keeps the template: :class:`DeviceArray` makes it once)."""
    managed = _DLManagedTensor()
    dims = (ctypes.c_int64 * max(1, len(shape)))(*shape)
    t = managed.dl_tensor
    t.data, t.ndim, t.byte_offset = ptr, len(shape), 0
    t.device = _DLDevice(*device)
    t.dtype = _DLDataType(_DL_CODES[dtype.kind], dtype.itemsize * 8, 1)
    t.shape = dims
    t.strides = ctypes.POINTER(ctypes.c_int64)()  # NULL: C-contiguous
    managed.deleter = _delete
    return bytes(managed), dims


def _capsule_of(template: tuple[bytes, Any], owner: Any) -> Any:
    managed = _DLManagedTensor.from_buffer_copy(template[0])
    address = ctypes.addressof(managed)
    with _live_lock:
        _live[address] = (owner, managed, template[1])
    return _capsule_new(address, _NAME, _destroy_capsule)


def _read_capsule(capsule: Any) -> tuple[int, tuple[int, ...], tuple[int, ...] | None, np.dtype,
                                          tuple[int, int]]:
    """(data pointer, shape, strides in bytes or None, dtype, (device type, id)) of an
    unconsumed ``dltensor`` capsule (left unconsumed: its destructor frees it)."""
    address = _capsule_pointer(capsule, _NAME)
    t = _DLManagedTensor.from_address(address).dl_tensor
    shape = tuple(t.shape[i] for i in range(t.ndim))
    kinds = {v: k for k, v in _DL_CODES.items()}
    if t.dtype.code not in kinds or t.dtype.lanes != 1:
        raise RfwError(f"unsupported dlpack dtype (code {t.dtype.code}, lanes {t.dtype.lanes})")
    dtype = np.dtype(f"{kinds[t.dtype.code]}{t.dtype.bits // 8}")
    strides = None if not t.strides else tuple(t.strides[i] * dtype.itemsize
                                               for i in range(t.ndim))
    return ((t.data or 0) + t.byte_offset, shape, strides, dtype,
            (t.device.device_type, t.device.device_id))


# ---------------------------------------------------------------------------------------------
# arrays


class DeviceArray:
    """An array rfw hands out that PyTorch, CuPy, JAX and numpy take without a copy.

    Attributes
    ----------
    zero_copy
        True: GPU memory that Vulkan wrote and CUDA maps (nothing crossed to the host);
        False: a host copy (no CUDA device shares memory with the Vulkan device).
    device
        ``"cuda:N"`` (the CUDA device ordinal) or ``"cpu"``.
    shape, dtype, nbytes, ptr
        As numpy names them; ``ptr`` is the CUDA device pointer or the host address.

    ``__cuda_array_interface__`` (v3, no stream: the data is complete when handed out) exists
    only on CUDA arrays; ``__dlpack__``/``__dlpack_device__`` on both. :meth:`numpy` copies
    a CUDA array to the host (counted in ``rfw.interop.copies``). A view of a buffer rfw
    reuses (``RayScene.cast``'s hits) is overwritten by the next cast: clone to keep.
    """

    def __init__(self, *, ptr: int, shape: tuple[int, ...], dtype: Any, ordinal: int | None,
                 owner: Any, host: np.ndarray | None = None):
        self.ptr, self.shape, self.dtype = int(ptr), tuple(int(s) for s in shape), np.dtype(dtype)
        self._ordinal, self._owner, self._host = ordinal, owner, host
        self._dl: tuple[bytes, Any] | None = None  # the capsule's template, made once
        hold = getattr(owner, "hold", None)
        if hold is not None:  # the exported memory lives while any view of it does
            hold(self)

    @classmethod
    def of_host(cls, array: np.ndarray) -> DeviceArray:
        """The host path's array: ``array`` (made C-contiguous) behind the same face."""
        array = np.ascontiguousarray(array)
        return cls(ptr=array.ctypes.data, shape=array.shape, dtype=array.dtype, ordinal=None,
                   owner=array, host=array)

    @property
    def zero_copy(self) -> bool:
        return self._ordinal is not None

    @property
    def device(self) -> str:
        return "cpu" if self._ordinal is None else f"cuda:{self._ordinal}"

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) * self.dtype.itemsize

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def __cuda_array_interface__(self) -> dict[str, Any]:
        if self._ordinal is None:
            raise AttributeError("a host DeviceArray (device 'cpu') has no "
                                 "__cuda_array_interface__; use __dlpack__ or numpy()")
        return {"shape": self.shape, "typestr": self.dtype.str, "data": (self.ptr, False),
                "strides": None, "version": 3}

    def __dlpack_device__(self) -> tuple[int, int]:
        return (KDL_CPU, 0) if self._ordinal is None else (KDL_CUDA, self._ordinal)

    def __dlpack__(self, *, stream: Any = None, max_version: Any = None, dl_device: Any = None,
                   copy: Any = None) -> Any:
        # the data is complete when handed out, so any consumer stream may read it now
        if copy:
            raise BufferError("rfw's DeviceArray shares its memory (copy=True is not offered)")
        if dl_device is not None and tuple(dl_device) != self.__dlpack_device__():
            raise BufferError(f"this array lives on {self.device}")
        if self._dl is None:
            self._dl = _template(self.ptr, self.shape, self.dtype, self.__dlpack_device__())
        return _capsule_of(self._dl, self)

    def numpy(self) -> np.ndarray:
        """The values on the host: the array itself (cpu) or a copy (cuda)."""
        if self._host is not None:
            return self._host
        out = np.empty(self.shape, self.dtype)
        cuda().copy_dtoh(out, self.ptr, self._ordinal)
        return out

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self.numpy()
        return a if dtype is None else a.astype(dtype)

    def __repr__(self) -> str:
        path = "zero-copy" if self.zero_copy else "host copy"
        return f"<rfw DeviceArray {self.dtype} {self.shape} on {self.device}, {path}>"


class SharedMemory:
    """What exported memory's arrays hold (``vkext.external`` subclasses it): it is freed
    by :meth:`free` once its owner called :meth:`release` and no array of it is left."""

    def __init__(self) -> None:
        self._holders = 0
        self._released = False
        self._lock = threading.Lock()

    def hold(self, array: Any) -> None:
        with self._lock:
            self._holders += 1
        weakref.finalize(array, self._let_go)

    def _let_go(self) -> None:
        with self._lock:
            self._holders -= 1
            done = self._released and self._holders == 0
        if done:
            self.free()

    def release(self) -> None:
        with self._lock:
            self._released = True
            done = self._holders == 0
        if done:
            self.free()

    @property
    def held(self) -> int:
        return self._holders

    def free(self) -> None:
        raise NotImplementedError


@dataclass(frozen=True)
class CudaView:
    """A caller's CUDA array as rfw reads it: ``shape`` of ``dtype`` on device ``ordinal``,
    element ``strides`` in bytes (None: C-contiguous); :func:`gather_of` says how to copy
    it into contiguous memory."""

    ptr: int
    shape: tuple[int, ...]
    dtype: np.dtype
    ordinal: int
    owner: Any  # keeps the memory alive while rfw copies it
    strides: tuple[int, ...] | None = None


# rfw_gather32: dst[i] = src[(i / cols) * row + (i % cols) * col] for i < count, 4-byte
# elements (strides in elements), a grid-stride loop. PTX written for this (ISA 6.0, sm_52:
# any driver since CUDA 9 compiles it for its GPU); no CUDA toolkit is needed.
GATHER_PTX = b"""
.version 6.0
.target sm_52
.address_size 64

.visible .entry rfw_gather32(.param .u64 p_dst, .param .u64 p_src, .param .u64 p_count,
                             .param .u64 p_cols, .param .u64 p_row, .param .u64 p_col)
{
    .reg .pred %p<2>;
    .reg .b32 %r<6>;
    .reg .b64 %rd<14>;

    ld.param.u64 %rd1, [p_dst];
    ld.param.u64 %rd2, [p_src];
    ld.param.u64 %rd3, [p_count];
    ld.param.u64 %rd4, [p_cols];
    ld.param.u64 %rd5, [p_row];
    ld.param.u64 %rd6, [p_col];
    cvta.to.global.u64 %rd1, %rd1;
    cvta.to.global.u64 %rd2, %rd2;
    mov.u32 %r1, %ctaid.x;
    mov.u32 %r2, %ntid.x;
    mov.u32 %r3, %tid.x;
    mov.u32 %r4, %nctaid.x;
    mul.wide.u32 %rd7, %r1, %r2;
    cvt.u64.u32 %rd8, %r3;
    add.s64 %rd7, %rd7, %rd8;          // i
    mul.wide.u32 %rd9, %r4, %r2;       // the grid's stride
$L_loop:
    setp.ge.u64 %p1, %rd7, %rd3;
    @%p1 bra $L_done;
    div.u64 %rd10, %rd7, %rd4;         // row
    mul.lo.s64 %rd11, %rd10, %rd4;
    sub.s64 %rd11, %rd7, %rd11;        // column
    mul.lo.s64 %rd12, %rd10, %rd5;
    mad.lo.s64 %rd12, %rd11, %rd6, %rd12;
    shl.b64 %rd12, %rd12, 2;
    add.s64 %rd12, %rd2, %rd12;
    ld.global.u32 %r5, [%rd12];
    shl.b64 %rd13, %rd7, 2;
    add.s64 %rd13, %rd1, %rd13;
    st.global.u32 [%rd13], %r5;
    add.s64 %rd7, %rd7, %rd9;
    bra.uni $L_loop;
$L_done:
    ret;
}
\0"""
_GATHER_BLOCK, _GATHER_GRID = 256, 4096  # threads a block; blocks at most (then the loop)


@dataclass(frozen=True)
class Gather:
    """An (N,) or (N, W) array of 4-byte elements at ``src`` made C-contiguous at ``dst``:
    element ``(r, k)`` read at ``src + 4 * (r * row_stride + k * col_stride)`` (strides in
    elements), written at ``dst + 4 * (r * cols + k)`` (:meth:`CudaDriver.gather`)."""

    src: int
    dst: int
    rows: int
    cols: int
    row_stride: int
    col_stride: int

    @property
    def contiguous(self) -> bool:
        return (self.rows <= 1 or self.row_stride == self.cols) and \
            (self.cols <= 1 or self.col_stride == 1)


def gather_of(ptr: int, shape: tuple[int, ...], strides: tuple[int, ...] | None,
              dst: int) -> Gather:
    """The :class:`Gather` of a 4-byte (N,) or (N, W) array at ``ptr`` with ``strides`` in
    bytes (None: C-contiguous) into ``dst``."""
    n = int(shape[0])
    w = int(shape[1]) if len(shape) > 1 else 1
    if strides is None:
        return Gather(ptr, dst, n, w, w, 1)
    return Gather(ptr, dst, n, w, int(strides[0]) // 4 if n > 1 else w,
                  int(strides[1]) // 4 if len(shape) > 1 and w > 1 else 1)


def run_gather_on_host(g: Gather, src: np.ndarray, dst: np.ndarray) -> None:
    """``g`` done on host words as the kernel does it (``src``/``dst`` uint32, pointers as
    byte offsets into them), for tests where there is no CUDA."""
    i = np.arange(g.rows * g.cols, dtype=np.int64)
    r, k = i // g.cols, i % g.cols
    dst[g.dst // 4 + i] = src[g.src // 4 + r * g.row_stride + k * g.col_stride]


def is_device_array(a: Any) -> bool:
    """Whether ``a`` is a CUDA array (``__cuda_array_interface__`` or a CUDA dlpack)."""
    if isinstance(a, DeviceArray):
        return a.zero_copy
    if isinstance(a, np.ndarray | int | float | str | bytes) or a is None:
        return False
    # on the instance: PyTorch's CPU tensors have the property and raise AttributeError
    try:
        a.__cuda_array_interface__  # noqa: B018 - evaluated for its AttributeError
        return True
    except AttributeError:
        pass
    except Exception:  # a CUDA array that refuses (a tensor that requires grad): device_view
        return True    # says why
    dev = getattr(a, "__dlpack_device__", None)
    if dev is None or isinstance(a, np.ndarray):
        return False
    try:
        kind = dev()[0]
    except Exception:
        return False
    return int(kind) in (KDL_CUDA, 13)  # kDLCUDA, kDLCUDAManaged


def host_of(a: Any) -> Any:
    """A CPU dlpack producer (a host DeviceArray, a CPU tensor) as a numpy array; anything
    else as it is."""
    if isinstance(a, DeviceArray) and not a.zero_copy:
        return a.numpy()
    if not isinstance(a, np.ndarray) and hasattr(a, "__dlpack_device__") \
            and hasattr(a, "__dlpack__"):
        try:
            if int(a.__dlpack_device__()[0]) == KDL_CPU:
                return np.from_dlpack(a)
        except (TypeError, BufferError, RuntimeError):
            return a
    return a


def device_view(name: str, a: Any, width: int | None, dtype: Any = np.float32) -> CudaView:
    """``a`` (a CUDA array) checked as ``dtype`` of shape (N, width) (or (N,) with ``width``
    None), any element strides that are positive multiples of the item size (a transposed
    view, a slice of a wider array: :func:`gather_of`); one :class:`RfwError` line
    naming ``name`` otherwise."""
    dtype = np.dtype(dtype)
    want = f"(N, {width})" if width else "(N,)"
    owner = a
    try:
        iface = getattr(a, "__cuda_array_interface__", None)
    except Exception as e:  # e.g. PyTorch's for a tensor that requires grad
        raise RfwError(f"{name}: its __cuda_array_interface__ failed "
                       f"({' '.join(str(e).split())[:160]}): detach it first") from None
    if iface is not None:
        ptr = int(iface["data"][0])
        shape = tuple(int(s) for s in iface["shape"])
        got = np.dtype(iface["typestr"])
        strides = iface.get("strides")
        ordinal = None
    else:
        try:
            owner = a.__dlpack__(stream=None)
        except TypeError:
            owner = a.__dlpack__()
        ptr, shape, strides, got, (_, ordinal) = _read_capsule(owner)
        owner = (a, owner)
    if got != dtype:
        raise RfwError(f"{name} is a device array of dtype {got}; rfw takes {dtype} only "
                       f"(convert it on the GPU, e.g. tensor.float())")
    if (width and (len(shape) != 2 or shape[1] != width)) or (not width and len(shape) != 1):
        raise RfwError(f"{name} is a device array of shape {shape}; it must be {want}")
    contiguous = tuple(int(np.prod(shape[i + 1:], dtype=np.int64)) * dtype.itemsize
                       for i in range(len(shape)))
    strides = None if strides is None or tuple(strides) == contiguous else \
        tuple(int(x) for x in strides)
    if strides is not None:
        # any element strides that are positive multiples of the item size: gathered on the
        # device (gather_of); a single row or column's stride does not matter
        used = [x for x, n in zip(strides, shape, strict=True) if n > 1]
        if any(x <= 0 or x % dtype.itemsize for x in used):
            raise RfwError(f"{name} is a device array with strides {tuple(strides)} bytes; "
                           f"rfw takes positive multiples of {dtype.itemsize} (no broadcast "
                           f"or reversed views: e.g. tensor.contiguous())")
    return CudaView(ptr, shape, dtype, int(ordinal or 0), owner, strides)


def device_outputs(frame: Any, names: Any) -> dict[str, str | None]:
    """Let a running :class:`rfw.frame.Frame`'s next frames copy the graph outputs ``names``
    into exported memory inside their own submission (vk with a CUDA link), so that
    :func:`read_device` after a frame is the wrapper alone (no submit, no wait of its own:
    ordered by the frame's fence, which finishing the frame waits for anyway). ``()``
    stops it. Returns, by output, None (the frames copy it) or why not (read_device then
    copies as before)."""
    names = tuple(names)
    out: dict[str, str | None] = {}
    by_owner: dict[str, list[str]] = {}
    for n in names:
        if n not in frame.frame_plan.owner:
            raise RfwError(f"device_outputs: '{n}' is not a resource of the graph")
        by_owner.setdefault(frame.frame_plan.owner[n], []).append(n)
    for owner in frame.executors:
        backend = frame.backends.get(owner)
        export = getattr(backend, "export_outputs", None)
        mine = by_owner.get(owner, [])
        if export is None:
            out.update({n: f"the {owner} backend copies through the host" for n in mine})
            continue
        why = export(frame.executors[owner], mine)
        out.update({n: why for n in mine})
    return out


def read_device(frame: Any, resource: str, *, wrap: Any = None) -> Any:
    """A graph output of a running :class:`rfw.frame.Frame` (e.g. in ``rfw.render``'s
    ``each_frame(k, frame)``) as a :class:`DeviceArray`, after its frames in flight: on vk
    with a GPU that CUDA shares memory with, copied on the GPU into exported memory
    (``zero_copy`` True; the same memory each read of the frame's resource, so the next
    read overwrites it; after :func:`device_outputs` the copy the frame made itself, one
    buffer per frame in flight, nothing submitted here); elsewhere a host copy
    (``zero_copy`` False).

    ``wrap`` (e.g. ``torch.from_dlpack``): the array as ``wrap`` makes it. Where the frames
    copy the output themselves (:func:`device_outputs`), ``wrap`` runs once per buffer and
    its result is handed out again (the same tensor for every frame that used that buffer:
    like the array, a view that a later frame overwrites), so a read costs no dlpack
    exchange; elsewhere ``wrap`` runs on each read."""
    frame.drain()
    owner = frame.frame_plan.owner[resource]
    backend = frame.backends.get(owner)
    read = getattr(backend, "read_device", None)
    if read is None:
        a = DeviceArray.of_host(frame.read(resource))
        return a if wrap is None else wrap(a)
    return read(frame.executors[owner], resource, wrap=wrap)
