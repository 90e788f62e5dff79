"""Async compute plans (rfw.graph.queues), without a GPU: which passes go to the compute
queue, the submissions and their semaphores, ownership transfers between families, memory
that may be in use on both queues never shared, the switch, and ``rfw graph plan``."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from rfw.config import build, load_config
from rfw.graph import Attachment, GraphBuilder, Texture, compile
from rfw.graph import queues as gq
from rfw.graph.queues import COMPUTE, GRAPHICS, PREVIOUS_FRAME, check_sync

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
SSAO = ROOT / "configs" / "deferred_ssao_shadows.toml"


def _graph(switch: str = "auto"):
    cfg = load_config(SSAO)
    return replace(build(cfg).graph, async_compute=switch)


def _plan(caps=("compute_queue",), switch="auto", **kw):
    return compile(_graph(switch), caps=caps, **kw)


def test_ssao_goes_beside_the_shadow_map():
    c = _plan()
    q = c.queues
    assert q.mode == "one family" and q.queues == (GRAPHICS, COMPUTE)
    assert q.async_passes() == ("ssao",)
    # ssao and what it needs first, so the shadow map is left to overlap it
    assert c.order[:3] == ("gbuffer", "ssao", "shadow")
    got = [(s.queue, s.passes, [(w.queue, w.value) for w in s.waits]) for s in q.submissions]
    assert got == [(GRAPHICS, ("gbuffer",), []),
                   (COMPUTE, ("ssao",), [(GRAPHICS, 1)]),
                   (GRAPHICS, ("shadow",), []),
                   (GRAPHICS, ("lighting", "points_lines", "tonemap", "fxaa"),
                    [(COMPUTE, 1)])]
    assert [s.value for s in q.submissions] == [1, 1, 2, 3]
    assert q.transfers == ()  # one family: no ownership to move
    check_sync(q, c.edges)


def test_switch_off_or_no_second_queue_gives_one_queue():
    for plan in (_plan(switch="off"), _plan(caps=()), _plan(caps=None)):
        q = plan.queues
        assert q.mode == "off" and q.queues == (GRAPHICS,)
        assert len(q.submissions) == 1 and q.submissions[0].passes == plan.order
        assert plan.order == ("shadow", "gbuffer", "ssao", "lighting", "points_lines",
                              "tonemap", "fxaa")
    assert "off" in _plan(switch="off").queues.why
    assert "no second queue" in _plan(caps=()).queues.why


def test_on_without_a_second_queue_splits_for_one_queue():
    q = _plan(caps=(), switch="on").queues
    assert q.mode == "one queue" and q.async_passes() == ("ssao",)
    assert len(q.submissions) == 4


def test_check_sync_rejects_a_missing_wait():
    """Negative control of the checker the tests rely on."""
    c = _plan()
    q = c.queues
    subs = list(q.submissions)
    subs[3] = replace(subs[3], waits=())  # lighting no longer waits for ssao
    with pytest.raises(AssertionError, match="lighting"):
        check_sync(replace(q, submissions=tuple(subs)), c.edges)
    subs = list(q.submissions)
    subs[1] = replace(subs[1], waits=(gq.Wait(GRAPHICS, 2, 2),))  # a later batch
    with pytest.raises(AssertionError, match="later"):
        check_sync(replace(q, submissions=tuple(subs)), c.edges)


def test_two_families_transfer_ownership_with_the_plans_layouts():
    c = _plan(caps=("compute_family",))
    q = c.queues
    assert q.mode == "two families" and q.async_passes() == ("ssao",)
    pairs = {(t.resource, t.src, t.dst, t.after, t.before) for t in q.transfers}
    assert pairs == {("gbuffer.depth", GRAPHICS, COMPUTE, "gbuffer", "ssao"),
                     ("gbuffer.normal", GRAPHICS, COMPUTE, "gbuffer", "ssao"),
                     ("gbuffer.depth", COMPUTE, GRAPHICS, "ssao", "lighting"),
                     ("gbuffer.normal", COMPUTE, GRAPHICS, "ssao", "lighting"),
                     ("ssao.ao", COMPUTE, GRAPHICS, "ssao", "lighting")}
    barriers = {(b.pass_name, b.resource): b for b in c.barriers}
    for t in q.transfers:
        state = next(a.state for a in c.accesses[t.before] if a.resource == t.resource)
        assert t.acquire.dst == state  # the acquire ends where the plan wants it
        # both halves name the same layout change; the release waits for the last use
        assert t.release.src.layout == t.acquire.src.layout
        assert t.release.dst.layout == t.acquire.dst.layout
        assert not t.release.dst.stages and not t.acquire.src.stages
        b = barriers.get((t.before, t.resource))
        if b is not None:  # the acquire takes the place of the plan's barrier
            assert b.src.layout == t.release.src.layout and b.src == t.release.src
    check_sync(q, c.edges)
    # a graphics-family second queue needs none of that
    assert _plan(caps=("compute_queue",)).queues.transfers == ()


def _overlaps(c):
    """(async resource, graphics resource) pairs sharing bytes while they may be in use on
    both queues at once."""
    q = c.queues
    beside = {p for s in q.submissions if s.queue == GRAPHICS for p in s.passes}
    async_res = {a.resource for p in q.async_passes() for a in c.accesses[p]}
    out = []
    subs = q.submissions
    for s in subs:
        if s.queue != COMPUTE:
            continue
        fork = max((w.value for w in s.waits if w.queue == GRAPHICS), default=0)
        join = min((g.value for g in subs if g.queue == GRAPHICS and any(
            w.queue == COMPUTE and w.value >= s.value for w in g.waits)), default=99)
        beside = {p for g in subs if g.queue == GRAPHICS and fork < g.value < join
                  for p in g.passes}
        g_res = {a.resource for p in beside for a in c.accesses[p]}
        for a in async_res:
            for b in g_res - async_res:
                ra, rb = c.resource(a), c.resource(b)
                if ra.transient and rb.transient and ra.heap == rb.heap and \
                        ra.offset < rb.offset + rb.bytes and rb.offset < ra.offset + ra.bytes:
                    out.append((a, b))
    return out


def _chain():
    """A two-pass compute chain beside a raster pass: its scratch image and the raster
    target have disjoint lifetimes in the serial order, same size and format."""
    g = GraphBuilder("chain", size=(64, 64))
    g.add_pass("src", "graphics").output("color", Attachment("rgba8unorm"))
    g.add_pass("blur_a", "compute").input("t", "src.color", Texture()) \
        .output("tmp", Texture("rgba8unorm"))
    g.add_pass("blur_b", "compute").input("t", "blur_a.tmp", Texture()) \
        .output("out", Texture("rgba8unorm"))
    g.add_pass("raster", "graphics").output("color", Attachment("rgba8unorm"))
    g.add_pass("mix", "compute").input("a", "raster.color", Texture()) \
        .input("b", "blur_b.out", Texture()).output("out", Texture("rgba8unorm"))
    g.output("mix.out")
    return g.build()


def test_memory_in_use_on_both_queues_is_not_shared():
    for c in (_plan(), compile(_chain(), caps=("compute_queue",))):
        assert c.queues.async_passes()
        assert _overlaps(c) == []
        check_sync(c.queues, c.edges)


def test_overlap_check_finds_shared_memory_without_the_stretch(monkeypatch):
    """Negative control: lifetimes from the serial order alone let the compute chain's
    scratch image take the raster target's bytes, though the passes run at the same time."""
    c = compile(_chain(), caps=("compute_queue",), size=(64, 65))
    assert c.queues.async_passes() == ("blur_a", "blur_b")
    assert c.order == ("src", "blur_a", "blur_b", "raster", "mix")
    monkeypatch.setattr(sys.modules["rfw.graph.compile"], "overlap_spans",
                        lambda spans, *a: spans)
    c = compile(_chain(), caps=("compute_queue",), size=(64, 66))  # not cached
    assert ("blur_a.tmp", "raster.color") in _overlaps(c)


def _toy(shared: bool):
    g = GraphBuilder("toy", size=(64, 64))
    g.add_pass("src", "graphics").output("color", Attachment("rgba8unorm"))
    a = g.add_pass("raster", "graphics").output("color", Attachment("rgba8unorm"))
    if shared:
        a.input("t", "src.color", Texture())
    g.add_pass("blur", "compute").input("t", "src.color", Texture()) \
        .output("out", Texture("rgba8unorm"))
    g.add_pass("mix", "compute").input("a", "raster.color", Texture()) \
        .input("b", "blur.out", Texture()).output("out", Texture("rgba8unorm"))
    g.output("mix.out")
    return g.build()


def test_a_pass_sharing_a_resource_with_raster_beside_it_stays():
    apart = compile(_toy(False), caps=("compute_queue",))
    assert apart.queues.async_passes() == ("blur",)
    check_sync(apart.queues, apart.edges)
    # raster reads src.color too and has no path to blur: blur stays on the graphics queue
    shared = compile(_toy(True), caps=("compute_queue",))
    assert shared.queues.async_passes() == ()
    assert shared.queues.queues == (GRAPHICS,)
    assert "no compute pass can overlap" in shared.queues.why


def test_compute_first_waits_for_the_last_frame_and_the_frame_joins():
    g = GraphBuilder("toy2", size=(64, 64))
    g.add_pass("noise", "compute").output("n", Texture("rgba8unorm"))
    g.add_pass("draw", "graphics").output("c", Attachment("rgba8unorm"))
    g.output("noise.n", "draw.c")
    c = compile(g.build(), caps=("compute_queue",))
    q = c.queues
    assert q.async_passes() == ("noise",)
    first = next(s for s in q.submissions if s.queue == COMPUTE)
    assert [w.submission for w in first.waits] == [PREVIOUS_FRAME]
    last = q.submissions[-1]
    assert last.queue == GRAPHICS and any(w.queue == COMPUTE for w in last.waits)
    check_sync(q, c.edges)


def test_the_switch_is_part_of_the_cache_key():
    assert _plan(switch="on").queues.on != _plan(switch="off").queues.on


def test_graph_plan_prints_queues_submissions_and_transfers():
    r = warm_cli("graph", "plan", str(SSAO), "--caps", "compute_family", cwd=ROOT)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "queues: graphics, compute (two families" in out
    assert "#1 compute  [ssao]  wait graphics = 1 at ALL_COMMANDS;  signal compute = 1" in out
    assert "#3 graphics [lighting, points_lines, tonemap, fxaa]  wait compute = 1" in out
    assert "ssao.ao: compute -> graphics; release after ssao" in out
    r = warm_cli("graph", "plan", str(SSAO), "--json", "--caps", "compute_queue", cwd=ROOT)
    q = json.loads(r.stdout)["queues"]
    assert [s["queue"] for s in q["submissions"]] == [GRAPHICS, COMPUTE, GRAPHICS, GRAPHICS]
    r = warm_cli("graph", "plan", str(SSAO), cwd=ROOT)
    assert "queues: graphics (off: async_compute = auto and the device has no second" in r.stdout


@pytest.mark.parametrize("line", ['async_compute = "sometimes"', "async_compute = 3"])
def test_a_bad_switch_in_a_config_is_one_line(tmp_path, line):
    cfg = tmp_path / "c.toml"
    cfg.write_text(line + "\n" + SSAO.read_text())
    r = warm_cli("graph", "plan", str(cfg), cwd=ROOT)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "async_compute: must be true, false or" in r.stderr


def test_a_bad_switch_on_the_command_line_is_one_line(tmp_path):
    r = warm_cli("run", str(SSAO), "--set", "async_compute=maybe", "--out", str(tmp_path / "o"),
                 cwd=ROOT)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        f"rfw: error: {SSAO}: --set async_compute: must be true, false or \"auto\", "
        "not 'maybe'"]


def test_switch_spellings():
    cfg = load_config(SSAO)
    from rfw.config import apply_overrides

    for word, want in (("true", "on"), ("off", "off"), ("auto", "auto"), ("1", "on")):
        assert apply_overrides(cfg, [f"async_compute={word}"]).async_compute == want
    assert build(apply_overrides(cfg, ["async_compute=no"])).graph.async_compute == "off"
