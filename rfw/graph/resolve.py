"""Step 4 of ``compile``: size rules to texels, formats to bytes."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from .errors import GraphError, did_you_mean
from .formats import image_bytes
from .plan import MAX_DIMENSION, RASTER, Declared, _Problems
from .resources import ResourceDecl, SizeRule

# ---------------------------------------------------------------------------------------------
# step 4: resolve sizes and formats


@dataclass(frozen=True)
class Resolved:
    name: str
    kind: str
    format: str | None
    width: int
    height: int
    mips: int
    layers: int
    samples: int
    raw_bytes: int


def resolve(declared: Declared, used: Iterable[str], size: tuple[int, int],
            problems: _Problems) -> dict[str, Resolved]:
    """Turn size rules into texels and formats into bytes."""
    out: dict[str, Resolved] = {}
    sizes: dict[str, tuple[int, int]] = {}
    for name in used:
        r = declared.resources[name]
        if r.kind == "buffer":
            out[name] = Resolved(name, "buffer", None, 0, 0, 1, 1, 1, r.bytes or 0)
            continue
        if r.kind == "accel":  # its builder owns its memory: nothing for the heaps
            out[name] = Resolved(name, "accel", None, 0, 0, 1, 1, 1, 0)
            continue
        if r.format is None:  # lenient: application-owned image of unknown shape
            out[name] = Resolved(name, "image", None, 0, 0, 1, 1, 1, 0)
            continue
        w, h = _resolve_size(name, declared.resources, size, sizes, [])
        if not (1 <= w <= MAX_DIMENSION and 1 <= h <= MAX_DIMENSION):
            where = f"pass '{r.producer}', slot '{r.slot}'" if r.producer else "external"
            shape = f"{w}x{h}" if max(w, h) <= MAX_DIMENSION else f"over {MAX_DIMENSION}"
            problems.error(f"{where}: '{name}' resolves to {shape} texels "
                           f"(size rule {r.size.describe()}; 1..{MAX_DIMENSION} allowed)")
            continue
        shape = (r.format, w, h, r.mips, r.layers, r.samples)
        raw = _IMAGE_BYTES.get(shape)
        if raw is None:
            if len(_IMAGE_BYTES) > 4096:  # many output sizes over a long session
                _IMAGE_BYTES.clear()
            try:
                raw = _IMAGE_BYTES[shape] = image_bytes(r.format, w, h, mips=r.mips,
                                                        layers=r.layers, samples=r.samples)
            except ValueError as e:
                where = f"pass '{r.producer}', slot '{r.slot}': " if r.producer else ""
                problems.error(f"{where}'{name}': {e}")
                continue
        out[name] = Resolved(name, "image", r.format, w, h, r.mips, r.layers, r.samples, raw)
    return out


# (format, width, height, mips, layers, samples) -> bytes: big graphs repeat a few shapes
_IMAGE_BYTES: dict[tuple, int] = {}


def _resolve_size(name: str, resources: dict[str, ResourceDecl], size: tuple[int, int],
                  memo: dict[str, tuple[int, int]], stack: list[str]) -> tuple[int, int]:
    if name in memo:
        return memo[name]
    if name in stack:
        raise GraphError("size rules form a cycle: " + " -> ".join([*stack, name]))
    rule = resources[name].size or SizeRule.output()
    if rule.mode == "fixed":
        wh = (rule.width, rule.height)
    else:
        if rule.mode == "relative":
            if rule.of not in resources or resources[rule.of].kind != "image":
                raise GraphError(f"'{name}' is sized like '{rule.of}', which is not an image "
                                 "of the graph" + did_you_mean(str(rule.of), resources))
            base = _resolve_size(rule.of, resources, size, memo, [*stack, name])
        else:
            base = size
        # truncation, as Raptor does: a 0.5 scale of 1281 is 640
        sx, sy = (base[0] * rule.scale[0], base[1] * rule.scale[1])
        wh = (int(sx) if math.isfinite(sx) else 0, int(sy) if math.isfinite(sy) else 0)
    memo[name] = wh
    return wh


def check_attachment_sizes(declared: Declared, kept: list[int], resolved: dict[str, Resolved],
                           problems: _Problems) -> None:
    """A render pass has one framebuffer size: its attachments must agree."""
    for i in kept:
        p = declared.passes[i]
        if p.type not in RASTER:
            continue
        sizes = {(a.resource, resolved[a.resource].width, resolved[a.resource].height)
                 for a in declared.accesses[p.name]
                 if a.usages & {"color", "depth", "depth_read"} and a.resource in resolved
                 and resolved[a.resource].format}
        if len({(w, h) for _, w, h in sizes}) > 1:
            listed = ", ".join(f"{n} {w}x{h}" for n, w, h in sorted(sizes))
            problems.error(f"{p.where()}: attachments differ in size: {listed}")
