"""Schedule fuzzing with poisoned memory: a test mode that proves a plan's aliasing and barriers.

Two switches for the vk backend, off by default:

- **order seed**: the compiler breaks ties in its topological sort at random
  (``compile(order_seed=N)``), so passes run in another valid order, and lifetimes, memory
  placement, aliasing and barriers change with it;
- **poison**: every transient, each frame when its lifetime starts (when it takes over its
  memory), is filled with a loud pattern before its first planned access: NaN for float
  formats, magenta for normalized ones, all ones for integer formats and buffers, depth 0.5
  and stencil 0xA5. The fill waits for the memory's previous occupants as the plan's aliasing
  barrier does, and the plan's first barrier then starts from the fill.

A correct plan gives the same image under every order, with or without poison, and leaves
synchronization validation silent: every pass writes what it produces before anything reads
it. A pass that reads a transient before it is written, or a memory plan that lets two live
resources share bytes, shows up as NaN or magenta in the image.

Both are run options (:class:`rfw.options.RunOptions` ``order_seed`` and ``poison``; the
edge reads ``rfw run --order-seed N --poison``, else ``RFW_ORDER_SEED=N`` and
``RFW_POISON=1``). The vk backend hands the seed to the compiler (``fit_graph``) and the
executor asks :func:`prepare` for a :class:`Poisoner` and lets it record the fills.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import replace
from functools import reduce
from typing import Any

from rfw.graph import CompiledGraph
from rfw.graph.formats import format_info
from rfw.graph.plan import Barrier
from rfw.graph.sync import NONE, State
from rfw.options import RunOptions

from .commands import BufferBarrier, ImageBarrier, barrier, image_layout
from .consts import const, ffi, lib
from .memory import Buffer, Image

# the patterns: loud, and never what a pass that writes its output leaves behind
NAN = float("nan")
NORMALIZED = (1.0, 0.0, 1.0, 1.0)  # NaN turns into 0 in unorm/snorm: magenta instead
DEPTH, STENCIL = 0.5, 0xA5  # depth clears are 1.0 (or 0.0 reversed): neither
WORD = 0xFFFFFFFF  # buffers: NaN as float, the largest count or index as uint, -1 as int

# the fill is a transfer write; ALL_TRANSFER covers clears and fills alike
FILLED_IMAGE = State("TRANSFER_DST_OPTIMAL", frozenset({"ALL_TRANSFER"}),
                     frozenset({"TRANSFER_WRITE"}))
FILLED_BUFFER = replace(FILLED_IMAGE, layout=None)

# fills recorded in this process (tests check the poison is not vacuous)
STATS: Counter[str] = Counter()


def prepare(plan: CompiledGraph,
            options: RunOptions) -> tuple[CompiledGraph, Poisoner | None]:
    """With ``options.poison``: the plan with transfer-destination usage on its transients
    (a fill needs it) and a :class:`Poisoner` for it; otherwise the plan unchanged and None."""
    if not options.poison:
        return plan, None
    resources = tuple(replace(r, usages=r.usages | {"transfer_dst"}) if r.transient else r
                      for r in plan.resources)
    plan = replace(plan, resources=resources)
    return plan, Poisoner(plan)


class Poisoner:
    """Fills each transient with poison where its lifetime starts, every frame."""

    def __init__(self, plan: CompiledGraph):
        self.plan = plan
        # acceleration structures have no bytes of their own to poison
        transient = {r.name for r in plan.resources
                     if r.transient and r.kind in ("image", "buffer")}
        # pass -> (resource, its first planned state) for the lifetimes starting there
        self.starts: dict[str, list[tuple[str, State]]] = {}
        seen: set[str] = set()
        for name in plan.order:
            for a in plan.accesses[name]:
                if a.resource in transient and a.state is not None and a.resource not in seen:
                    seen.add(a.resource)
                    self.starts.setdefault(name, []).append((a.resource, a.state))

    def fill(self, cmd: Any, pass_name: str, barriers: list[Barrier],
             resources: Mapping[str, Any]) -> list[Barrier]:
        """Record the fills of the transients whose lifetime starts at ``pass_name`` and
        return the pass's barriers, those transients' first ones starting from the fill."""
        starts = self.starts.get(pass_name)
        if not starts:
            return barriers
        ours = {name for name, _ in starts}
        images, buffers, after = [], [], []
        for name, first in starts:
            res = resources[name]
            planned = [b for b in barriers if b.resource == name]
            # wait for the memory's previous occupants as the plan's aliasing barrier does
            src = reduce(State.merge, (b.src for b in planned), State(None, NONE, NONE))
            if isinstance(res, Image):
                images.append(ImageBarrier(res, replace(src, layout="UNDEFINED"), FILLED_IMAGE))
            else:
                buffers.append(BufferBarrier(res, src, FILLED_BUFFER))
            filled = FILLED_IMAGE if isinstance(res, Image) else FILLED_BUFFER
            after += [replace(b, src=filled, aliased=()) for b in planned] or \
                [Barrier(pass_name, name, filled, first)]
        barrier(cmd, images, buffers)
        for name, _ in starts:
            _fill(cmd, resources[name])
            STATS["fills"] += 1
        return [b for b in barriers if b.resource not in ours] + after


def _fill(cmd: Any, res: Image | Buffer) -> None:
    if isinstance(res, Buffer):
        lib.vkCmdFillBuffer(cmd, res.handle, 0, const("VK_WHOLE_SIZE"), WORD)
        return
    rng = ffi.new("VkImageSubresourceRange*")
    rng.aspectMask, rng.levelCount, rng.layerCount = res.aspect, res.mips, res.layers
    layout = image_layout(FILLED_IMAGE.layout)
    info = res.info
    if info.depth or info.stencil:
        value = ffi.new("VkClearDepthStencilValue*")
        value.depth, value.stencil = DEPTH, STENCIL
        lib.vkCmdClearDepthStencilImage(cmd, res.handle, layout, value, 1, rng)
        return
    value = ffi.new("VkClearColorValue*")
    field = {"uint": value.uint32, "sint": value.int32}.get(info.kind, value.float32)
    for k, v in enumerate(pattern(res.format)):
        field[k] = v
    lib.vkCmdClearColorImage(cmd, res.handle, layout, value, 1, rng)


def pattern(format: str) -> tuple[float | int, ...]:
    """The poison a transient of ``format`` holds before its first write (4 channels; depth
    and stencil images: (depth, stencil))."""
    info = format_info(format)
    if info.depth or info.stencil:
        return (DEPTH, STENCIL)
    if info.kind == "uint":
        return (min(WORD, (1 << (info.block_bytes * 8 // info.components)) - 1),) * 4
    if info.kind == "sint":
        return (-1,) * 4
    if info.kind in ("float", "ufloat"):
        return (NAN,) * 4
    return NORMALIZED


# ---------------------------------------------------------------------------------------------
# what a fuzzing run reports


def count_orders(plan: CompiledGraph, limit: int = 200_000) -> int | None:
    """How many valid orders the plan's passes have (its edges' linear extensions), counted
    over the sets of passes that can have run; None past ``limit`` such sets."""
    index = {n: i for i, n in enumerate(plan.order)}
    needs = [0] * len(index)
    for a, b, _ in plan.edges:
        needs[index[b]] |= 1 << index[a]
    full = (1 << len(index)) - 1
    ways: dict[int, int] = {full: 1}  # set of passes run -> orders of the rest

    def count(done: int) -> int | None:
        if done not in ways:
            if len(ways) > limit:
                return None
            total = 0
            for i in range(len(index)):
                if not done >> i & 1 and needs[i] & ~done == 0:
                    n = count(done | 1 << i)
                    if n is None:
                        return None
                    total += n
            ways[done] = total
        return ways[done]

    return count(0)


def placement(plan: CompiledGraph) -> tuple[tuple[str, int | None, int | None], ...]:
    """Where the plan puts its transients: (name, heap, offset), sorted by name."""
    return tuple(sorted((r.name, r.heap, r.offset) for r in plan.resources if r.transient))
