"""Compiling a graph for a Vulkan device: placement that fits the driver, and the passes'
shader files checked before any GPU object is made."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rfw.graph import CompiledGraph
from rfw.graph.compile import MemoryOptions, compile, place
from rfw.graph.graph import Graph
from rfw.passes import Pass
from rfw.shaders import ShaderError, program_files

from .device import VkDevice
from .memory import memory_options, requirements

# ---------------------------------------------------------------------------------------------
# compiling for a device


def fit_plan(graph: Graph, device: VkDevice, *, alias: bool = True, readback: bool = True,
             order_seed: int | None = None) -> tuple[CompiledGraph, dict[str, Any]]:
    """Compile ``graph`` for the vk backend with placement rules that fit ``device`` (and,
    with ``order_seed``, passes in another valid order: :mod:`vkext.poison`).

    The compiler's default placement (texel bytes, 64 KiB image / 256 B buffer alignment) is
    checked against the driver's real requirements (``vkext.memory.memory_options``: its
    alignments and exact padded sizes); where they differ the graph is compiled again with
    the device's, so the plan's bytes are the bytes the driver binds. The returned dict says
    what happened: ``recompiled``, ``default_fits`` (whether ``plan_heaps`` would have
    accepted the default plan at all), the alignments and a ``reason``.
    """
    for p in graph.passes:
        if p.enabled and p.backend not in (None, "vk"):
            raise ShaderError(f"pass '{p.name}' is pinned to backend '{p.backend}': the vk "
                              "backend runs every pass on Vulkan (frames that mix backends "
                              "run through rfw.render.render)",
                              file=graph.source)
    return fit_graph(graph, device, alias=alias, readback=readback, order_seed=order_seed)


def fit_graph(graph: Graph, device: VkDevice, *, alias: bool = True, readback: bool = True,
              order_seed: int | None = None) -> tuple[CompiledGraph, dict[str, Any]]:
    """``fit_plan`` without the check for pins (a backend's part of a mixed frame, with its
    halves of bridges, compiles through here). The graph is compiled once; the device's
    placement is :func:`rfw.graph.compile.place` on that plan."""
    base = MemoryOptions(alias=alias)
    order_seed = _order_seed(graph, order_seed)
    # the device's capabilities: a pass needing a feature it lacks is refused here, by name
    plan = compile(graph, caps=device.caps, backend="vk", memory=base,
                   order_seed=order_seed)
    opts = memory_options(plan, device, base=base, readback=readback)
    info: dict[str, Any] = {"recompiled": False, "image_alignment": base.image_alignment,
                            "buffer_alignment": base.buffer_alignment, "default_fits": True}
    fitted = place(plan, opts)
    placement = [(r.name, r.bytes, r.offset) for r in plan.resources if r.transient]
    if placement != [(r.name, r.bytes, r.offset) for r in fitted.resources if r.transient]:
        fits = plan_fits(plan, device, readback=readback)
        padded = [r.name for r in plan.resources
                  if r.transient and dict(opts.sizes).get(r.name, 0) > r.raw_bytes]
        info = {"recompiled": True, "image_alignment": opts.image_alignment,
                "buffer_alignment": opts.buffer_alignment, "default_fits": fits,
                "reason": (f"the default placement ({base.image_alignment} B image, "
                           f"{base.buffer_alignment} B buffer alignment, texel bytes) "
                           + ("fits but over-reserves on" if fits else "does not fit")
                           + f" {device.name}: re-compiled with its {opts.image_alignment} B / "
                           f"{opts.buffer_alignment} B alignment and exact sizes"
                           + (f" ({len(padded)} padded by the driver)" if padded else ""))}
        plan = fitted
    return plan, info


def _order_seed(graph: Graph, seed: int | None) -> int | None:
    """The schedule-fuzzing order ``seed`` (``vkext.poison``) for a frame all on Vulkan; a
    mixed frame's part (pins elsewhere, or bridges, as rfw.mixed cuts it) keeps its order:
    its driver records it in the full plan's."""
    if any(p.enabled and (p.backend not in (None, "vk") or p.bridge is not None)
           for p in graph.passes):
        return None
    return seed


def plan_fits(plan: CompiledGraph, device: VkDevice, *, readback: bool = True) -> bool:
    """Whether every transient's driver size and alignment fit its planned bytes and offset."""
    reqs = requirements(plan, device, readback=readback)
    for r in plan.resources:
        if r.name in reqs:
            size, alignment = reqs[r.name]
            if size > r.bytes or (r.offset or 0) % alignment:
                return False
    return True


# ---------------------------------------------------------------------------------------------
# the passes' shader files


def shader_paths(pass_: Pass, shader: str | None = None) -> list[Path]:
    """The files of ``shader`` (default: the pass's) by the rule both backends follow
    (``rfw.shaders.program_files``), or a ShaderError naming the pass and the file: a
    missing one, or WGSL, which only the wgpu backend runs."""
    name = shader or pass_.shader
    who = f"pass '{pass_.name}' ({type(pass_).id or type(pass_).__name__})"
    if not name:
        raise ShaderError(f"{who} records work but declares no shader")
    paths = program_files(pass_.folder(), name, owner=pass_.name)
    if paths[0].suffix == ".wgsl":
        raise ShaderError(f"{who}: {paths[0]} is WGSL, which only --backend wgpu runs (a "
                          "pass for both backends is written in GLSL)")
    return paths


def check_passes(plan: CompiledGraph, passes: dict[str, Pass]) -> None:
    """Every scheduled pass has an instance and GLSL shader files: a ShaderError naming the
    pass and the missing (or WGSL) file, before any GPU object is made."""
    for name in plan.order:
        p = passes.get(name)
        if p is None:
            if name in plan.bridges and len(plan.accesses[name]) > 1:
                raise ShaderError(f"pass '{name}' copies between backends: the plan mixes "
                                  "them, and runs through rfw.render.render (each backend gets its "
                                  "part of it)")
            if name in plan.bridges:
                continue  # its barriers are recorded; rfw.frame copies through the host
            raise ShaderError(f"pass '{name}' has no pass instance")
        if p.shader:
            shader_paths(p)
