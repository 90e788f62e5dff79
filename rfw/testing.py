"""Run one pass on arrays: analytic pass tests without a scene file or a config."""

from __future__ import annotations

from typing import Any

import numpy as np

from .config import MAX_SIZE
from .errors import RfwTypeError, RfwValueError, check_number, check_type, type_name
from .graph import GraphBuilder, Texture, compile
from .graph.resources import SizeRule
from .passes import Pass


def run_pass(cls: type[Pass], inputs: dict[str, tuple[str, np.ndarray]], *,
             settings: dict[str, Any] | None = None, scene: Any = None, device: Any = None,
             frames: int = 1, size: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """Feed ``inputs`` ({slot: (format, (H, W, C) array)}) to one pass; return its outputs.

    Inputs become external images filled from the arrays; outputs are read back as arrays of
    their texel type. A scene is needed only by passes that draw one.
    """
    from .backends.wgpu import Device, Executor
    from .backends.wgpu.scene import GpuScene

    _check_args(cls, inputs, settings, frames, size)
    inst = cls(cls.id or cls.__name__, **(settings or {}))
    ins, outs = inst.declare()
    first = next(iter(inputs.values()), None)
    if size is None:
        size = (first[1].shape[1], first[1].shape[0]) if first is not None else (64, 64)
    g = GraphBuilder(f"test_{inst.name}", size=size)
    slots: dict[str, str] = {}
    for slot, (fmt, array) in inputs.items():
        name = f"in.{slot}"
        g.external(name, Texture(fmt, size=SizeRule.fixed(array.shape[1], array.shape[0])))
        slots[slot] = name
    b = g.add_pass(inst.name, cls.type, settings=inst.params.as_dict(),
                   schema=tuple(inst.params.fields()), steps=inst.steps())
    for slot, spec in ins.items():
        if slot in slots:
            b.input(slot, slots[slot], spec)
    for slot, spec in outs.items():
        if spec.size is not None and spec.size.mode == "relative" and spec.size.of in slots:
            spec = spec.with_(size=SizeRule.like(slots[spec.size.of], *spec.size.scale))
        b.output(slot, spec)
        slots[slot] = f"{inst.name}.{slot}"
    g.output(*(f"{inst.name}.{s}" for s in outs))
    plan = compile(g.build())
    device = device or Device()
    gpu_scene = None
    if scene is not None:
        gpu_scene = GpuScene(device.device, scene)
        gpu_scene.set_viewport(size)
    ex = Executor(device, plan, {inst.name: inst}, {inst.name: slots}, gpu_scene,
                  readback=tuple(plan.outputs))
    try:
        for slot, (_, array) in inputs.items():
            ex.upload(slots[slot], array)
        ex.run(frames)
        return {s: ex.read(f"{inst.name}.{s}") for s in outs}
    finally:
        ex.destroy()
        if gpu_scene is not None:
            gpu_scene.destroy()


def _check_args(cls: Any, inputs: Any, settings: Any, frames: Any, size: Any) -> None:
    where = "rfw.testing.run_pass"
    if not (isinstance(cls, type) and issubclass(cls, Pass)):
        raise RfwTypeError(f"'cls' must be a Pass subclass, not {type_name(cls)}",
                           element=where)
    check_type(inputs, "inputs", dict, "{slot: (format, array)}", element=where)
    for slot, value in inputs.items():
        if not (isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str)
                and isinstance(value[1], np.ndarray)):
            raise RfwTypeError(f"'inputs' must map each slot to (format, array), not "
                               f"{type_name(value)} for {slot!r}", element=where)
        if value[1].ndim != 3 or 0 in value[1].shape:
            raise RfwValueError(f"'inputs' {slot!r} must be an (H, W, C) array, not shape "
                                f"{value[1].shape}", element=where)
    if settings is not None:
        check_type(settings, "settings", dict, "a dict of settings", element=where)
    check_number(frames, "frames", kind=int, lo=1, hi=1000, element=where)
    if size is not None:
        if not isinstance(size, tuple | list) or len(size) != 2:
            raise RfwTypeError(f"'size' must be (width, height), not {type_name(size)}",
                               element=where)
        for v in size:
            check_number(v, "size", kind=int, lo=1, hi=MAX_SIZE, element=where)
