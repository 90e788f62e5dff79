"""What handing the GPU from CUDA to Vulkan and back costs (issue 24 item 1's floor).

On the GPU machine, after ``source benchmarks/device_env.sh``, with torch::

    python3 benchmarks/probe_cuda_vulkan_handoff.py     # JSON into $OUT/handoff.json

A ray scene of the embedded courtyard casts 921,600 primary rays once (so its command
buffer is recorded); then loops of 60 timed iterations (after 8), each step waited for on
the host (``cuCtxSynchronize``, the fence), time per step as the median:

- CUDA alone: the two ray copies (torch tensors into the exported ray buffer,
  ``cuMemcpyDtoDAsync``), or a small ``cuMemsetD32Async`` (4 KiB), or an empty call (0
  words: no GPU work, the control);
- Vulkan alone: an empty command buffer, or the trace;
- alternating CUDA and Vulkan steps: what each costs right after the other API used the GPU.

``semaphore``: the copies, then ``cuSignalExternalSemaphoresAsync`` on a Vulkan timeline
semaphore exported as an opaque fd (``VK_KHR_external_semaphore_fd``, enabled here for the
probe only) and the trace submitted waiting on it: the hand-off without the host in
between. The hits it gives are checked against a cast's.
"""
import ctypes
import json
import os
import statistics
import sys
import time
import traceback
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
out: dict = {"commit": os.environ.get("RFW_COMMIT", "unknown")}
OUT = Path(os.environ.get("OUT", "."))

import vkext.device as vd  # noqa: E402

vd.EXTENSIONS["VK_KHR_external_semaphore_fd"] = (None, None, ())
vd.COMMANDS["VK_KHR_external_semaphore_fd"] = ("vkGetSemaphoreFdKHR",)


def save():
    (OUT / "handoff.json").write_text(json.dumps(out, indent=1, default=str))


def med(ts):
    return round(statistics.median(ts) * 1e6, 2)


def section(name):
    def run(fn):
        try:
            out[name] = fn()
        except Exception:
            out[name] = {"error": traceback.format_exc()[-2500:]}
        save()
    return run


from bench_rt import flatten, primary_rays  # noqa: E402

import rfw  # noqa: E402
from rfw import interop  # noqa: E402
from rfw.scene import default_scene  # noqa: E402
from vkext.consts import const, ffi, lib  # noqa: E402

scene = default_scene()
v, f = flatten(scene)
o, d = primary_rays(scene, (1280, 720))
n = len(o)
rs = rfw.RayScene(v, f)
ot = torch.from_numpy(np.ascontiguousarray(o)).cuda()
dt = torch.from_numpy(np.ascontiguousarray(d)).cuda()
ro, rd = rs.device_rays(n)
rs.cast(ro, rd)
sh = rs._scene.shared
sub = sh.submitter
dev = sh.device
drv = interop.cuda()
base = sh.rays.cuda_ptr
out["exts"] = sorted(e for e in dev.extensions if "semaphore" in e or "external" in e)
clock = time.perf_counter


def copies():
    for src, off in ((ot, 0), (dt, 12 * n)):
        drv.call("cuMemcpyDtoDAsync_v2", ctypes.c_ulonglong(base + off),
                 ctypes.c_ulonglong(src.data_ptr()), ctypes.c_size_t(12 * n), ctypes.c_void_p(0))


scratch = torch.empty(1024, dtype=torch.int32, device="cuda")


def memset(words):
    def run():
        drv.call("cuMemsetD32Async", ctypes.c_ulonglong(scratch.data_ptr()), ctypes.c_uint(0),
                 ctypes.c_size_t(words), ctypes.c_void_p(0))
    return run


tiny, nothing = memset(1024), memset(0)


empty = None
# the trace of real rays (the ray buffer holds the courtyard's primary rays from here on)
rs.cast(ot, dt)


@section("host_synced_us")
def _():
    global empty
    from vkext.external import Submitter
    empty = Submitter(dev, label="empty")
    empty.begin()
    empty.end("e")
    res = {}
    with drv.push(0):
        def loop(parts, k=60, warm=8):
            ts = {name: [] for name, _ in parts}
            tot = []
            for i in range(k + warm):
                t0 = clock()
                for name, fn in parts:
                    a = clock()
                    fn()
                    if i >= warm:
                        ts[name].append(clock() - a)
                if i >= warm:
                    tot.append(clock() - t0)
            return {"total": med(tot), **{k2: med(v2) for k2, v2 in ts.items()}}

        def cu(fn):
            def run():
                fn()
                drv.call("cuCtxSynchronize")
            return run
        res["vk_empty_only"] = loop([("vk", empty.run)])
        res["cu_tiny_only"] = loop([("cu", cu(tiny))])
        res["cu_nothing_only"] = loop([("cu", cu(nothing))])
        res["alt_tiny_empty"] = loop([("cu", cu(tiny)), ("vk", empty.run)])
        res["alt_nothing_empty"] = loop([("cu", cu(nothing)), ("vk", empty.run)])
        res["trace_only"] = loop([("vk", sub.run)])
        res["copies_only"] = loop([("cu", cu(copies))])
        res["alt_copies_trace"] = loop([("cu", cu(copies)), ("vk", sub.run)])
        res["alt_tiny_trace"] = loop([("cu", cu(tiny)), ("vk", sub.run)])
        res["alt_nothing_trace"] = loop([("cu", cu(nothing)), ("vk", sub.run)])
        res["alt_copies_empty"] = loop([("cu", cu(copies)), ("vk", empty.run)])
        res["alt_copies_empty_trace"] = loop([("cu", cu(copies)), ("vk0", empty.run),
                                              ("vk", sub.run)])
    return res


class _SemHandle(ctypes.Union):
    _fields_ = [("fd", ctypes.c_int), ("win32", ctypes.c_void_p * 2),
                ("nvSciSyncObj", ctypes.c_void_p)]


class _SemDesc(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("handle", _SemHandle), ("flags", ctypes.c_uint),
                ("reserved", ctypes.c_uint * 16)]


class _SigParams(ctypes.Structure):
    _fields_ = [("value", ctypes.c_ulonglong), ("nvsci", ctypes.c_ulonglong),
                ("key", ctypes.c_ulonglong), ("reserved", ctypes.c_uint * 12),
                ("flags", ctypes.c_uint), ("reserved2", ctypes.c_uint * 16)]


@section("semaphore_us")
def _():
    res = {}
    handle = const("VK_EXTERNAL_SEMAPHORE_HANDLE_TYPE_OPAQUE_FD_BIT")
    exp = ffi.new("VkExportSemaphoreCreateInfo*")
    exp.sType = const("VK_STRUCTURE_TYPE_EXPORT_SEMAPHORE_CREATE_INFO")
    exp.handleTypes = handle
    kind = ffi.new("VkSemaphoreTypeCreateInfo*")
    kind.sType = const("VK_STRUCTURE_TYPE_SEMAPHORE_TYPE_CREATE_INFO")
    kind.semaphoreType = const("VK_SEMAPHORE_TYPE_TIMELINE")
    kind.initialValue = 0
    kind.pNext = exp
    info = ffi.new("VkSemaphoreCreateInfo*")
    info.sType = const("VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO")
    info.pNext = kind
    sem = ffi.new("VkSemaphore*")
    r = lib.vkCreateSemaphore(dev.device, info, ffi.NULL, sem)
    res["create"] = r
    get = ffi.new("VkSemaphoreGetFdInfoKHR*")
    get.sType = const("VK_STRUCTURE_TYPE_SEMAPHORE_GET_FD_INFO_KHR")
    get.semaphore, get.handleType = sem[0], handle
    fd = int(dev.fn.vkGetSemaphoreFdKHR(dev.device, get))
    desc = _SemDesc()
    desc.type = 9  # CU_EXTERNAL_SEMAPHORE_HANDLE_TYPE_TIMELINE_SEMAPHORE_FD
    desc.handle.fd = fd
    ext = ctypes.c_void_p()
    with drv.push(0):
        drv.call("cuImportExternalSemaphore", ctypes.byref(ext), ctypes.byref(desc))
    res["sizeof_sig"] = ctypes.sizeof(_SigParams)
    # a submit waiting on the timeline at `value`, signalling the fence
    vals = ffi.new("uint64_t[1]")
    tsi = ffi.new("VkTimelineSemaphoreSubmitInfo*")
    tsi.sType = const("VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO")
    tsi.waitSemaphoreValueCount, tsi.pWaitSemaphoreValues = 1, vals
    stages = ffi.new("VkPipelineStageFlags[1]", [const("VK_PIPELINE_STAGE_ALL_COMMANDS_BIT")])
    sems = ffi.new("VkSemaphore[1]", [sem[0]])
    si = ffi.new("VkSubmitInfo*")
    si.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO")
    si.pNext = tsi
    si.waitSemaphoreCount, si.pWaitSemaphores, si.pWaitDstStageMask = 1, sems, stages
    si.commandBufferCount, si.pCommandBuffers = 1, sub._cmds
    exts = (ctypes.c_void_p * 1)(ext.value)
    params = (_SigParams * 1)()
    value = [0]

    def one(copy=True):
        value[0] += 1
        if copy:
            copies()
        params[0].value = value[0]
        drv.call("cuSignalExternalSemaphoresAsync", exts, params, ctypes.c_uint(1),
                 ctypes.c_void_p(0))
        vals[0] = value[0]
        lib.vkResetFences(dev.device, 1, sub._fences)
        rr = lib.vkQueueSubmit(dev.queue, 1, si, sub.fence)
        assert rr == 0, rr
        sub.wait()

    with drv.push(0):
        for copy, name in ((True, "copies_sem_trace"), (False, "sem_trace_nocopy")):
            ts = []
            for i in range(68):
                t0 = clock()
                one(copy)
                if i >= 8:
                    ts.append(clock() - t0)
            res[name] = med(ts)
        # correctness: hits equal to a host-synced cast
        one(True)
        got = {k: torch.from_dlpack(a).clone() for k, a in sh.hit_views(n, ("t",)).items()}
        want = rs.cast(ot, dt)
        res["t_equal"] = bool(torch.equal(got["t"], torch.from_dlpack(want["t"])))
    return res


save()
print(json.dumps(out, indent=1, default=str))
