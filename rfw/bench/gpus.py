"""Which device a Ray GPU id is: its UUID, so a bench task opens that GPU by UUID.

Ray numbers a node's GPUs as NVML and CUDA do (``CUDA_VISIBLE_DEVICES``), while ``RFW_GPU``'s
index counts the Vulkan driver's devices, in an order nobody promises is the same; a UUID
names one GPU in all three (Vulkan's ``deviceUUID`` is CUDA's and NVML's). The sources, in
order: NVML (``pynvml``, where it imports), ``nvidia-smi --query-gpu=index,uuid``, then CUDA's
``cuDeviceGetUuid`` (:func:`rfw.interop.cuda`), whose ordinals count the task's
``CUDA_VISIBLE_DEVICES``. docs/multi-gpu.md says what of this has run on real GPUs.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from typing import Any

from ..env import uuid_hex
from ..errors import RfwError

SMI_TIMEOUT_S = 20.0


def uuid_of_gpu(gpu_id: str) -> tuple[str | None, str]:
    """The UUID (32 lowercase hex digits) of the GPU Ray calls ``gpu_id``, and which source
    said so (or, with None, why none could)."""
    given = uuid_hex(gpu_id) if gpu_id.startswith("GPU-") else None
    if given:  # CUDA_VISIBLE_DEVICES may name GPUs by UUID, and Ray's ids are then those
        return given, "ray"
    if not gpu_id.isdigit():
        return None, f"Ray's GPU id {gpu_id!r} is neither an index nor a GPU-<uuid>"
    index = int(gpu_id)
    tried = []
    for name, source in (("nvml", _nvml), ("nvidia-smi", _smi), ("cuda", _cuda)):
        try:
            table = source()
        except Exception as e:  # a source that is missing or broken: the next one
            tried.append(f"{name}: {' '.join(str(e).split())[:120] or type(e).__name__}")
            continue
        if index in table:
            return table[index], name
        tried.append(f"{name}: no GPU {index} among {len(table)}")
    return None, "no source names it (" + "; ".join(tried) + ")"


def _nvml() -> dict[int, str]:
    import pynvml  # optional: nvidia-ml-py

    pynvml.nvmlInit()
    try:
        out = {}
        for i in range(pynvml.nvmlDeviceGetCount()):
            raw = pynvml.nvmlDeviceGetUUID(pynvml.nvmlDeviceGetHandleByIndex(i))
            out[i] = _checked(raw.decode() if isinstance(raw, bytes) else raw, "nvml")
        return out
    finally:
        pynvml.nvmlShutdown()


def parse_smi(text: str) -> dict[int, str]:
    """``nvidia-smi --query-gpu=index,uuid --format=csv,noheader``'s lines as index -> UUID."""
    out = {}
    for line in text.splitlines():
        if not line.strip():
            continue
        index, _, uuid = (x.strip() for x in line.partition(","))
        if not index.isdigit():
            raise RfwError(f"nvidia-smi printed {line.strip()[:80]!r}")
        out[int(index)] = _checked(uuid, "nvidia-smi")
    return out


def _smi() -> dict[int, str]:
    exe = shutil.which("nvidia-smi")
    if exe is None:
        raise RfwError("not on PATH")
    done = subprocess.run([exe, "--query-gpu=index,uuid", "--format=csv,noheader"],
                          capture_output=True, text=True, timeout=SMI_TIMEOUT_S, check=False)
    if done.returncode:
        raise RfwError(f"exit {done.returncode}: {done.stderr.strip()[:120]}")
    return parse_smi(done.stdout)


def _cuda() -> dict[int, str]:
    from ..interop import cuda

    driver = cuda()
    # CUDA's ordinals count CUDA_VISIBLE_DEVICES (Ray sets it to the task's GPUs): Ray's
    # index is its place there, and where it is unset, the ordinal itself
    visible = [x.strip() for x in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",")
               if x.strip()]
    ordinals: dict[int, int] = {}
    for ordinal in range(driver.devices()):
        if not visible:
            ordinals[ordinal] = ordinal
        elif ordinal < len(visible) and visible[ordinal].isdigit():
            ordinals[int(visible[ordinal])] = ordinal
    return {index: driver.uuid(o).hex() for index, o in ordinals.items()}


def _checked(uuid: Any, source: str) -> str:
    digits = uuid_hex(str(uuid))
    if digits is None:
        raise RfwError(f"{source} gave {str(uuid)[:60]!r}, not a UUID")
    return digits
