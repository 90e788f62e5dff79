"""Transient memory without a GPU: the bytes and alignment a driver asks for each image and
buffer (what ``vkGetDeviceImageMemoryRequirements`` / ``...BufferMemoryRequirements``
return), modelled per device profile, so a plan predicts what the vk executor allocates.

The vk backend compiles a graph, asks the driver for every transient's requirements and
places the plan again with them (``vkext.fitting.fit_graph``: the largest alignment per kind,
each resource's exact size). :func:`predict` does the same with a profile's model in place of
the driver, so where the model is exact the predicted heaps are the allocated ones.

Profiles
--------
``lavapipe``
    Mesa's llvmpipe texture layout: each mip level's width and height rounded up to 4
    texels (compressed formats: whole blocks), rows padded to the CPU's cache line, each level
    to 64 bytes, times the sample count; buffers take their exact size; alignment 64.
    Checked against the driver on 640 random images (16 formats, mips, layers, MSAA): exact.
``nvidia``
    NVIDIA's block-linear layout: 64-byte x 8-row GOBs, a block height per level of the
    smallest power of two of GOBs that holds the level's rows, at most 16 (128 rows), rows
    padded to 64 bytes, MSAA as a wider and taller image; images aligned and padded to
    1 KiB (what the H200's driver asks for; 64 KiB pages were the first guess). This is
    the layout NVIDIA's Tegra documentation and nouveau describe; the
    proprietary driver's private padding (compression tags, its own block-height choice) is
    not public: ``benchmarks/device_memplan.sh`` measures how far it is off on a device.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, fields, replace
from pathlib import Path

from ..units import align_up
from .compile import place
from .formats import format_info
from .plan import CompiledGraph, MemoryOptions, ResourcePlan

__all__ = ["PROFILES", "Profile", "model_options", "predict", "profile", "requirements"]


@dataclass(frozen=True)
class Profile:
    """How one driver lays out images and buffers in memory."""

    name: str
    about: str

    def image(self, format: str, width: int, height: int, *, mips: int = 1, layers: int = 1,
              samples: int = 1, usages: Iterable[str] = ()) -> tuple[int, int]:
        """(bytes, alignment) of one optimal-tiling 2D image."""
        raise NotImplementedError

    def buffer(self, size: int, usages: Iterable[str] = ()) -> tuple[int, int]:
        """(bytes, alignment) of one buffer of ``size`` bytes."""
        raise NotImplementedError


def _levels(width: int, height: int, mips: int) -> Iterable[tuple[int, int]]:
    for _ in range(mips):
        yield width, height
        width, height = max(width >> 1, 1), max(height >> 1, 1)


@dataclass(frozen=True)
class Lavapipe(Profile):
    cacheline: int = 64  # util_get_cpu_caps()->cacheline: 64 on x86, 128 on some ARM cores

    def image(self, format, width, height, *, mips=1, layers=1, samples=1, usages=()):
        info = format_info(format)
        level_align = max(64, self.cacheline)
        total = 0
        for w, h in _levels(width, height, mips):
            if info.compressed:
                row = -(-w // info.block_width) * info.block_bytes
                rows = -(-h // info.block_height)
            else:  # 4x4 raster blocks, rows on cache lines
                row = align_up(align_up(w, 4) * info.block_bytes, self.cacheline)
                rows = align_up(h, 4)
            total += align_up(row * rows * layers, level_align)
        return total * samples, 64

    def buffer(self, size, usages=()):
        return size, 64


# samples -> (x, y) factors of an MSAA surface stored as a larger single-sample one
_SAMPLE_GRID = {1: (1, 1), 2: (2, 1), 4: (2, 2), 8: (4, 2), 16: (4, 4)}


@dataclass(frozen=True)
class Nvidia(Profile):
    gob_bytes: int = 64  # a GOB is 64 bytes wide
    gob_rows: int = 8  # and 8 rows tall
    max_block_gobs: int = 16  # block height in GOBs, at most
    # image sizes and alignment: 1 KiB on the H200 (driver 580.159.04: its requirements for
    # 240 probed images, benchmarks/results/2026-12-03/memplan_h200/); 64 KiB pages, the
    # guess before that, gave the same totals there but no small image's size
    page: int = 1024

    def image(self, format, width, height, *, mips=1, layers=1, samples=1, usages=()):
        info = format_info(format)
        sx, sy = _SAMPLE_GRID.get(samples, (samples, 1))
        layer = 0
        block = self.max_block_gobs
        first_block = None
        for w, h in _levels(width, height, mips):
            cols = -(-w // info.block_width) * sx
            rows = -(-h // info.block_height) * sy
            gobs = -(-rows // self.gob_rows)
            block = min(block, 1 << max(gobs - 1, 0).bit_length())
            first_block = first_block or block
            layer += align_up(cols * info.block_bytes, self.gob_bytes) * \
                align_up(rows, self.gob_rows * block)
        layer = align_up(layer, self.gob_bytes * self.gob_rows * (first_block or 1))
        return align_up(layer * layers, self.page), self.page

    def buffer(self, size, usages=()):
        return align_up(size, 256), 256


PROFILES: dict[str, Profile] = {
    "lavapipe": Lavapipe("lavapipe", "Mesa lavapipe (llvmpipe layout, x86 cache lines); "
                                     "exact on Mesa 22-23"),
    "nvidia": Nvidia("nvidia", "NVIDIA block-linear (64x8-byte GOBs, blocks of <= 16 GOBs, "
                               "1 KiB alignment; measured on the H200, driver 580); "
                               "driver-private padding not modelled"),
}


def profile(name: str) -> Profile:
    """The profile of that name, or of a JSON file (``{"base": "nvidia", "page": 131072}``:
    a known profile with some of its parameters changed, e.g. fitted to a device by
    ``benchmarks/bench_memplan.py``); a ValueError saying what is wrong."""
    if name.lower().endswith(".json"):
        return _profile_file(Path(name))
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown device profile '{name}' (known: "
                         f"{', '.join(sorted(PROFILES))}, or a .json file)") from None


def _profile_file(path: Path) -> Profile:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"device profile {path}: {e}") from None
    if not isinstance(data, dict) or data.get("base") not in PROFILES:
        raise ValueError(f"device profile {path}: expected an object with \"base\": one of "
                         f"{', '.join(sorted(PROFILES))}")
    base = PROFILES[data.pop("base")]
    known = {f.name for f in fields(base)} - {"name", "about"}
    unknown = sorted(set(data) - known)
    if unknown or not all(isinstance(v, int) and v > 0 for v in data.values()):
        raise ValueError(f"device profile {path}: parameters of '{base.name}' are positive "
                         f"integers among {', '.join(sorted(known))}"
                         + (f" (unknown: {', '.join(unknown)})" if unknown else ""))
    return replace(base, name=f"{base.name}:{path.name}", **data)


def _usages(r: ResourcePlan, readback: bool) -> frozenset[str]:
    # what the vk executor creates the resource with (vkext.memory's _image_usages)
    return frozenset(r.usages) | ({"transfer_src"} if readback else frozenset())


def requirements(plan: CompiledGraph, prof: Profile, *,
                 readback: bool = True) -> dict[str, tuple[int, int]]:
    """The modelled (size, alignment) of each transient of ``plan``, as
    ``vkext.memory.requirements`` gives the driver's."""
    out: dict[str, tuple[int, int]] = {}
    for r in plan.resources:
        if not r.transient or r.heap is None:
            continue
        if r.kind == "image":
            out[r.name] = prof.image(r.format, r.width, r.height, mips=r.mips,
                                     layers=r.layers, samples=r.samples,
                                     usages=_usages(r, readback))
        else:
            out[r.name] = prof.buffer(r.raw_bytes, _usages(r, readback))
    return out


def model_options(plan: CompiledGraph, prof: Profile, *, base: MemoryOptions | None = None,
                  readback: bool = True) -> MemoryOptions:
    """Placement rules as ``vkext.memory.memory_options`` derives them from a driver: per
    kind the largest alignment, and every resource's size, from the profile instead."""
    base = base or MemoryOptions()
    reqs = requirements(plan, prof, readback=readback)
    kinds = {r.name: r.kind for r in plan.resources}
    chosen = {"image": base.image_alignment, "buffer": base.buffer_alignment}
    for kind in chosen:
        aligns = [a for name, (_, a) in reqs.items() if kinds[name] == kind]
        if aligns:
            chosen[kind] = max(aligns)
    return replace(base, image_alignment=chosen["image"], buffer_alignment=chosen["buffer"],
                   sizes=tuple(sorted((n, s) for n, (s, _) in reqs.items())))


def predict(plan: CompiledGraph, prof: Profile, *, alias: bool = True,
            readback: bool = True) -> CompiledGraph:
    """``plan`` placed as the vk backend would place it on a device of that profile: its
    ``transient_bytes`` are the bytes the executor's heaps would have."""
    base = MemoryOptions(alias=alias)
    return place(plan, model_options(plan, prof, base=base, readback=readback))
