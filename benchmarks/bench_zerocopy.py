"""Zero-copy arrays on a GPU that Vulkan and CUDA share (issue 24 item 1): rays from and hits
to PyTorch/CuPy device arrays, a graph output to a torch tensor, and the proof that nothing
crossed to the host.

Measures, in one run (results as JSON into ``$OUT/bench_zerocopy.json``, or ``--out``):

- ``rays``: 1280x720 = 921,600 primary rays of the embedded courtyard from torch (and CuPy)
  device arrays, hits back as device arrays: wall per cast end to end (``torch.cuda.synchronize``
  before and after; the hits wrapped by ``torch.from_dlpack``), median of ``--casts`` (>= 50)
  after ``--warmup``; the same rays through the host path (numpy) and Embree on all cores
  (``bench_rt.embree_all_cores``) in the same run; the device hits checked bit for bit
  against the host path's.
- ``image``: a 1920x1080 RGBA16F output to a torch tensor: from the render done (frames
  drained) to the tensor usable (``torch.cuda.synchronize``), median over frames; through
  ``vkext.external.ImageExport`` of a cleared image, and in a real vk render of
  ``forward.hdr`` through ``rfw.interop.read_device`` twice: per read (a submit of the copy
  and a wait) and in-frame (``rfw.interop.device_outputs``: the frame's own command buffer
  copies it, ordered by the frame's fence), with the frame's GPU ms with and without that
  copy (``cost``), and in-frame with ``read_device(..., wrap=torch.from_dlpack)`` (each
  slot's buffer wrapped once, that tensor handed out again: ``render_in_frame_wrapped``);
  each checked against the host readback inside the frame. Rays also
  come as strided tensors (transposed, a slice of (N, 8)), gathered on the device.
- ``copies``: no device-to-host copy during the timed casts, shown four ways: rfw's own
  counters (``rfw.interop.copies``), every ``vkMapMemory`` and ``Buffer.map`` call counted
  (no host-visible staging touched), ``cuPointerGetAttribute`` of the tensor's pointer
  (device memory, inside the exported hit buffer), and the torch profiler's CUDA memcpy
  events (no ``DtoH``).

Targets (issue 24): <= 0.65 ms per cast, >= 30x Embree, <= 50 us for the image.

What cannot run (no torch, no CuPy, no embreex, no CUDA link) is one line in ``notes`` and on
stderr, and the rest goes on. ``--probe`` runs each step of the zero-copy path separately
(device, CUDA driver, UUID match, export and import, torch, CuPy, a small device cast, an
image export, 921,600 rays from contiguous and strided torch tensors, a real render's output
read per read, copied in the frame, and after the render) and reports which one fails.

Usage (from the repository root, after ``source benchmarks/device_env.sh``)::

    python3 benchmarks/bench_zerocopy.py --probe
    python3 benchmarks/bench_zerocopy.py            # everything, JSON into $OUT
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
import traceback
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

TARGETS = {"cast_ms": 0.65, "embree_ratio": 30.0, "image_us": 50.0}
notes: list[str] = []


def note(text: str) -> None:
    """What could not be done, and why: one line."""
    line = " ".join(str(text).split())[:300]
    notes.append(line)
    print(f"bench_zerocopy: {line}", file=sys.stderr)


def error_line(e: BaseException) -> str:
    return f"{type(e).__name__}: {' '.join(str(e).split())[:240]}"


def summary(times_s: list[float]) -> dict[str, float]:
    ms = sorted(t * 1e3 for t in times_s)
    pick = lambda q: ms[min(len(ms) - 1, int(q * len(ms)))]  # noqa: E731
    return {"median_ms": statistics.median(ms), "p10_ms": pick(0.1), "p90_ms": pick(0.9),
            "min_ms": ms[0], "n": len(ms)}


def optional(name: str) -> Any:
    try:
        return __import__(name)
    except Exception as e:  # any import failure is a note
        note(f"{name} is not importable ({error_line(e)}): its rows are skipped")
        return None


# ---------------------------------------------------------------------------------------------
# the probe: each step of the path alone


def probe() -> dict[str, Any]:
    from rfw import interop

    steps: dict[str, dict[str, Any]] = {}
    state: dict[str, Any] = {}

    def step(name: str, needs: tuple[str, ...] = ()):
        def run(fn):
            missing = [n for n in needs if not steps.get(n, {}).get("ok")]
            if missing:
                steps[name] = {"ok": False, "skipped": f"needs {', '.join(missing)}"}
            else:
                t0 = time.perf_counter()
                try:
                    steps[name] = {"ok": True, "detail": fn()}
                except BaseException as e:  # the probe reports, never stops
                    steps[name] = {"ok": False, "error": error_line(e),
                                   "where": traceback.format_exc().strip().splitlines()[-3:]}
                steps[name]["s"] = round(time.perf_counter() - t0, 4)
            status = "ok" if steps[name]["ok"] else "FAILED"
            said = next(steps[name][k] for k in ("detail", "error", "skipped", "ok")
                        if steps[name].get(k) is not None)
            print(f"probe {name}: {status} {said}", file=sys.stderr)
            return fn
        return run

    @step("vulkan_device")
    def _():
        from vkext import VkDevice
        from vkext.external import EXTENSION

        state["device"] = dev = VkDevice()
        return {"name": dev.name, "driver": dev.driver, EXTENSION: EXTENSION in dev.extensions}

    @step("cuda_driver")
    def _():
        drv = interop.cuda()
        return {"devices": drv.devices(), "uuids": [drv.uuid(i).hex()
                                                    for i in range(drv.devices())]}

    @step("uuid_match", ("vulkan_device", "cuda_driver"))
    def _():
        from vkext.external import CudaLink, cuda_link, device_uuid

        link = cuda_link(state["device"])
        if not isinstance(link, CudaLink):
            raise RuntimeError(link)
        state["link"] = link
        return {"vulkan_uuid": device_uuid(state["device"]).hex(), "cuda_ordinal": link.ordinal}

    @step("export_import", ("uuid_match",))
    def _():
        from vkext.commands import one_time
        from vkext.consts import vk
        from vkext.external import ExportedBuffer, ownership

        dev = state["device"]
        buf = ExportedBuffer(dev, 1 << 20, ("storage", "transfer_dst"), link=state["link"],
                             label="probe")
        with one_time(dev) as cmd:
            ownership(dev, cmd, [buf], acquire=True)
            vk.vkCmdFillBuffer(cmd, buf.handle, 0, 1 << 20, 0x3F800000)
            ownership(dev, cmd, [buf], acquire=False)
        arr = buf.array(0, (1 << 18,), np.float32)
        seen = arr.numpy()
        if not (seen == 1.0).all():
            raise RuntimeError(f"CUDA read {seen[:4]} where Vulkan wrote 1.0")
        kind, ordinal = interop.cuda().pointer(arr.ptr)
        state["buffer"], state["array"] = buf, arr
        return {"ptr": hex(arr.ptr), "memory_type": kind, "ordinal": ordinal}

    @step("torch_dlpack", ("export_import",))
    def _():
        import torch

        t = torch.from_dlpack(state["array"])
        ok = bool((t == 1.0).all().item())
        if not ok or t.data_ptr() != state["array"].ptr:
            raise RuntimeError(f"torch saw {t[:4].tolist()} at {hex(t.data_ptr())}")
        t2 = torch.as_tensor(state["array"], device="cuda")  # __cuda_array_interface__
        return {"device": str(t.device), "cai_same_ptr": t2.data_ptr() == t.data_ptr()}

    @step("cupy", ("export_import",))
    def _():
        import cupy

        c = cupy.asarray(state["array"])
        if not bool((c == 1.0).all()):
            raise RuntimeError("cupy saw other values")
        return {"ptr_equal": int(c.data.ptr) == state["array"].ptr}

    @step("device_cast", ("uuid_match",))
    def _():
        import rfw

        tri = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
        o = np.float32([[0.25, 0.25, 1], [3, 3, 1]])
        d = np.float32([[0, 0, -1], [0, 0, -1]])
        with rfw.RayScene(tri, np.array([[0, 1, 2]]), device=state["device"]) as s:
            want = s.cast(o, d)
            try:
                import torch

                ot, dt = torch.from_numpy(o).cuda(), torch.from_numpy(d).cuda()
            except ImportError:
                ot, dt = o, d
            got = s.cast(ot, dt, out="device")
            if not all(a.zero_copy for a in got.values()):
                raise RuntimeError(f"not zero-copy: {s.zero_copy_reason}")
            for k in want:
                if not np.array_equal(got[k].numpy(), want[k]):
                    raise RuntimeError(f"{k}: device {got[k].numpy()} host {want[k]}")
            return {"last": s.last}

    @step("image_export", ("uuid_match",))
    def _():
        from vkext.external import ImageExport
        from vkext.images import Image

        dev = state["device"]
        img = Image(dev, 64, 32, "rgba16float", ("transfer_src", "transfer_dst", "sampled"),
                    label="probe image")
        img.allocate()
        try:
            _clear(dev, img, 0.375)
            exp = ImageExport(dev, img, layout_now="TRANSFER_DST_OPTIMAL",
                              layout_after="TRANSFER_DST_OPTIMAL", link=state["link"])
            got = exp.read().numpy()
            exp.destroy()
        finally:
            img.destroy()
        if got.shape != (32, 64, 4) or not (got[..., 0] == np.float16(0.375)).all():
            raise RuntimeError(f"the export read {got.shape} {got[0, 0]}")
        return {"shape": list(got.shape)}

    @step("cast_921600_rays", ("uuid_match",))
    def _():
        import torch
        from bench_rt import flatten, primary_rays

        import rfw
        from rfw.scene import default_scene

        scene = default_scene()
        v, f = flatten(scene)
        o, d = primary_rays(scene, (1280, 720))
        res: dict[str, Any] = {"rays": len(o)}
        with rfw.RayScene(v, f, device=state["device"]) as rs:
            want = rs.cast(o, d)
            oc = torch.from_numpy(np.ascontiguousarray(o)).cuda()
            dc = torch.from_numpy(np.ascontiguousarray(d)).cuda()
            for name, (os_, ds_) in {"contiguous": (oc, dc),
                                     **strided_rays(torch, oc, dc)}.items():
                try:
                    got = rs.cast(os_, ds_)
                    t = torch.from_dlpack(got["t"]).cpu().numpy()
                    res[name] = {"zero_copy": got["t"].zero_copy, "wall_ms": rs.last["wall_ms"],
                                 "copy_in_ms": rs.last["copy_in_ms"],
                                 "t_equal_host": bool(np.array_equal(t, want["t"]))}
                except Exception as e:  # each layout named on its own
                    res[name] = {"error": error_line(e)}
            try:  # rays written into the scene's own buffer: cast in place
                ro, rd = rs.device_rays(len(o))
                torch.from_dlpack(ro).copy_(oc)
                torch.from_dlpack(rd).copy_(dc)
                got = rs.cast(ro, rd)
                t = torch.from_dlpack(got["t"]).cpu().numpy()
                res["device_rays"] = {"in_place": rs.last.get("rays_in_place"),
                                      "wall_ms": rs.last["wall_ms"],
                                      "copy_in_ms": rs.last["copy_in_ms"],
                                      "t_equal_host": bool(np.array_equal(t, want["t"]))
                                      and rs.last.get("rays_in_place") is True}
            except Exception as e:
                res["device_rays"] = {"error": error_line(e)}
        bad = [k for k, r in res.items() if isinstance(r, dict)
               and (r.get("error") or not r.get("t_equal_host"))]
        if bad:
            raise RuntimeError(f"layouts failed: {bad}: {res}")
        return res

    @step("render_output", ("uuid_match",))
    def _():
        import torch

        from rfw import interop
        from rfw.config import apply_overrides, load_config
        from rfw.render import render

        cfg = apply_overrides(load_config(ROOT / "configs" / "forward.toml"),
                              ["size=64x36", "frames=4"])
        cfg = replace(cfg, outputs=["forward.hdr"])
        seen: dict[str, Any] = {}
        held: list[Any] = []

        def each(k: int, frame: Any) -> None:
            stage = "per_read" if k == 0 else "in_frame"
            try:
                if k == 1:  # frame 0 was read per read; frame 1 on copy in the frame
                    seen["device_outputs"] = interop.device_outputs(frame, ["forward.hdr"])
                    return
                a = interop.read_device(frame, "forward.hdr")
                t = torch.from_dlpack(a)
                same = bool(np.array_equal(t.cpu().numpy(), frame.read("forward.hdr")))
                seen[stage] = {"zero_copy": a.zero_copy, "equal_host_readback": same}
                held.append((t, frame.read("forward.hdr")))
            except Exception as e:
                seen[stage] = {"error": error_line(e)}

        # its own device, destroyed when it returns: the tensor must outlive it (run last,
        # an unmapped read may poison the CUDA context)
        render(cfg, backend="vk", each_frame=each)
        try:
            t, want = held[-1]
            seen["after_render"] = {"equal": bool(np.array_equal(t.cpu().numpy(), want))}
        except Exception as e:
            seen["after_render"] = {"error": error_line(e)}
        bad = [k for k in ("per_read", "in_frame", "after_render")
               if (seen.get(k) or {}).get("error") or (seen.get(k) or {}).get(
                   "equal_host_readback", (seen.get(k) or {}).get("equal")) is not True]
        if bad:
            raise RuntimeError(f"stages failed: {bad}: {seen}")
        return seen

    out = {"probe": steps, "first_failure": next((k for k, v in steps.items()
                                                   if not v["ok"]), None)}
    for key in ("array",):
        state.pop(key, None)
    if "buffer" in state:
        state.pop("buffer").release()
    if "device" in state:
        state["device"].destroy()
    return out


def _clear(dev: Any, img: Any, value: float) -> None:
    """The image cleared to ``value`` and left in TRANSFER_DST_OPTIMAL (the render)."""
    from vkext.commands import one_time
    from vkext.consts import vk

    with one_time(dev) as cmd:
        rng = vk.VkImageSubresourceRange(aspectMask=vk.VK_IMAGE_ASPECT_COLOR_BIT,
                                         levelCount=1, layerCount=1)
        bar = vk.VkImageMemoryBarrier(
            srcAccessMask=0, dstAccessMask=vk.VK_ACCESS_TRANSFER_WRITE_BIT,
            oldLayout=vk.VK_IMAGE_LAYOUT_UNDEFINED,
            newLayout=vk.VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
            srcQueueFamilyIndex=vk.VK_QUEUE_FAMILY_IGNORED,
            dstQueueFamilyIndex=vk.VK_QUEUE_FAMILY_IGNORED, image=img.handle,
            subresourceRange=rng)
        vk.vkCmdPipelineBarrier(cmd, vk.VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT,
                                vk.VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, None, 0, None, 1,
                                [bar])
        vk.vkCmdClearColorImage(cmd, img.handle, vk.VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                                vk.VkClearColorValue(float32=[value, 0.5, 0.25, 1.0]), 1, [rng])


# ---------------------------------------------------------------------------------------------
# rays


class MapCounter:
    """Counts vkMapMemory and Buffer.map calls while active (host-visible memory touched)."""

    def __init__(self) -> None:
        self.counts = {"vkMapMemory": 0, "Buffer.map": 0}

    def __enter__(self) -> MapCounter:
        from vkext import allocation, buffers

        self._vk, self._buffer = allocation.vk, buffers.Buffer
        self._map_memory, self._map = allocation.vk.vkMapMemory, buffers.Buffer.map
        counts = self.counts

        def map_memory(*a, **k):
            counts["vkMapMemory"] += 1
            return self._map_memory(*a, **k)

        def buffer_map(buf, *a, **k):
            counts["Buffer.map"] += 1
            return self._map(buf, *a, **k)

        allocation.vk.vkMapMemory = map_memory
        buffers.Buffer.map = buffer_map
        return self

    def __exit__(self, *exc: Any) -> None:
        self._vk.vkMapMemory = self._map_memory
        self._buffer.map = self._map


WARMUP_S = 1.0  # casts before the counted warm-up ones: the GPU's clocks settle


def timed_casts(scene: Any, o: Any, d: Any, casts: int, warmup: int, wrap: Any,
                sync: Any, *, write: Any = None,
                phases: list[dict[str, float]] | None = None) -> tuple[list[float], Any]:
    """Wall per cast: sync, (``write``: the rays written in place, a row of its own), cast,
    wrap the hits (from_dlpack), sync; after :data:`WARMUP_S` of such casts and ``warmup``
    more. ``phases``: each timed cast's ``phases_us`` (the cast's own clock, read after the
    timed region) with the timed region's own steps (``loop_write``, ``loop_cast``,
    ``loop_wrap``, ``loop_sync``: where the time outside the cast goes)."""
    got = None
    times = []
    clock = time.perf_counter
    until = clock() + WARMUP_S
    while clock() < until:
        if write is not None:
            write()
        got = {k: wrap(v) for k, v in scene.cast(o, d).items()}
        sync()
    for i in range(warmup + casts):
        sync()
        t0 = clock()
        if write is not None:
            write()
        t1 = clock()
        hits = scene.cast(o, d)
        t2 = clock()
        got = {k: wrap(v) for k, v in hits.items()}
        t3 = clock()
        sync()
        t4 = clock()
        if i >= warmup:
            times.append(t4 - t0)
            if phases is not None:
                phases.append({**(scene._scene._last.get("phases_us") or {}),
                               "loop_write": (t1 - t0) * 1e6, "loop_cast": (t2 - t1) * 1e6,
                               "loop_wrap": (t3 - t2) * 1e6, "loop_sync": (t4 - t3) * 1e6})
    return times, got


def median_phases(phases: list[dict[str, float]]) -> dict[str, float]:
    keys = sorted({k for p in phases for k in p})
    return {k: statistics.median(p[k] for p in phases if k in p) for k in keys}


def calls_of_a_cast(rs: Any, o: Any, d: Any) -> dict[str, int]:
    """CUDA driver calls (rfw.interop.CudaDriver.calls) of one cast of ``o``, ``d``."""
    from rfw import interop

    drv = interop.cuda()
    before = dict(drv.calls)
    rs.cast(o, d)
    return {k: v - before.get(k, 0) for k, v in drv.calls.items() if v != before.get(k, 0)}


def rays_section(args: argparse.Namespace, torch: Any, cupy: Any) -> dict[str, Any]:
    from bench_rt import embree_all_cores, flatten, primary_rays

    import rfw
    from rfw import interop
    from rfw.scene import default_scene

    scene = default_scene()
    v, f = flatten(scene)
    w, h = args.size
    o, d = primary_rays(scene, (w, h))
    out: dict[str, Any] = {"scene": "courtyard (embedded)", "triangles": len(f),
                           "rays": len(o), "size": [w, h]}
    rs = rfw.RayScene(v, f)
    try:
        out["method"], out["device"] = rs._scene.method, rs.device.name
        out["zero_copy"], out["zero_copy_reason"] = rs.zero_copy, rs.zero_copy_reason
        host_times = []
        with MapCounter() as maps:  # the counter's control: the host path maps staging
            for i in range(args.warmup + min(args.casts, 20)):
                t0 = time.perf_counter()
                want = rs.cast(o, d)
                if i >= args.warmup:
                    host_times.append(time.perf_counter() - t0)
        out["host_path"] = {**summary(host_times), "last": rs.last,
                            "maps_during_casts": maps.counts}
        try:
            import embreex  # noqa: F401

            all_s, workers, t_embree = embree_all_cores(v, f, o, d, args.embree_repeats)
            agree = float(np.mean(np.isclose(t_embree, want["t"], rtol=1e-3, atol=1e-4)
                                  | (np.isinf(t_embree) & np.isinf(want["t"]))))
            out["embree"] = {"median_ms": all_s * 1e3, "workers": workers,
                             "repeats": args.embree_repeats, "t_agreement": agree}
        except Exception as e:  # embreex missing or failing: a note
            note(f"Embree on all cores not measured ({error_line(e)})")
        if not rs.zero_copy:
            note(f"no zero-copy ray casts: {rs.zero_copy_reason}")
            return out
        if torch is not None:
            # primary_rays' arrays are transposed views (strides (4, 4N)): the contiguous
            # rows are made explicitly, the strided ones are timed apart below
            ot = torch.from_numpy(np.ascontiguousarray(o)).cuda()
            dt = torch.from_numpy(np.ascontiguousarray(d)).cuda()
            before = dict(interop.copies)
            phases: list[dict[str, float]] = []
            with MapCounter() as maps:
                times, got = timed_casts(rs, ot, dt, args.casts, args.warmup,
                                         torch.from_dlpack, torch.cuda.synchronize,
                                         phases=phases)
            copies = {k: interop.copies[k] - before[k] for k in before}
            out["torch"] = {**summary(times), "last": rs.last, "maps_during_casts":
                            maps.counts, "rfw_copies_during_casts": copies,
                            "phases_us_median": median_phases(phases),
                            "cuda_calls_per_cast": calls_of_a_cast(rs, ot, dt)}
            before = dict(interop.copies)
            rs.cast(ot, dt, out="host")  # the counter's control: hits copied to the host
            out["torch"]["rfw_copies_of_a_host_cast"] = {
                k: interop.copies[k] - before[k] for k in before}
            for k in want:
                same = np.array_equal(got[k].cpu().numpy(), want[k])
                out["torch"][f"{k}_equal_host_path"] = same
                if not same:
                    note(f"device hits '{k}' differ from the host path's")
            out["torch"]["pointer"] = pointer_proof(rs, got["t"])
            out["torch"]["profiler"] = profiler_proof(torch, rs, ot, dt)
            for name, (os_, ds_) in strided_rays(torch, ot, dt).items():
                try:
                    ph: list[dict[str, float]] = []
                    times, got = timed_casts(rs, os_, ds_, args.casts, args.warmup,
                                             torch.from_dlpack, torch.cuda.synchronize,
                                             phases=ph)
                    out[f"torch_{name}"] = {
                        **summary(times), "strides": [list(os_.stride()), list(ds_.stride())],
                        "phases_us_median": median_phases(ph),
                        "last": rs.last, "t_equal_host_path": bool(np.array_equal(
                            got["t"].cpu().numpy(), want["t"]))}
                except Exception as e:
                    note(f"strided rays '{name}' failed ({error_line(e)})")
                    out[f"torch_{name}"] = {"error": error_line(e)}
            try:
                out["torch_device_rays"], out["torch_device_rays_written"] = \
                    device_rays_rows(args, torch, rs, ot, dt, want)
            except Exception as e:
                note(f"device_rays rows failed ({error_line(e)})")
                out["torch_device_rays"] = {"error": error_line(e), "where": traceback
                                            .format_exc().strip().splitlines()[-4:]}
        if cupy is not None:
            oc, dc = cupy.asarray(o), cupy.asarray(d)
            sync = cupy.cuda.runtime.deviceSynchronize
            ph = []
            times, got = timed_casts(rs, oc, dc, args.casts, args.warmup, cupy.asarray, sync,
                                     phases=ph)
            out["cupy"] = {**summary(times), "last": rs.last, "strides": [oc.strides, dc.strides],
                           "phases_us_median": median_phases(ph),
                           "t_equal_host_path": bool(np.array_equal(cupy.asnumpy(got["t"]),
                                                                    want["t"]))}
            # cupy.asarray keeps primary_rays' transposed layout (above): C-contiguous here
            oc, dc = cupy.asarray(np.ascontiguousarray(o)), cupy.asarray(np.ascontiguousarray(d))
            ph = []
            times, got = timed_casts(rs, oc, dc, args.casts, args.warmup, cupy.asarray, sync,
                                     phases=ph)
            out["cupy_contiguous"] = {
                **summary(times), "last": rs.last, "strides": [oc.strides, dc.strides],
                "phases_us_median": median_phases(ph),
                "t_equal_host_path": bool(np.array_equal(cupy.asnumpy(got["t"]), want["t"]))}
    finally:
        rs.close()
    return out


def device_rays_rows(args: argparse.Namespace, torch: Any, rs: Any, ot: Any, dt: Any,
                     want: dict[str, np.ndarray]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Rays written by torch into ``rs.device_rays(n)`` (the scene's exported ray buffer),
    cast in place (no copy in): the timed region as the torch row's (sync, cast, wrap,
    sync), the rays written once before; then with the write (``copy_`` from the ray
    tensors, as generating them there would) inside the timed region."""
    from rfw import interop

    n = ot.shape[0]
    ro, rd = rs.device_rays(n)
    to, td = torch.from_dlpack(ro), torch.from_dlpack(rd)
    to.copy_(ot)
    td.copy_(dt)
    torch.cuda.synchronize()
    rows = []
    for write in (None, lambda: (to.copy_(ot), td.copy_(dt))):
        before = dict(interop.copies)
        phases: list[dict[str, float]] = []
        times, got = timed_casts(rs, ro, rd, args.casts, args.warmup, torch.from_dlpack,
                                 torch.cuda.synchronize, write=write, phases=phases)
        copies = {k: interop.copies[k] - before[k] for k in before}
        row = {**summary(times), "last": rs.last, "rfw_copies_during_casts": copies,
               "phases_us_median": median_phases(phases),
               "rays_ptr_is_exported_buffer": to.data_ptr() == rs._scene.shared.rays.cuda_ptr,
               **{f"{k}_equal_host_path": bool(np.array_equal(got[k].cpu().numpy(), want[k]))
                  for k in want}}
        if write is None:
            row["cuda_calls_per_cast"] = calls_of_a_cast(rs, ro, rd)
        rows.append(row)
        if not all(row[f"{k}_equal_host_path"] for k in want):
            note(f"device_rays hits ({'written' if write else 'in place'}) differ from the "
                 f"host path's")
    return rows[0], rows[1]


def strided_rays(torch: Any, o: Any, d: Any) -> dict[str, tuple[Any, Any]]:
    """The same rays as strided device views: transposed (strides (1, N) elements) and the
    first three columns of (N, 8) tensors (row stride 8)."""
    def wide(x: Any) -> Any:
        w = torch.zeros((x.shape[0], 8), dtype=x.dtype, device=x.device)
        w[:, :3] = x
        return w[:, :3]

    return {"transposed": (o.t().contiguous().t(), d.t().contiguous().t()),
            "slice_of_n8": (wide(o), wide(d))}


def pointer_proof(rs: Any, tensor: Any) -> dict[str, Any]:
    """The hit tensor's pointer as the CUDA driver sees it, and the exported buffer's range."""
    from rfw import interop

    try:
        kind, ordinal = interop.cuda().pointer(int(tensor.data_ptr()))
        hits = rs._scene.shared.hits
        inside = hits.cuda_ptr <= int(tensor.data_ptr()) < hits.cuda_ptr + hits.bytes
        return {"memory_type": kind, "device_memory": kind == 2, "ordinal": ordinal,
                "inside_exported_hits": bool(inside),
                "exported_hits_memory": "device-local, VkExportMemoryAllocateInfo opaque fd"}
    except Exception as e:
        note(f"pointer check failed ({error_line(e)})")
        return {"error": error_line(e)}


def profiler_proof(torch: Any, rs: Any, o: Any, d: Any) -> dict[str, Any]:
    """CUDA memcpy activity (CUPTI, through the torch profiler) over a few casts."""
    try:
        from torch.profiler import ProfilerActivity, profile

        def memcpys(out: str) -> dict[str, int]:
            with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
                for _ in range(5):
                    hits = rs.cast(o, d, out=out)
                    if out == "device":
                        torch.from_dlpack(hits["t"]).sum()  # a consumer kernel on the hits
                torch.cuda.synchronize()
            names: dict[str, int] = {}
            for e in prof.events():
                if "memcpy" in e.name.lower() or "memset" in e.name.lower():
                    names[e.name] = names.get(e.name, 0) + 1
            return names

        def dtoh(names: dict[str, int]) -> int:
            return sum(c for n, c in names.items() if "dtoh" in n.lower().replace(" ", ""))

        device, host = memcpys("device"), memcpys("host")  # host: the control, must see DtoH
        return {"casts": 5, "memcpy_events": device, "device_to_host_memcpys": dtoh(device),
                "control_out_host_memcpy_events": host,
                "control_device_to_host_memcpys": dtoh(host)}
    except Exception as e:
        note(f"torch profiler proof not taken ({error_line(e)})")
        return {"error": error_line(e)}


# ---------------------------------------------------------------------------------------------
# images


def image_section(args: argparse.Namespace, torch: Any) -> dict[str, Any]:
    out: dict[str, Any] = {"size": [1920, 1080], "format": "rgba16float"}
    if torch is None:
        note("no torch: the image rows are skipped")
        return out
    out["export"] = image_export(args, torch)
    out["render"] = image_render(args, torch, in_frame=False)
    out["render_in_frame"] = image_render(args, torch, in_frame=True)
    out["render_in_frame_wrapped"] = image_render(args, torch, in_frame=True, wrapped=True)
    per, inf = out["render"], out["render_in_frame"]
    if "frame_gpu_ms_passes" in per and "frame_gpu_ms_passes" in inf:
        copy = inf.get("in_frame_copy_gpu_ms") or 0.0
        out["cost"] = {"frame_gpu_ms_without_copy": per["frame_gpu_ms_passes"],
                       "frame_gpu_ms_with_in_frame_copy": inf["frame_gpu_ms_passes"] + copy,
                       "in_frame_copy_gpu_ms": inf.get("in_frame_copy_gpu_ms"),
                       "per_read_us": per.get("median_us"),
                       "in_frame_read_us": inf.get("median_us"),
                       "in_frame_wrapped_read_us":
                           out["render_in_frame_wrapped"].get("median_us")}
    return out


def image_export(args: argparse.Namespace, torch: Any) -> dict[str, Any]:
    """vkext.external.ImageExport of a cleared 1920x1080 image (the render stand-in)."""
    from vkext import VkDevice
    from vkext.commands import read_image
    from vkext.external import CudaLink, ImageExport, cuda_link
    from vkext.images import Image

    dev = VkDevice()
    try:
        link = cuda_link(dev)
        if not isinstance(link, CudaLink):
            note(f"no image export: {link}")
            return {"error": link}
        img = Image(dev, 1920, 1080, "rgba16float", ("transfer_src", "transfer_dst",
                                                    "sampled", "color"),
                    label="bench image")
        img.allocate()
        _clear(dev, img, 0.375)
        exp = ImageExport(dev, img, layout_now="TRANSFER_DST_OPTIMAL",
                          layout_after="TRANSFER_DST_OPTIMAL", link=link)
        times, tensor = [], None
        for i in range(args.warmup + args.casts):
            torch.cuda.synchronize()
            t0 = time.perf_counter()
            tensor = torch.from_dlpack(exp.read())
            torch.cuda.synchronize()
            if i >= args.warmup:
                times.append(time.perf_counter() - t0)
        want = read_image(dev, img, layout_now="TRANSFER_DST_OPTIMAL")
        same = bool(np.array_equal(tensor.cpu().numpy(), want))
        res = {**summary(times), "median_us": statistics.median(times) * 1e6,
               "equal_host_readback": same, "shape": list(tensor.shape),
               "dtype": str(tensor.dtype), "tensor_device": str(tensor.device)}
        del tensor
        exp.destroy()
        img.destroy()
        return res
    except Exception as e:
        note(f"image export failed ({error_line(e)})")
        return {"error": error_line(e)}
    finally:
        dev.destroy()


def image_render(args: argparse.Namespace, torch: Any, *, in_frame: bool,
                 wrapped: bool = False) -> dict[str, Any]:
    """forward.hdr of a real vk render as a torch tensor, in each_frame through
    rfw.interop.read_device: the frames drained (the render done), then timed to the tensor
    usable. ``in_frame``: after frame 0, ``rfw.interop.device_outputs`` makes each frame's
    own command buffer copy the output into exported memory (ordered by the frame's fence),
    so the read is the wrapper alone; else each read submits the copy and waits (the old
    path). ``wrapped``: ``read_device(..., wrap=torch.from_dlpack)``, which wraps each slot's
    buffer once and hands that tensor out again (no dlpack exchange per read). The tensor is checked against the host readback inside the frame (the device
    goes with the render)."""
    from rfw import interop
    from rfw.config import apply_overrides, load_config
    from rfw.render import render

    cfg = apply_overrides(load_config(ROOT / "configs" / "forward.toml"),
                          ["size=1920x1080", f"frames={args.warmup + args.frames}"])
    cfg = replace(cfg, outputs=["forward.hdr"])
    times: list[float] = []
    keep: dict[str, Any] = {}
    parts: dict[str, list[float]] = {}

    def read(frame: Any) -> tuple[Any, Any, float]:
        """(the array or None, the tensor, when read_device returned): with ``wrapped``
        read_device makes the tensor itself (the from_dlpack part is then 0)."""
        if wrapped:
            t = interop.read_device(frame, "forward.hdr", wrap=torch.from_dlpack)
            return None, t, time.perf_counter()
        a = interop.read_device(frame, "forward.hdr")
        read_at = time.perf_counter()
        return a, (torch.from_dlpack(a) if a.zero_copy else None), read_at

    def each(k: int, frame: Any) -> None:
        if in_frame and k == 0:
            keep["why_not"] = interop.device_outputs(frame, ["forward.hdr"])["forward.hdr"]
            if keep["why_not"]:
                note(f"no in-frame device output: {keep['why_not']}")
        frame.drain()  # the render done
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        a, t, _ = read(frame)
        torch.cuda.synchronize()
        if k >= args.warmup:
            times.append(time.perf_counter() - t0)
            # the same steps timed one by one after the timed read (where the time goes)
            c0 = time.perf_counter()
            a, t, c1 = read(frame)
            c2 = time.perf_counter()
            torch.cuda.synchronize()
            c3 = time.perf_counter()
            for part, v in (("read_device", c1 - c0), ("from_dlpack", c2 - c1),
                            ("synchronize", c3 - c2)):
                parts.setdefault(part, []).append(v * 1e6)
        if k == args.warmup:  # checked here: the arrays die with the render's device
            keep["zero_copy"], keep["device"] = (bool(t.is_cuda), str(t.device)) if wrapped \
                else (a.zero_copy, a.device)
            if t is not None:
                keep["equal_host_readback"] = bool(np.array_equal(
                    t.cpu().numpy(), frame.read("forward.hdr")))
        ex = frame.executors.get("vk")
        exports = getattr(ex, "frame_exports", None)
        if exports is not None and exports.last is not None:  # after the timed read
            exports.read_timer()
            keep["copy_gpu_ms"] = list(exports.gpu_ms)

    try:
        result = render(cfg, backend="vk", each_frame=each)
        res = {**summary(times), "median_us": statistics.median(times) * 1e6,
               "frames": len(times), "frame_gpu_ms_passes": result.gpu_ms_total,
               "parts_us_median": {k: statistics.median(v) for k, v in parts.items()},
               **{k: keep.get(k) for k in ("zero_copy", "device", "equal_host_readback")}}
        if in_frame:
            copy = keep.get("copy_gpu_ms") or []
            res["in_frame_copy_gpu_ms"] = statistics.median(copy[args.warmup:] or copy) \
                if copy else None
            res["copy_gpu_ms_n"] = len(copy)
            res["why_not"] = keep.get("why_not")
        if keep.get("equal_host_readback") is False:
            note(f"render image ({'in-frame' if in_frame else 'per-read'}) differs from "
                 f"the host readback")
        return res
    except Exception as e:
        note(f"render image read ({'in-frame' if in_frame else 'per-read'}) failed "
             f"({error_line(e)})")
        return {"error": error_line(e), "where": traceback.format_exc().strip()
                .splitlines()[-4:]}


# ---------------------------------------------------------------------------------------------


def verdicts(rec: dict[str, Any]) -> dict[str, Any]:
    rays, img = rec.get("rays", {}), rec.get("image", {})
    cast = rays.get("torch", {}).get("median_ms")
    embree = rays.get("embree", {}).get("median_ms")
    image = img.get("render_in_frame", {}).get("median_us")
    wrapped = img.get("render_in_frame_wrapped", {}).get("median_us")
    torch_rec = rays.get("torch", {})
    out = {"cast_ms": cast, "cast_ms_target": TARGETS["cast_ms"],
           "cast_ok": cast is not None and cast <= TARGETS["cast_ms"],
           "embree_ratio": embree / cast if cast and embree else None,
           "embree_ratio_target": TARGETS["embree_ratio"],
           "image_us": image, "image_us_target": TARGETS["image_us"],
           "image_ok": image is not None and image <= TARGETS["image_us"],
           "image_wrapped_us": wrapped,
           "image_wrapped_ok": wrapped is not None and wrapped <= TARGETS["image_us"],
           "zero_device_to_host": (
               torch_rec.get("rfw_copies_during_casts", {}).get("device_to_host") == 0
               and not any(torch_rec.get("maps_during_casts", {"x": 1}).values())
               and torch_rec.get("pointer", {}).get("device_memory") is True)
           if torch_rec else None}
    out["embree_ok"] = out["embree_ratio"] is not None and \
        out["embree_ratio"] >= TARGETS["embree_ratio"]
    for row in ("torch_device_rays", "torch_device_rays_written"):
        ms = rays.get(row, {}).get("median_ms")
        out[f"{row}_ms"] = ms
        out[f"{row}_ok"] = ms is not None and ms <= TARGETS["cast_ms"]
        out[f"{row}_embree_ratio"] = embree / ms if ms and embree else None
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--probe", action="store_true", help="run each step alone and report")
    ap.add_argument("--size", default="1280x720", help="primary rays: WxH")
    ap.add_argument("--casts", type=int, default=60, help="timed casts (and image reads)")
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--frames", type=int, default=60, help="timed frames of the render")
    ap.add_argument("--embree-repeats", type=int, default=20)
    ap.add_argument("--sections", default="rays,image")
    ap.add_argument("--out", type=Path, help="JSON file (default: $OUT/bench_zerocopy.json)")
    args = ap.parse_args(argv)
    args.size = tuple(int(x) for x in args.size.lower().split("x"))
    target = args.out or (Path(os.environ["OUT"]) / "bench_zerocopy.json"
                          if os.environ.get("OUT") else None)
    rec: dict[str, Any] = {"commit": os.environ.get("RFW_COMMIT", "unknown")}
    if args.probe:
        rec.update(probe())
        if target is not None:
            target = target.with_name("bench_zerocopy_probe.json")
    else:
        torch = optional("torch")
        if torch is not None and not torch.cuda.is_available():
            note("torch has no CUDA device: the torch rows are skipped")
            torch = None
        cupy = optional("cupy")
        sections = set(args.sections.split(","))
        for name, fn in (("rays", lambda: rays_section(args, torch, cupy)),
                         ("image", lambda: image_section(args, torch))):
            if name not in sections:
                continue
            try:
                rec[name] = fn()
            except Exception as e:  # a section that fails is a note
                note(f"section {name} failed ({error_line(e)})")
                rec[name] = {"error": error_line(e), "where": traceback.format_exc()
                             .strip().splitlines()[-4:]}
        rec["verdicts"] = verdicts(rec)
    rec["notes"] = notes
    text = json.dumps(rec, indent=1, default=str)
    print(text)
    if target is not None:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text + "\n")
        print(f"bench_zerocopy: wrote {target}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
