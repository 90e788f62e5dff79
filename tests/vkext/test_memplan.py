"""The no-GPU memory model against the vk executor's real heaps: the transient bytes
``rfw graph plan --device-profile lavapipe`` (on lavapipe) or ``nvidia`` (on an NVIDIA GPU)
predicts are the bytes allocated."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from rfw.config import apply_overrides, build, load_config, resolve_auto
from rfw.graph import MemoryOptions, compile, load_graph
from rfw.graph.compile import place
from rfw.graph.memory_model import PROFILES, predict
from rfw.graph.memory_model import requirements as modelled
from vkext.fitting import fit_graph
from vkext.memory import memory_options, plan_heaps, requirements

ROOT = Path(__file__).parents[2]
TOLERANCE = 0.02  # issue 24: prediction within 2 % of the allocation


NVIDIA = 0x10DE
# the nvidia profile's mip chains: the driver packs a chain's small tail a little
# differently (benchmarks/results/2026-12-03/memplan_h200: under 0.05 %)
MIP_TOLERANCE = 0.001


@pytest.fixture(scope="module")
def driver(vk_device):
    """(device, its profile's name): lavapipe on llvmpipe, nvidia on an NVIDIA GPU."""
    if vk_device.driver_name == "llvmpipe":
        return vk_device, "lavapipe"
    if vk_device.vendor_id == NVIDIA:
        return vk_device, "nvidia"
    pytest.skip(f"no profile models {vk_device.name} (benchmarks/device_memplan.sh "
                "measures other drivers)")


def _allocated(plan, device) -> int:
    tm = plan_heaps(plan, device, readback=True)
    try:
        return tm.allocated_bytes
    finally:
        tm.destroy()


def _config(name: str, size: tuple[int, int], device):
    cfg, _ = resolve_auto(load_config(ROOT / "configs" / f"{name}.toml"), device.caps)
    graph = build(apply_overrides(cfg, [f"size={size[0]}x{size[1]}"])).graph
    fitted, _ = fit_graph(graph, device, readback=True)  # what rfw run --backend vk does
    return compile(graph, caps=device.caps, backend="vk"), fitted


def _raptor(size: tuple[int, int], device):
    graph = replace(load_graph(ROOT / "tests" / "data" / "raptor" / "chapter11_graph.json"),
                    size=size)
    base = compile(graph, backend="vk")
    return base, place(base, memory_options(base, device, base=MemoryOptions(), readback=True))


# odd sizes: the driver pads rows and heights to 4 texels and rows to cache lines there
CASES = [("flat", (48, 48)), ("deferred_ssao_shadows", (50, 38)), ("forward", (37, 61)),
         ("raptor", (61, 45))]


@pytest.mark.parametrize("name, size", CASES, ids=[c[0] for c in CASES])
def test_prediction_is_the_allocation(driver, name, size):
    device, mine = driver
    other = "nvidia" if mine == "lavapipe" else "lavapipe"
    base, fitted = _raptor(size, device) if name == "raptor" else _config(name, size, device)
    allocated = _allocated(fitted, device)
    predicted = predict(base, PROFILES[mine]).transient_bytes
    assert allocated > 0
    assert abs(predicted - allocated) <= TOLERANCE * allocated, (predicted, allocated)
    # resource by resource, the model is the driver (so the 2 % holds at any size)
    driver_reqs = requirements(base, device, readback=True)
    model_reqs = modelled(base, PROFILES[mine])
    mips = {r.name for r in base.resources if r.kind == "image" and r.mips > 1}
    if mine == "lavapipe":
        assert model_reqs == driver_reqs
    else:
        assert model_reqs.keys() == driver_reqs.keys()
        for r, (size_b, align) in driver_reqs.items():
            if r in mips:
                assert abs(model_reqs[r][0] - size_b) <= MIP_TOLERANCE * size_b, r
            else:
                assert model_reqs[r] == (size_b, align), r
    # negative controls: the other driver's layout is not this driver's resource by
    # resource; on lavapipe, 64 KiB pages or the compiler's own estimate (64 KiB-aligned
    # texel bytes) miss by far more than 2 % at these sizes
    assert modelled(base, PROFILES[other]) != driver_reqs
    if mine == "lavapipe":
        paged = replace(PROFILES["nvidia"], page=64 * 1024)
        for wrong in (predict(base, paged).transient_bytes, base.transient_bytes):
            assert abs(wrong - allocated) > TOLERANCE * allocated, (wrong, allocated)
