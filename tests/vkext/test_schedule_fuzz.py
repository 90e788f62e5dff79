"""Schedule fuzzing with poisoned memory (issue 12, item 5): the proof that the plan is right.

Every config in configs/ runs on vk in several valid pass orders (``compile(order_seed=N)``:
random ties in the topological sort), each frame with every transient poisoned when its
lifetime starts (``vkext.poison``: NaN, magenta, all ones), under synchronization validation.
Orders move lifetimes, so memory placement, aliasing and barriers move with them; every order
must give the default order's unpoisoned image bit for bit (lavapipe is deterministic here:
the same plan twice, or poisoned, gives identical bytes) and no validation message. A config
that mixes backends keeps its one order (its driver records the vk part in the full plan's
order) and is poisoned. ``wide`` (below) adds parallel levels the configs lack: most of them
are chains, with 1 to 4 orders.

The negative controls break a plan three ways and show each is caught: two live transients
sharing bytes (image and sync validation), a pass reading a transient before it is written
(the image only when poisoned: unpoisoned, lavapipe hands it last frame's bytes; sync
validation), and a barrier that waits for nothing (sync validation).

``RFW_FUZZ_ORDERS=N`` tries up to N distinct orders per config (default 4, plus the default
order) and adds variants with more passes; ``-s`` prints, per config, its orders, those
tried, and the memory placements and barrier plans they produced. Measured on lavapipe
(Mesa 25, 2 cores): the file in about 50 s; with RFW_FUZZ_ORDERS=40, ``wide`` ran 41 of its
810 orders (34 placements, 41 barrier plans) and ``meshlet`` with shadows all 12 of its
orders, every image identical, no validation message."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rfw.config import apply_overrides, build, load_config, resolve_auto
from rfw.errors import RfwError
from rfw.frame import camera_for, load_scene_for
from rfw.graph import Attachment, CompiledGraph, GraphBuilder, Texture, compile
from rfw.graph.graph import Graph
from rfw.graph.sync import State
from rfw.graph.synthetic import synthetic_graph
from rfw.options import RunOptions
from rfw.render import render
from vkext import poison
from vkext.executor import VkExecutor
from vkext.fitting import fit_plan
from vkext.scene import VkScene

from ..cli.warm import warm_cli
from ..golden_util import read_png

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = sorted(p for p in (ROOT / "configs").glob("*.toml"))
SIZE = (64, 48)
ORDERS = int(os.environ.get("RFW_FUZZ_ORDERS", "4"))
LONG = "RFW_FUZZ_ORDERS" in os.environ
TRIES = 25  # seeds tried per distinct order wanted: the seeded sort is not uniform

# a config with wide parallel levels (two tonemaps, two fxaas, a debug view beside the
# lighting chain), so that orders change lifetimes and aliasing a lot
WIDE = """
name = "wide"
scene = "default"
size = [64, 48]
outputs = ["fxaa.color", "fxaa_dim.color", "debug.view"]

[[pass]]
name = "shadow"
use = "shadow_map"

[[pass]]
name = "gbuffer"

[[pass]]
name = "ssao"
inputs = { depth = "gbuffer.depth", normal = "gbuffer.normal" }

[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", emissive = "gbuffer.emissive", depth = "gbuffer.depth", shadow = "shadow.depth", ao = "ssao.ao" }

[[pass]]
name = "tonemap"
inputs = { hdr = "lighting.hdr" }

[[pass]]
name = "tonemap_dim"
use = "tonemap"
inputs = { hdr = "lighting.hdr" }
settings = { exposure = 0.25 }

[[pass]]
name = "fxaa"
inputs = { ldr = "tonemap.ldr" }

[[pass]]
name = "fxaa_dim"
use = "fxaa"
inputs = { ldr = "tonemap_dim.ldr" }

[[pass]]
name = "overdraw"

[[pass]]
name = "debug"
use = "debug_view"
inputs = { source = "overdraw.count" }
settings = { mode = "heatmap", range = [0.0, 8.0] }
"""


class Fuzzer:
    """One config on one device, its scene uploaded once: plans under any order seed, and
    frames of any plan (a broken one too)."""

    def __init__(self, cfg: Any, device: Any, scene: Any, *, alias: bool = True):
        self.device, self.alias = device, alias
        self.cfg, _ = resolve_auto(cfg, device.caps)
        scene = load_scene_for(self.cfg, scene if self.cfg.scene == "default" else None)
        self.built = build(self.cfg, scene)  # as rfw run builds it: for this scene
        self.scene = VkScene(device, scene, camera_for(self.cfg, scene))
        self.scene.set_viewport(self.cfg.size)

    def plan(self, seed: int | None) -> CompiledGraph:
        """The vk plan fitted to the device, in the order ``seed`` gives."""
        return fit_plan(self.built.graph, self.device, alias=self.alias, order_seed=seed)[0]

    def run(self, plan: CompiledGraph, *, poisoned: bool = True,
            frames: int = 2) -> dict[str, np.ndarray]:
        """The outputs after ``frames`` frames of ``plan``."""
        ex = None
        try:
            ex = VkExecutor(self.device, plan, self.built.passes, self.built.slots, self.scene,
                            readback=tuple(plan.outputs), alias=self.alias,
                            options=RunOptions(poison=poisoned))
            ex.run(frames)
            return {name: ex.read(name) for name in plan.outputs}
        finally:
            if ex is not None:
                ex.destroy()

    def close(self) -> None:
        self.scene.destroy()


# variants that add passes, and so orders: the long run takes them too
VARIANTS = ["deferred+shadow.enabled=true", "deferred_meshlet+shadow.enabled=true",
            "deferred_ssao_shadows+view=overdraw", "deferred_ssao_shadows+view=ao",
            "forward+shadow.enabled=true", "forward_prepass+shadow.enabled=true",
            "meshlet+shadow.enabled=true", "meshlet+culling.occlusion=false",
            "rt_primary+method=ray_query", "rt_shadows+shadows=ray_pipeline",
            "rt_shadows+shadows=shadow_map+ao=ssao"]


def _config(case: str, tmp_path: Path) -> Any:
    name, *sets = case.split("+")
    if name == "wide":
        path = tmp_path / "wide.toml"
        path.write_text(WIDE)
    else:
        path = ROOT / "configs" / f"{name}.toml"
    return replace(apply_overrides(load_config(path), sets), size=SIZE)


def _orders(fz: Fuzzer, want: int) -> tuple[int | None, list[tuple[int | None, CompiledGraph]]]:
    """How many orders the plan has, and the default one followed by up to ``want`` others,
    distinct, found by seed."""
    default = fz.plan(None)
    total = poison.count_orders(default)
    found = {default.order: (None, default)}
    for seed in range(TRIES * want):
        if len(found) > want or len(found) == total:
            break
        plan = fz.plan(seed)
        found.setdefault(plan.order, (seed, plan))
    return total, list(found.values())


def _differing(actual: dict[str, np.ndarray], expected: dict[str, np.ndarray]) -> list[str]:
    """The outputs that differ in any byte (NaN equals NaN in float outputs)."""
    return [n for n in expected
            if actual[n].shape != expected[n].shape
            or not np.array_equal(actual[n], expected[n],
                                  equal_nan=actual[n].dtype.kind == "f")]


def _mixed(cfg: Any) -> bool:
    # passes pinned to wgpu: the frame mixes backends (fit_plan's own test)
    return any(p.enabled and p.backend not in (None, "vk") for p in build(cfg).graph.passes)


CASES = [p.stem for p in CONFIGS] + ["wide"] + (VARIANTS if LONG else [])


@pytest.fixture
def sync_checked(vk_device):
    # (c): without the layer and its synchronization checks the test would prove nothing
    assert vk_device.validation and vk_device.sync_validation
    return vk_device


@pytest.mark.parametrize("case", CASES)
def test_every_order_poisoned_gives_the_default_image(sync_checked, case, tmp_path,
                                                      courtyard, device):
    cfg = _config(case, tmp_path)
    if _mixed(cfg):
        _mixed_poisoned(cfg, sync_checked, device, courtyard)
        return
    device = sync_checked
    fz = Fuzzer(cfg, device, courtyard)
    try:
        reference = fz.run(fz.plan(None), poisoned=False)
        device.check_validation()
        total, tried = _orders(fz, ORDERS)
        for seed, plan in tried:
            before = poison.STATS["fills"]
            images = fz.run(plan)
            transients = sum(r.transient and r.kind in ("image", "buffer")
                             for r in plan.resources)
            # the poison is not vacuous: every transient filled once per frame
            assert poison.STATS["fills"] - before == 2 * transients, (seed, plan.order)
            assert not _differing(images, reference), (seed, plan.order)
            device.check_validation()
        want = ORDERS + 1 if total is None else min(total, ORDERS + 1)
        assert len(tried) == want, (total, [p.order for _, p in tried])
        placements = {poison.placement(p) for _, p in tried}
        barriers = {p.barriers for _, p in tried}
        print(f"\n{case}: {total} orders, {len(tried)} tried, {len(placements)} placements, "
              f"{len(barriers)} barrier plans, {len(tried[0][1].resources)} resources")
    finally:
        fz.close()


def _mixed_poisoned(cfg: Any, device: Any, wgpu_device: Any, scene: Any) -> None:
    # a frame that mixes backends keeps its one order (its driver records the vk part in
    # the full plan's order), through the one frame driver; its vk transients are poisoned
    def run(options: RunOptions) -> Any:
        return render(cfg, backend="vk", device=device, devices=(wgpu_device,), scene=scene,
                      frames=1, options=options)

    reference = run(RunOptions())
    before = poison.STATS["fills"]
    fuzzed = run(RunOptions(order_seed=7, poison=True))
    assert poison.STATS["fills"] > before
    assert fuzzed.frame.plan.order == reference.frame.plan.order
    assert not _differing(fuzzed.images, reference.images)
    device.check_validation()
    print(f"\n{cfg.name}: mixed frame, its one order, poisoned")


# ---------------------------------------------------------------------------------------------
# negative controls: broken plans are caught


@pytest.fixture
def deferred_ssao(sync_checked, tmp_path, courtyard):
    fz = Fuzzer(_config("deferred_ssao_shadows", tmp_path), sync_checked, courtyard)
    try:
        plan = fz.plan(None)
        yield fz, plan, fz.run(plan, poisoned=False)
    finally:
        sync_checked.messages.clear()
        fz.close()


def test_live_transients_sharing_bytes_change_the_image(deferred_ssao):
    # ssao.ao moved onto gbuffer.normal, which lighting still reads after ssao ran
    fz, plan, reference = deferred_ssao
    normal, ao = plan.resource("gbuffer.normal"), plan.resource("ssao.ao")
    order = plan.order
    assert order.index(normal.first) < order.index(ao.first) <= order.index(normal.last)
    broken = replace(plan, resources=tuple(
        replace(r, heap=normal.heap, offset=normal.offset) if r.name == ao.name else r
        for r in plan.resources))
    assert _differing(fz.run(broken), reference) == ["fxaa.color"]
    # the fill writes bytes gbuffer.normal still holds: sync validation sees that too
    texts = [m.text for m in fz.device.messages]
    assert any("SYNC-HAZARD" in t and "gbuffer.normal" in t for t in texts), texts


def test_reading_a_transient_before_it_is_written_shows_poisoned(sync_checked, tmp_path,
                                                                  courtyard):
    # forward.toml backwards, every transient in memory of its own: tonemap reads forward.hdr
    # before forward writes it. Unpoisoned, lavapipe hands it the bytes the last frame left
    # there, the right image: the bug hides. Poisoned, the image shows it; sync validation
    # reports the unordered accesses either way
    device = sync_checked
    fz = Fuzzer(_config("forward", tmp_path), device, courtyard, alias=False)
    try:
        plan = fz.plan(None)
        reference = fz.run(plan, poisoned=False)
        broken = replace(plan, order=plan.order[::-1])
        assert "forward.hdr" in dict(poison.Poisoner(broken).starts["tonemap"])
        assert _differing(fz.run(broken), reference) == ["tonemap.ldr"]
        texts = [m.text for m in device.messages]
        assert any("SYNC-HAZARD" in t and "forward.hdr" in t for t in texts), texts
        device.messages.clear()
        hidden = fz.run(broken, poisoned=False)
        if device.driver_name == "llvmpipe":  # stale bytes are undefined in Vulkan terms
            assert not _differing(hidden, reference)
    finally:
        device.messages.clear()
        fz.close()


def test_a_barrier_that_waits_for_nothing_is_reported(deferred_ssao):
    # tonemap's barrier on lighting.hdr keeps its layout change but waits for no stage:
    # sync validation sees tonemap read what lighting wrote, unordered
    fz, plan, _ = deferred_ssao
    weak = [replace(b, src=State(b.src.layout, frozenset(), frozenset()))
            if (b.pass_name, b.resource) == ("tonemap", "lighting.hdr") else b
            for b in plan.barriers]
    assert weak != list(plan.barriers)
    fz.run(replace(plan, barriers=tuple(weak)))
    texts = [m.text for m in fz.device.messages]
    assert any("SYNC-HAZARD" in t and "lighting.hdr" in t for t in texts), texts


def test_cli_order_seed_and_poison(deferred_ssao, tmp_path):
    # rfw run --order-seed N --poison: another order, the same image as the default order's
    # (one warm-up and one timed frame: two frames, as the fixture's run)
    fz, plan, reference = deferred_ssao
    seed = next(s for s in range(50) if fz.plan(s).order != plan.order)
    run = ["run", ROOT / "configs/deferred_ssao_shadows.toml"]
    r = warm_cli(*run, "--backend", "vk", "--size", f"{SIZE[0]}x{SIZE[1]}", "--validate",
                 "--poison", "--order-seed", seed, "--out", tmp_path / "out", cwd=ROOT)
    assert r.returncode == 0, r.stderr
    timings = json.loads((tmp_path / "out/timings.json").read_text())
    assert [p["name"] for p in timings["passes"]] == list(fz.plan(seed).order)
    image = read_png(tmp_path / "out/fxaa.color.png")
    assert np.array_equal(image, reference["fxaa.color"])
    # the negative control: the same comparison tells another image apart
    assert not np.array_equal(image[:, ::-1], reference["fxaa.color"])
    # and only vk has them: one line, exit 2
    r = warm_cli(*run, "--backend", "wgpu", "--poison", "--out", tmp_path / "w", cwd=ROOT)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stderr
    assert "--order-seed and --poison need --backend vk" in r.stderr


# ---------------------------------------------------------------------------------------------
# the pieces


def _two_chains(n: int = 3) -> Graph:
    """Two chains of ``n`` passes joined by a last one: C(2n, n) valid orders."""
    g = GraphBuilder("two_chains", size=(16, 16))
    for chain in "ab":
        prev = None
        for i in range(n):
            p = g.add_pass(f"{chain}{i}", "graphics")
            if prev:
                p.input("src", prev, Texture())
            p.output("color", Attachment("rgba8unorm"))
            prev = f"{chain}{i}.color"
    g.add_pass("join", "graphics").input("a", f"a{n - 1}.color", Texture()) \
        .input("b", f"b{n - 1}.color", Texture()).output("color", Attachment("rgba8unorm"))
    g.output("join.color")
    return g.build()


def test_seeded_orders_are_valid_and_reach_every_order():
    # every seeded order respects every edge, the same seed gives the same order, enough
    # seeds find all 20 orders; without a seed the order is the compiler's own, unchanged
    graph = _two_chains(3)
    default = compile(graph)
    assert compile(graph, order_seed=None) == default
    assert default.order == ("a0", "a1", "a2", "b0", "b1", "b2", "join")
    assert poison.count_orders(default) == 20
    seen, placements = set(), set()
    for seed in range(400):
        plan = compile(graph, order_seed=seed)
        position = {n: k for k, n in enumerate(plan.order)}
        assert all(position[a] < position[b] for a, b, _ in plan.edges), plan.order
        assert compile(graph, order_seed=seed).order == plan.order
        seen.add(plan.order)
        placements.add(poison.placement(plan))
    assert len(seen) == 20
    assert len(placements) > 1  # orders move lifetimes, and aliasing with them


def test_seeded_orders_of_synthetic_graphs_keep_every_edge():
    # 60-pass graphs with in-place writes and buffers: each seed's order keeps every edge,
    # and lifetimes follow it (a transient lives from the first to the last pass touching it)
    for graph_seed in range(3):
        graph = synthetic_graph(60, seed=graph_seed)
        orders = set()
        for seed in range(8):
            plan = compile(graph, size=(64, 36), order_seed=seed)
            position = {n: k for k, n in enumerate(plan.order)}
            assert all(position[a] < position[b] for a, b, _ in plan.edges), (graph_seed, seed)
            for r in plan.resources:
                users = [n for n in plan.order
                         if any(x.resource == r.name for x in plan.accesses[n])]
                assert not r.transient or (r.first, r.last) == (users[0], users[-1]), r.name
            orders.add(plan.order)
        assert len(orders) == 8, graph_seed  # wide graphs: every seed another order


def test_count_orders_counts_linear_extensions(tmp_path):
    # against brute force over permutations, on a config with parallel passes and a chain
    from itertools import permutations

    for case in ("deferred_ssao_shadows", "forward"):
        plan = compile(build(_config(case, tmp_path)).graph, backend="vk")
        position = lambda order: {n: k for k, n in enumerate(order)}  # noqa: E731
        brute = sum(all(position(o)[a] < position(o)[b] for a, b, _ in plan.edges)
                    for o in permutations(plan.order))
        assert poison.count_orders(plan) == brute
    assert poison.count_orders(plan, limit=0) is None


def test_patterns_are_loud():
    assert all(np.isnan(v) for v in poison.pattern("rgba16float"))
    assert all(np.isnan(v) for v in poison.pattern("r32float"))
    assert poison.pattern("rgba8unorm") == (1.0, 0.0, 1.0, 1.0)  # NaN would store 0
    assert poison.pattern("r32uint") == (0xFFFFFFFF,) * 4
    assert poison.pattern("rgba8uint") == (255,) * 4  # in range for 8 bits
    assert poison.pattern("r32sint") == (-1,) * 4
    assert poison.pattern("depth32float") == (0.5, 0xA5)  # neither 0 nor 1: no clear value


def test_the_switches_from_the_environment(monkeypatch):
    # the edge reads them into RunOptions (rfw.options); given values win over them
    seed, poisoned = "RFW_ORDER_SEED", "RFW_POISON"
    monkeypatch.setenv(seed, "12")
    monkeypatch.setenv(poisoned, "1")
    options = RunOptions.from_env()
    assert (options.order_seed, options.poison) == (12, True)
    options = RunOptions.from_env(order_seed=3, poison=False)
    assert (options.order_seed, options.poison) == (3, False)
    for name, value in ((seed, "x"), (seed, "-1"), (poisoned, "maybe")):
        monkeypatch.setenv(name, value)
        with pytest.raises(RfwError, match=name):
            RunOptions.from_env()
        monkeypatch.setenv(seed, "12")
        monkeypatch.setenv(poisoned, "1")
    with pytest.raises(RfwError, match="order_seed"):
        RunOptions(order_seed=2**32)
