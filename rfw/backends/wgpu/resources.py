"""Textures and buffers from the compiled plan: WebGPU formats and usage flags.

WebGPU cannot alias memory, so transient resources with identical descriptions and disjoint
lifetimes share one texture instead (:func:`share_textures`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable

import wgpu

from ...graph.compile import ResourcePlan
from ...graph.formats import format_info
from ...shaders import ShaderError

_USAGE = {"sampled": wgpu.TextureUsage.TEXTURE_BINDING,
          "storage": wgpu.TextureUsage.STORAGE_BINDING,
          "color": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "depth": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "depth_read": wgpu.TextureUsage.RENDER_ATTACHMENT,
          "shading_rate": wgpu.TextureUsage.TEXTURE_BINDING,
          "transfer_src": wgpu.TextureUsage.COPY_SRC,
          "transfer_dst": wgpu.TextureUsage.COPY_DST}


def wgpu_format(name: str) -> str:
    info = format_info(name)
    if info.wgpu is None:
        raise ShaderError(f"format {name} has no WebGPU equivalent")
    return info.wgpu


_BUFFER_USAGE = {"storage": wgpu.BufferUsage.STORAGE, "uniform": wgpu.BufferUsage.UNIFORM,
                 "indirect": wgpu.BufferUsage.INDIRECT, "vertex": wgpu.BufferUsage.VERTEX,
                 "index": wgpu.BufferUsage.INDEX, "transfer_src": wgpu.BufferUsage.COPY_SRC,
                 "transfer_dst": wgpu.BufferUsage.COPY_DST}


def usage_flags(usages: Iterable[str]) -> int:
    """wgpu buffer usage flags of rfw's usage names (unknown names add none)."""
    usage = 0
    for u in usages:
        usage |= _BUFFER_USAGE.get(u, 0)
    return usage


def buffer_usage(r: ResourcePlan) -> int:
    # copies both ways so buffers can be cleared, filled and read back
    return wgpu.BufferUsage.COPY_SRC | wgpu.BufferUsage.COPY_DST | usage_flags(r.usages)


def texture_usage(r: ResourcePlan, readback: bool) -> int:
    usage = 0
    for u in r.usages:
        usage |= _USAGE.get(u, 0)
    return usage | (wgpu.TextureUsage.COPY_SRC if readback else 0)


def share_textures(plans: list[ResourcePlan], readback: set[str],
                   spans: dict[str, tuple[int, int]]) -> dict[str, str]:
    """Map each transient to the resource whose texture it reuses (itself if none).

    Same format, size, mips, layers, samples and usage, and lifetimes that do not overlap.
    """
    owner: dict[str, str] = {}
    busy: dict[tuple, list[tuple[str, int]]] = defaultdict(list)  # key -> [(owner, last)]
    for r in sorted(plans, key=lambda r: spans[r.name][0]):
        if not r.transient or r.name in readback:
            owner[r.name] = r.name
            continue
        key = (r.format, r.width, r.height, r.mips, r.layers, r.samples,
               texture_usage(r, False))
        first, last = spans[r.name]
        for k, (o, end) in enumerate(busy[key]):
            if end < first:
                owner[r.name] = o
                busy[key][k] = (o, last)
                break
        else:
            owner[r.name] = r.name
            busy[key].append((r.name, last))
    return owner
