"""Property tests of ``rfw.graph.compile`` on random graphs (hypothesis).

Two sources of graphs: a hypothesis strategy that draws a plain description (``Desc``) and
builds it with ``GraphBuilder``, and ``synthetic_graph(n, seed=...)``. Every expectation is
derived from what the schedule, memory plan and barriers are meant to guarantee, from the
accesses and edges the compiler reports, not from how it computes them.
"""

from __future__ import annotations

import importlib
import itertools
import json
import os
import subprocess
import sys
from collections import defaultdict
from dataclasses import dataclass, replace

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from rfw.graph import (
    Attachment,
    Buffer,
    DepthAttachment,
    Graph,
    GraphBuilder,
    History,
    MemoryOptions,
    Reference,
    SizeRule,
    Storage,
    Texture,
    compile,
)
from rfw.graph.compile import STATS, CompiledGraph
from rfw.graph.synthetic import synthetic_graph

IMAGE_ALIGN = 64 * 1024
BUFFER_ALIGN = 256
COLOR_FORMATS = ("rgba8unorm", "rgba16float", "r32float", "rg11b10ufloat", "r8unorm")
DEPTH_FORMATS = ("depth32float", "depth24plus-stencil8", "depth16unorm")
SIZES = ((64, 64), (37, 19), (256, 128), (1920, 1080))

# the package exports the function ``compile`` under the submodule's name
compile_mod = importlib.import_module("rfw.graph.compile")

FAST = settings(max_examples=100, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def clear_caches() -> None:
    compile_mod._CACHE.clear()
    compile_mod._MEMORY_CACHE.clear()


# ---------------------------------------------------------------------------------------------
# graph descriptions


@dataclass(frozen=True)
class Out:
    """An output slot: a new resource, or (kind "ref") an in-place write of ``target``."""

    slot: str
    kind: str  # attachment | depth | texture | buffer | ref
    format: str | None = None
    size: tuple = ("output", 1.0)  # ("output", s) | ("fixed", w, h) | ("like", name, s)
    bytes: int = 0
    target: str | None = None


@dataclass(frozen=True)
class In:
    slot: str
    resource: str
    kind: str  # texture | storage | buffer | attachment | depth | depth_ro | reference | history


@dataclass(frozen=True)
class PassDesc:
    name: str
    type: str
    enabled: bool = True
    side_effect: bool = False
    inputs: tuple[In, ...] = ()
    outputs: tuple[Out, ...] = ()


@dataclass(frozen=True)
class Desc:
    size: tuple[int, int]
    passes: tuple[PassDesc, ...]  # declaration order
    externals: tuple[tuple[str, Out], ...] = ()
    outputs: tuple[str, ...] | None = None


@dataclass(frozen=True)
class Synthetic:
    n: int
    seed: int
    modify: float = 0.1
    buffers: float = 0.1


def _size_rule(size: tuple) -> SizeRule:
    if size[0] == "output":
        return SizeRule.output(size[1])
    if size[0] == "fixed":
        return SizeRule.fixed(size[1], size[2])
    return SizeRule.like(size[1], size[2])


def _out_spec(o: Out):
    if o.kind == "buffer":
        return Buffer(o.bytes)
    if o.kind == "depth":
        return DepthAttachment(o.format, size=_size_rule(o.size))
    if o.kind == "attachment":
        return Attachment(o.format, size=_size_rule(o.size))
    return Texture(o.format, size=_size_rule(o.size))


_IN_SPECS = {
    "texture": Texture,
    "storage": Storage,
    "buffer": lambda: Buffer(usage=("storage",)),
    "attachment": Attachment,
    "depth": lambda: DepthAttachment(None),
    "depth_ro": lambda: DepthAttachment(None, read_only=True),
    "reference": Reference,
    "history": History,
}


def build(case: Desc | Synthetic) -> Graph:
    """A fresh Graph object for the description (equal, never identical, across calls)."""
    if isinstance(case, Synthetic):
        return synthetic_graph(case.n, seed=case.seed, modify=case.modify, buffers=case.buffers)
    g = GraphBuilder("random", size=case.size)
    for name, o in case.externals:
        g.external(name, _out_spec(o))
    for p in case.passes:
        b = g.add_pass(p.name, p.type, enabled=p.enabled, side_effect=p.side_effect)
        for i in p.inputs:
            b.input(i.slot, i.resource, _IN_SPECS[i.kind]())
        for o in p.outputs:
            if o.kind == "ref":
                b.output(o.slot, Reference(), target=o.target)
            else:
                b.output(o.slot, _out_spec(o))
    if case.outputs is not None:
        g.output(*case.outputs)
    return g.build()


@dataclass
class _Res:
    kind: str  # image | buffer
    depth: bool
    wh: tuple[int, int]
    enabled: bool  # produced by an enabled pass (or imported)


@st.composite
def descs(draw) -> Desc:
    """A valid random graph: passes are drawn in a dependency order ("rank") and declared in a
    random permutation of it, so a pass often reads resources declared after it."""
    W, H = draw(st.sampled_from(SIZES))
    n = draw(st.integers(1, 10))
    position = draw(st.permutations(range(n)))  # declaration position of the pass of rank r
    res: dict[str, _Res] = {}

    def image_size() -> tuple[tuple, tuple[int, int]]:
        mode = draw(st.sampled_from(("output", "output", "fixed", "like")))
        likes = [r for r, info in res.items() if info.kind == "image" and info.enabled]
        if mode == "like" and likes:
            of = draw(st.sampled_from(likes))
            s = draw(st.sampled_from((1.0, 0.5, 2.0)))
            w0, h0 = res[of].wh
            if int(w0 * s) < 1 or int(h0 * s) < 1:
                s = 1.0
            return ("like", of, s), (int(w0 * s), int(h0 * s))
        if mode == "fixed":
            w, h = draw(st.integers(1, 300)), draw(st.integers(1, 300))
            return ("fixed", w, h), (w, h)
        s = draw(st.sampled_from((1.0, 0.5, 0.25)))
        if int(W * s) < 1 or int(H * s) < 1:
            s = 1.0
        return ("output", s), (int(W * s), int(H * s))

    externals = []
    for k in range(draw(st.integers(0, 2))):
        name = f"ext{k}"
        if draw(st.booleans()):
            size, wh = image_size()
            externals.append((name, Out("ext", "texture", draw(st.sampled_from(COLOR_FORMATS)),
                                        size)))
            res[name] = _Res("image", False, wh, True)
        else:
            externals.append((name, Out("ext", "buffer", bytes=draw(st.integers(1, 200_000)))))
            res[name] = _Res("buffer", False, (0, 0), True)

    by_rank: list[PassDesc] = []
    for r in range(n):
        name = f"n{r}"
        ptype = draw(st.sampled_from(("graphics", "compute")))
        graphics = ptype == "graphics"
        enabled = draw(st.sampled_from((True, True, True, True, False)))
        side_effect = draw(st.sampled_from((False,) * 7 + (True,)))
        cands = [k for k, info in res.items() if info.enabled]
        chosen = draw(st.lists(st.sampled_from(cands), max_size=3, unique=True)) if cands else []
        inputs: list[In] = []
        outputs: list[Out] = []
        has_depth = False
        for k, rn in enumerate(chosen):
            info = res[rn]
            full = info.wh == (W, H)
            if info.kind == "buffer":
                options = ["buffer", "buffer", "reference", "ref"]
            elif info.depth:
                options = ["texture", "reference"]
                if graphics and full and not has_depth:
                    options += ["depth_ro", "depth"]
            else:
                options = ["texture", "texture", "reference"]
                options += (["attachment", "ref"] if full else []) if graphics \
                    else ["storage", "ref"]
            kind = draw(st.sampled_from(options))
            has_depth |= kind in ("depth", "depth_ro")
            if kind == "ref":
                outputs.append(Out(f"w{k}", "ref", target=rn))
            else:
                inputs.append(In(f"i{k}", rn, kind))
        made: list[tuple[str, _Res]] = []
        for k in range(draw(st.integers(0, 3))):
            kinds = ["attachment", "texture", "buffer"] + (["depth"] if graphics and not has_depth
                                                            else [])
            kind = draw(st.sampled_from(kinds))
            rname = f"{name}.o{k}"
            if kind == "buffer":
                outputs.append(Out(f"o{k}", "buffer", bytes=draw(st.integers(1, 200_000))))
                made.append((rname, _Res("buffer", False, (0, 0), enabled)))
            elif kind == "depth":
                has_depth = True
                fmt = draw(st.sampled_from(DEPTH_FORMATS))
                outputs.append(Out(f"o{k}", "depth", fmt, ("output", 1.0)))
                made.append((rname, _Res("image", True, (W, H), enabled)))
            else:
                fmt = draw(st.sampled_from(COLOR_FORMATS))
                if graphics and kind == "attachment":  # one framebuffer size per render pass
                    size, wh = ("output", 1.0), (W, H)
                else:
                    size, wh = image_size()
                outputs.append(Out(f"o{k}", kind, fmt, size))
                made.append((rname, _Res("image", False, wh, enabled)))
        res.update(made)
        by_rank.append(PassDesc(name, ptype, enabled, side_effect, tuple(inputs),
                                tuple(outputs)))

    # history reads may name any image, produced before or after the reader (or by itself)
    images = [k for k, info in res.items() if info.kind == "image" and info.enabled]
    for r, p in enumerate(by_rank):
        if images and draw(st.integers(0, 4)) == 0:
            hist = draw(st.sampled_from(images))
            by_rank[r] = replace(p, inputs=(*p.inputs, In("hist", hist, "history")))

    passes = [None] * n
    for r, p in enumerate(by_rank):
        passes[position[r]] = p
    live = [k for k, info in res.items() if info.enabled]
    mode = draw(st.sampled_from(("none", "some", "some", "some", "empty")))
    if mode == "none" or not live:
        outputs_: tuple[str, ...] | None = None
    elif mode == "empty":
        outputs_ = ()
    else:
        outputs_ = tuple(draw(st.lists(st.sampled_from(live), min_size=1, max_size=3,
                                       unique=True)))
    return Desc((W, H), tuple(passes), tuple(externals), outputs_)


synthetics = st.builds(Synthetic, n=st.integers(5, 300), seed=st.integers(0, 2**32 - 1),
                       modify=st.sampled_from((0.1, 0.5)), buffers=st.sampled_from((0.1, 0.4)))
cases = st.one_of(descs(), descs(), descs(), synthetics)


# hand-made descriptions of bugs found by these tests (kept as explicit examples)

# a compute pass writes a buffer in place; a later compute pass reads it as a storage buffer
BUFFER_MODIFY_THEN_READ = Desc((64, 64), (
    PassDesc("make", "compute", outputs=(Out("buf", "buffer", bytes=4096),)),
    PassDesc("bump", "compute", outputs=(Out("w", "ref", target="make.buf"),)),
    PassDesc("use", "compute", inputs=(In("buf", "make.buf", "buffer"),),
             outputs=(Out("out", "buffer", bytes=256),)),
), outputs=("use.out",))

# "O" orders after the writers of P.r (reference input); the writer "C" between A and O is
# culled and "Y" (culled too) only delays O in the unculled order
REFERENCE_AFTER_CULLED_WRITER = Desc((64, 64), (
    PassDesc("P", "compute", outputs=(Out("r", "texture", "rgba8unorm"),)),
    PassDesc("O", "compute", side_effect=True,
             inputs=(In("dep", "P.r", "reference"), In("y", "Y.y", "reference"))),
    PassDesc("A", "compute", outputs=(Out("r", "ref", target="P.r"),
                                      Out("o", "texture", "rgba8unorm"))),
    PassDesc("C", "compute", outputs=(Out("r", "ref", target="P.r"),
                                      Out("x", "texture", "rgba8unorm"))),
    PassDesc("Y", "compute", outputs=(Out("y", "texture", "rgba8unorm"),)),
), outputs=("A.o",))

# "C" is culled (its output is unused) but reads the history of P.r: P.r is kept out of the
# transient heap until C is disabled
HISTORY_READ_BY_CULLED_PASS = Desc((64, 64), (
    PassDesc("P", "compute", outputs=(Out("r", "texture", "rgba8unorm"),)),
    PassDesc("K", "compute", inputs=(In("r", "P.r", "texture"),),
             outputs=(Out("o", "texture", "rgba8unorm"),)),
    PassDesc("C", "compute", inputs=(In("prev", "P.r", "history"),),
             outputs=(Out("x", "texture", "rgba8unorm"),)),
), outputs=("K.o",))

# "H" reads the previous frame's P.r but P (whose output is no graph output) is culled, so
# P.r is never touched in the frame
HISTORY_OF_CULLED_PRODUCER = Desc((64, 64), (
    PassDesc("P", "compute", outputs=(Out("r", "texture", "rgba8unorm"),)),
    PassDesc("H", "compute", inputs=(In("prev", "P.r", "history"),),
             outputs=(Out("o", "texture", "rgba8unorm"),)),
), outputs=("H.o",))


# ---------------------------------------------------------------------------------------------
# helpers over a compiled graph


def positions(c: CompiledGraph) -> dict[str, int]:
    return {name: k for k, name in enumerate(c.order)}


def per_resource(c: CompiledGraph, with_order: bool = False):
    """resource -> [(position, access)] in schedule order (ordering-only accesses left out
    unless asked for)."""
    out = defaultdict(list)
    for k, name in enumerate(c.order):
        for a in c.accesses[name]:
            if with_order or a.state is not None:
                out[a.resource].append((k, a))
    return out


def reaches(edges, kinds=("data", "order")) -> dict[str, set[str]]:
    """Transitive successors over the given edges (a breadth-first search per node, so
    history edges, which may close cycles, are handled)."""
    succ = defaultdict(set)
    for a, b, kind in edges:
        if kind in kinds:
            succ[a].add(b)
    out: dict[str, set[str]] = defaultdict(set)
    for start in list(succ):
        seen: set[str] = set()
        todo = list(succ[start])
        while todo:
            x = todo.pop()
            if x not in seen:
                seen.add(x)
                todo.extend(succ[x])
        out[start] = seen
    return out


def compiled(case) -> tuple[Graph, CompiledGraph]:
    graph = build(case)
    return graph, compile(graph)


def spans(c: CompiledGraph) -> dict[str, tuple[int, int]]:
    """First and last schedule position touching each resource's memory, outputs to the end."""
    out: dict[str, tuple[int, int]] = {}
    for name, seq in per_resource(c).items():
        out[name] = (seq[0][0], seq[-1][0])
    for name in c.outputs:
        if name in out:
            out[name] = (out[name][0], len(c.order) - 1)
    return out


# ---------------------------------------------------------------------------------------------
# 1. order


@FAST
@given(cases)
def test_order_respects_edges_and_producers(case):
    graph, c = compiled(case)
    pos = positions(c)
    assert sorted(c.order) == sorted(set(c.order))
    enabled = [p.name for p in graph.passes if p.enabled]
    assert sorted([*c.order, *c.culled]) == sorted(enabled)
    for a, b, kind in c.edges:
        assert kind in ("data", "order")
        assert pos[a] < pos[b], f"edge {a} -> {b} ({kind}) runs backwards"
    producers = {r.name: r.producer for r in c.resources}
    for name, seq in per_resource(c, with_order=True).items():
        producer = producers.get(name)
        if producer is None or producer not in pos:
            continue
        for k, a in seq:
            if a.pass_name != producer:
                assert pos[producer] < k, f"{a.pass_name} touches {name} before its producer"
        # the producer's own access is the produce
        assert any(a.pass_name == producer and a.role == "produce" for _, a in seq)


@FAST
@given(cases)
@example(REFERENCE_AFTER_CULLED_WRITER)
def test_culling_keeps_the_order_of_each_resource(case):
    """In the unculled graph, the accesses of one resource that follow a write are ordered
    after it through that resource's own access chain; dropping culled passes must not
    reorder a kept writer and a kept pass that comes after it on that chain."""
    graph, c = compiled(case)
    full = compile(graph, cull_passes=False)
    pos = positions(c)
    for name, seq in per_resource(full, with_order=True).items():
        chain_passes = {a.pass_name for _, a in seq if a.role != "history"}
        chain = [(a, b, k) for a, b, k in full.edges if a in chain_passes and b in chain_passes]
        after = reaches(chain)
        for _, w in seq:
            if not w.writes or w.pass_name not in pos:
                continue
            for _, x in seq:
                if x.pass_name in after[w.pass_name] and x.pass_name in pos \
                        and x.role != "history":
                    assert pos[w.pass_name] < pos[x.pass_name], (
                        f"'{x.pass_name}' ({x.role} of {name}) follows writer '{w.pass_name}' "
                        f"in the unculled graph but runs before it: order {c.order}, "
                        f"culled {c.culled}")


# ---------------------------------------------------------------------------------------------
# 2. memory placement


def _check_placement(c: CompiledGraph) -> None:
    pos = positions(c)
    expected_spans = spans(c)
    transients = [r for r in c.resources if r.transient]
    for r in c.resources:
        if r.name in expected_spans:
            f, last = expected_spans[r.name]
            assert (r.first, r.last) == (c.order[f], c.order[last]), r.name
    for r in transients:
        align = IMAGE_ALIGN if r.kind == "image" else BUFFER_ALIGN
        assert r.heap is not None and r.offset is not None
        assert r.offset % align == 0, (r.name, r.offset)
        assert r.bytes % align == 0 and r.raw_bytes <= r.bytes < r.raw_bytes + align
        assert r.offset + r.bytes <= c.heaps[r.heap]
        assert r.first is not None and r.last is not None
    kinds = defaultdict(set)
    for r in transients:
        kinds[r.heap].add(r.kind)
    assert all(len(k) == 1 for k in kinds.values()), "a heap mixes images and buffers"
    for i, a in enumerate(transients):
        for b in transients[i + 1:]:
            if a.heap != b.heap:
                continue
            live = pos[a.first] <= pos[b.last] and pos[b.first] <= pos[a.last]
            disjoint = a.offset + a.bytes <= b.offset or b.offset + b.bytes <= a.offset
            assert not live or disjoint, (
                f"{a.name} [{a.offset}, {a.offset + a.bytes}) live {a.first}..{a.last} and "
                f"{b.name} [{b.offset}, {b.offset + b.bytes}) live {b.first}..{b.last}")
    assert c.transient_bytes == sum(c.heaps)


@FAST
@given(cases, st.booleans())
def test_transients_alive_together_never_share_bytes(case, alias):
    graph = build(case)
    _check_placement(compile(graph, memory=MemoryOptions(alias=alias)))


# ---------------------------------------------------------------------------------------------
# 3. memory totals


@FAST
@given(cases)
def test_memory_totals_are_bounded(case):
    graph, c = compiled(case)
    transients = [r for r in c.resources if r.transient]
    assert c.unaliased_bytes == sum(r.bytes for r in transients)
    live = [0] * (len(c.order) + 1)
    pos = positions(c)
    for r in transients:
        for k in range(pos[r.first], pos[r.last] + 1):
            live[k] += r.bytes
    assert c.lower_bound_bytes == max(live)
    assert c.lower_bound_bytes <= c.transient_bytes <= c.unaliased_bytes
    assert c.lower_bound_bytes <= c.unaliased_bytes
    plain = compile(graph, memory=MemoryOptions(alias=False))
    assert plain.transient_bytes == plain.unaliased_bytes == c.unaliased_bytes
    assert plain.order == c.order


# ---------------------------------------------------------------------------------------------
# 4. determinism


def _dump(c: CompiledGraph) -> str:
    return json.dumps(c.to_json(), sort_keys=True)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(cases)
def test_compile_is_deterministic(case):
    graph = build(case)
    clear_caches()
    first = compile(graph)
    clear_caches()
    second = compile(graph)
    assert first is not second
    assert first.to_json() == second.to_json()
    assert first.edges == second.edges
    twin = build(case)  # equal, not identical
    assert twin == graph and twin is not graph
    clear_caches()
    third = compile(twin)
    assert third.to_json() == first.to_json()
    assert _dump(third) == _dump(first)
    assert third.edges == first.edges
    assert third.accesses == first.accesses


_HASH_SEED_SCRIPT = """
import json, sys
from rfw.graph import compile
from rfw.graph.synthetic import synthetic_graph
out = []
for n, seed, modify, buffers in json.loads(sys.argv[1]):
    g = synthetic_graph(n, seed=seed, modify=modify, buffers=buffers)
    out.append(compile(g).to_json())
    out.append(compile(g.with_outputs(None)).to_json())
print(json.dumps(out, sort_keys=True))
"""


def test_compile_is_independent_of_the_hash_seed():
    params = [[n, seed, modify, buffers] for n, seed in ((12, 1), (60, 2), (150, 3))
              for modify, buffers in ((0.1, 0.1), (0.5, 0.4))]
    dumps = []
    for hash_seed in ("1", "2", "12345"):
        env = {**os.environ, "PYTHONHASHSEED": hash_seed}
        done = subprocess.run([sys.executable, "-c", _HASH_SEED_SCRIPT, json.dumps(params)],
                              capture_output=True, text=True, env=env, check=True)
        dumps.append(done.stdout)
    assert dumps[0] == dumps[1] == dumps[2]


# ---------------------------------------------------------------------------------------------
# 5. parallel levels


@FAST
@given(cases)
def test_parallel_levels_are_longest_path_depths(case):
    _, c = compiled(case)
    flat = [name for level in c.parallel_levels for name in level]
    assert sorted(flat) == sorted(c.order) and len(flat) == len(set(flat))
    assert all(level for level in c.parallel_levels)
    level = {name: k for k, names in enumerate(c.parallel_levels) for name in names}
    preds = defaultdict(set)
    for a, b, _ in c.edges:
        assert level[a] != level[b], f"edge {a} -> {b} inside level {level[a]}"
        preds[b].add(a)
    for name in c.order:
        assert level[name] == 1 + max((level[p] for p in preds[name]), default=-1), name


# ---------------------------------------------------------------------------------------------
# 6. culling


@FAST
@given(cases)
def test_culling_keeps_exactly_what_reaches_an_output(case):
    graph, c = compiled(case)
    full = compile(graph, cull_passes=False)
    assert full.culled == () and set(full.order) == set(c.order) | set(c.culled)
    outputs = set(full.outputs)
    assert set(c.outputs) == outputs
    roots = set()
    for name in full.order:
        writes = [a for a in full.accesses[name] if a.writes]
        if graph.pass_(name).side_effect or not writes \
                or any(a.resource in outputs for a in writes):
            roots.add(name)
    # a pass that reads last frame's value of a resource needs that resource's writers to run
    writers = defaultdict(set)
    for name in full.order:
        for a in full.accesses[name]:
            if a.writes:
                writers[a.resource].add(name)
    history = [(w, name, "history") for name in full.order for a in full.accesses[name]
               if a.role == "history" for w in writers[a.resource.removesuffix("@prev")]]
    data = reaches([*full.edges, *history], kinds=("data", "history"))
    feeds = {name for name in full.order if name in roots or data[name] & roots}
    for name in c.culled:
        assert name not in feeds, f"culled pass '{name}' feeds an output"
    for name in c.order:
        assert name in feeds, f"kept pass '{name}' feeds no output"


# ---------------------------------------------------------------------------------------------
# 7. barriers


def _writes(access: frozenset[str]) -> frozenset[str]:
    return frozenset(x for x in access if x.endswith("WRITE"))


def _alias_predecessors(c: CompiledGraph, r) -> set[str]:
    """For each byte of ``r``, the transient of its heap that used it last before ``r``."""
    pos = positions(c)
    key = (pos[r.first], r.name)
    earlier = [q for q in c.resources if q.transient and q.heap == r.heap and q.name != r.name
               and (pos[q.first], q.name) < key
               and q.offset < r.offset + r.bytes and r.offset < q.offset + q.bytes]
    cuts = sorted({r.offset, r.offset + r.bytes}
                  | {x for q in earlier for x in (q.offset, q.offset + q.bytes)
                     if r.offset < x < r.offset + r.bytes})
    found = set()
    for lo, hi in itertools.pairwise(cuts):
        covering = [q for q in earlier if q.offset <= lo and hi <= q.offset + q.bytes]
        if covering:
            found.add(max(covering, key=lambda q: (pos[q.first], q.name)).name)
    return found


def _initial_layout(name: str, plan, plans, seqs) -> str | None:
    """The layout an image starts the frame in: UNDEFINED for a transient; for a persistent
    one, how the frame leaves it (a history pair: its twin, which it was last frame)."""
    if plan.kind != "image":
        return None
    if plan.transient:
        return "UNDEFINED"
    if name.endswith("@prev"):
        twin = name.removesuffix("@prev")
    else:
        twin = f"{name}@prev" if f"{name}@prev" in plans else name
    return seqs[twin][-1][1].state.layout if twin in seqs else "UNDEFINED"


@FAST
@given(cases)
@example(BUFFER_MODIFY_THEN_READ)
@example(HISTORY_OF_CULLED_PRODUCER)
def test_barriers_cover_every_hazard(case):
    _, c = compiled(case)
    bar = {}
    for b in c.barriers:
        assert (b.pass_name, b.resource) not in bar, "two barriers for one access"
        bar[b.pass_name, b.resource] = b
    plans = {r.name: r for r in c.resources}
    seqs = per_resource(c)
    for b in c.barriers:
        access = next(a for a in c.accesses[b.pass_name] if a.resource == b.resource)
        assert b.dst == access.state
        if plans[b.resource].kind == "image":
            assert b.src.layout is not None and b.dst.layout is not None, (
                f"image barrier without a layout: {b.to_json()}")
    for name, seq in seqs.items():
        plan = plans[name]
        preds = _alias_predecessors(c, plan) if plan.transient else set()
        layout = _initial_layout(name, plan, plans, seqs)
        last_write = None  # index into seq
        for idx, (_, a) in enumerate(seq):
            b = bar.get((a.pass_name, name))
            where = f"{a.pass_name} {a.role}s {name} (order {c.order})"
            if a.writes and b is None:
                assert idx == 0 and plan.transient and plan.kind == "buffer" and not preds, \
                    f"{where}: a write without a barrier"
            if b is not None:
                assert set(b.aliased) == (preds if idx == 0 else set()), (where, preds)
            if idx == 0 and preds:
                assert b is not None, f"{where}: takes over the memory of {preds}, no barrier"
                for q in preds:
                    last = seqs[q][-1][1]
                    assert last.state.stages <= b.src.stages, (where, q)
            if idx > 0 and a.writes:  # WAW and WAR: wait for everything since the last write
                since = seq[last_write:idx] if last_write is not None else seq[:idx]
                need = frozenset().union(*(x.state.stages for _, x in since))
                assert need <= b.src.stages, f"{where}: waits for {b.src.stages}, not {need}"
                if last_write is not None:
                    assert _writes(seq[last_write][1].state.access) <= b.src.access, where
            if idx > 0 and not a.writes and seq[idx - 1][1].writes:  # RAW
                w = seq[idx - 1][1]
                assert b is not None, f"{where} right after {w.pass_name} writes it: no barrier"
                assert w.state.stages <= b.src.stages, where
                assert _writes(w.state.access) <= b.src.access, where
            if plan.kind == "image" and a.state.layout != layout:
                assert b is not None and b.src.layout == layout, (
                    f"{where}: layout {layout} -> {a.state.layout} without a transition")
            layout = a.state.layout
            if a.writes:
                last_write = idx


# ---------------------------------------------------------------------------------------------
# 8. incremental recompile


def _culled_passes_safe_to_disable(case: Desc, c: CompiledGraph) -> list[str]:
    """Culled passes that no other pass names: no input, in-place write, history read or size
    rule refers to a resource they produce, so the graph stays valid without them."""
    produced = {p.name: {f"{p.name}.{o.slot}" for o in p.outputs if o.kind != "ref"}
                for p in case.passes}
    named: dict[str, set[str]] = defaultdict(set)  # resource -> passes naming it
    for p in case.passes:
        for i in p.inputs:
            named[i.resource].add(p.name)
        for o in p.outputs:
            if o.kind == "ref":
                named[o.target].add(p.name)
            elif o.size[0] == "like":
                named[o.size[1]].add(p.name)
    return [name for name in c.culled
            if all(named[r] <= {name} for r in produced[name])]


@FAST
@given(descs(), st.data())
@example(REFERENCE_AFTER_CULLED_WRITER, None)
@example(HISTORY_READ_BY_CULLED_PASS, None)
def test_disabling_a_culled_pass_changes_nothing(case, data):
    graph = build(case)
    clear_caches()
    c = compile(graph)
    assert compile(graph) is c  # an unchanged graph is a lookup
    candidates = _culled_passes_safe_to_disable(case, c)
    if not candidates:
        return
    name = candidates[0] if data is None else data.draw(st.sampled_from(candidates))
    before = STATS["assign_memory"]
    d = compile(graph.with_enabled(name, False))
    assert d.order == c.order, f"disabling culled '{name}' reorders: {c.order} -> {d.order}"
    assert d.resources == c.resources
    assert (d.heaps, d.transient_bytes, d.unaliased_bytes, d.lower_bound_bytes) == \
        (c.heaps, c.transient_bytes, c.unaliased_bytes, c.lower_bound_bytes)
    assert d.barriers == c.barriers
    assert STATS["assign_memory"] == before, "memory plan recomputed"
