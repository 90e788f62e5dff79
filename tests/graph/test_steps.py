"""Steps inside a pass: the compiler plans the barriers between them per mip or byte range."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rfw.graph import (
    Buffer,
    DepthAttachment,
    GraphBuilder,
    GraphError,
    Part,
    Step,
    Texture,
    compile,
)
from rfw.graph.inspect import describe


def pyramid_steps(levels: int) -> list[Step]:
    """The depth pyramid's steps: level 0 from depth, level L from level L - 1."""
    steps = [Step("level 0", reads="depth", writes=Part("pyramid", mips=(0, 1)))]
    steps += [Step(f"level {lv}", reads=Part("pyramid", mips=(lv - 1, 1)),
                   writes=Part("pyramid", mips=(lv, 1))) for lv in range(1, levels)]
    return steps


def pyramid_graph(levels: int = 5, steps: list[Step] | None = None):
    g = GraphBuilder("hiz", size=(64, 64))
    g.add_pass("z").output("depth", DepthAttachment())
    p = g.add_pass("hiz", "compute",
                   steps=pyramid_steps(levels) if steps is None else steps)
    p.input("depth", "z.depth", Texture()).output("pyramid", Texture("r32float", mips=levels))
    g.add_pass("use", "compute").input("p", "hiz.pyramid").output("o", Texture("r8unorm"))
    return g.build()


def one_pass(steps, out=None, inputs=()):
    """One compute pass with the given steps over an image 'img' (4 mips) and, when a step
    names it, a buffer 'buf' (1 KiB)."""
    g = GraphBuilder("s", size=(32, 32))
    p = g.add_pass("a", "compute", side_effect=True, steps=steps)
    for slot, resource, spec in inputs:
        p.input(slot, resource, spec)
    p.output("img", Texture("rgba8unorm", mips=4))
    if any(isinstance(s, Step) and any(x.slot == "buf" for x in (*s.reads, *s.writes))
           for s in steps):
        p.output("buf", Buffer(1024))
    for slot, spec in out or ():
        p.output(slot, spec)
    return g.build()


# ---------------------------------------------------------------------------------------------
# planned barriers


def test_pyramid_gets_one_barrier_per_level_on_the_mip_below():
    c = compile(pyramid_graph(5))
    got = [(b.pass_name, b.step, b.resource, b.mips) for b in c.step_barriers]
    assert got == [("hiz", lv, "hiz.pyramid", (lv - 1, 1)) for lv in range(1, 5)]
    for b in c.step_barriers:  # compute write made visible to compute storage reads
        assert b.src.layout == b.dst.layout == "GENERAL"
        assert b.src.stages == b.dst.stages == {"COMPUTE_SHADER"}
        assert b.src.access == {"SHADER_STORAGE_WRITE"}
        assert b.dst.access == {"SHADER_STORAGE_READ"}
    assert c.steps == {"hiz": tuple(f"level {lv}" for lv in range(5))}


def test_pass_access_covers_its_steps():
    # the barrier before the pass makes earlier work visible to every step's access: the
    # pyramid's entry barrier includes the storage reads the steps do
    c = compile(pyramid_graph(3))
    entry = next(b for b in c.barriers if b.pass_name == "hiz" and b.resource == "hiz.pyramid")
    assert entry.dst.access == {"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE"}
    # negative control: without steps the pass only writes it
    g = pyramid_graph(3, steps=[])
    entry = next(b for b in compile(g).barriers if b.resource == "hiz.pyramid"
                 and b.pass_name == "hiz")
    assert entry.dst.access == {"SHADER_STORAGE_WRITE"}


def test_steps_change_no_barrier_between_passes_but_the_covered_access():
    with_steps, without = compile(pyramid_graph(4)), compile(pyramid_graph(4, steps=[]))
    assert without.step_barriers == ()
    pairs = [(b.pass_name, b.resource, b.src) for b in with_steps.barriers]
    assert pairs == [(b.pass_name, b.resource, b.src) for b in without.barriers]
    assert with_steps.heaps == without.heaps


def test_no_barrier_without_a_hazard_between_steps():
    # steps writing disjoint mips, then reading mips nobody wrote in the pass: nothing to wait
    steps = [Step(f"w{m}", writes=Part("img", mips=(m, 1))) for m in range(4)]
    steps += [Step("r", reads=Part("buf", bytes=(512, 16)), writes=Part("buf", bytes=(0, 16)))]
    assert compile(one_pass(steps)).step_barriers == ()


def test_write_after_read_waits_for_the_read():
    steps = [Step("r0", reads=Part("img", mips=(0, 1)), writes=Part("img", mips=(1, 1))),
             Step("w0", writes=Part("img", mips=(0, 1)))]
    b = compile(one_pass(steps)).step_barriers
    assert [(x.step, x.mips) for x in b] == [(1, (0, 1))]
    war = b[0]
    assert war.src.stages == {"COMPUTE_SHADER"} and not war.src.access  # execution only
    assert war.dst.access == {"SHADER_STORAGE_WRITE"}


def test_write_after_write_waits_for_the_write():
    steps = [Step("w0", writes=Part("img", mips=(0, 1))),
             Step("r0", reads=Part("img", mips=(0, 1)), writes=Part("img", mips=(1, 1))),
             Step("w0 again", writes=Part("img", mips=(0, 1)))]
    b = compile(one_pass(steps)).step_barriers
    assert [(x.step, x.mips) for x in b] == [(1, (0, 1)), (2, (0, 1))]
    assert b[1].src.access == {"SHADER_STORAGE_WRITE"}  # the first write, and the read since


def test_neighbouring_spans_with_one_source_merge():
    steps = [Step("w0", writes=Part("img", mips=(0, 1))),
             Step("w1", writes=Part("img", mips=(1, 1))),
             Step("read both", reads=Part("img", mips=(0, 2)), writes=Part("img", mips=(3, 1)))]
    b = compile(one_pass(steps)).step_barriers
    assert [(x.step, x.mips) for x in b] == [(2, (0, 2))]


def test_whole_resource_and_byte_ranges():
    steps = [Step("fill", writes=Part("buf", bytes=(0, 256))),
             Step("use", reads=Part("buf", bytes=(0, 128)), writes=Part("buf", bytes=(512, 64))),
             Step("all", reads="buf", writes=Part("img", mips=(0, 1)))]
    b = compile(one_pass(steps)).step_barriers
    got = [(x.step, x.mips, x.bytes) for x in b]
    # the last step reads the whole buffer: bytes 0..127 are visible to reads already, the
    # fill's other half and the second step's write still need barriers, bytes nobody wrote
    # in the pass none
    assert got == [(1, None, (0, 128)), (2, None, (128, 128)), (2, None, (512, 64))]
    assert [x.part() for x in b] == ["bytes 0..127", "bytes 128..255", "bytes 512..575"]
    assert all(x.dst.layout is None for x in b)


def test_plan_json_and_text_show_step_barriers():
    c = compile(pyramid_graph(3))
    j = c.to_json()["step_barriers"]
    assert [(x["pass"], x["step"], x["mips"]) for x in j] == [("hiz", 1, [0, 1]),
                                                                ("hiz", 2, [1, 1])]
    text = describe(c)
    assert "barriers (5, 2 between steps):" in text
    assert ("  hiz step 2 (level 2) / hiz.pyramid mip 1: GENERAL -> GENERAL; "
            "COMPUTE_SHADER:SHADER_STORAGE_WRITE -> COMPUTE_SHADER:SHADER_STORAGE_READ") in text
    # between-pass barriers come first for their pass, then the pass's steps
    lines = text.splitlines()
    assert lines.index(next(x for x in lines if x.startswith("  hiz / hiz.pyramid"))) < \
        lines.index(next(x for x in lines if x.startswith("  hiz step 1")))


def test_steps_take_part_in_the_compile_cache_key():
    a, b = compile(pyramid_graph(4)), compile(pyramid_graph(4, steps=pyramid_steps(3)))
    assert len(a.step_barriers) == 3 and len(b.step_barriers) == 2


# ---------------------------------------------------------------------------------------------
# soundness on random steps: every hazard between two steps has a barrier between them


def hazards_uncovered(steps: list[list[tuple[int, bool]]], barriers) -> list[tuple]:
    """(i, j, mip) for accesses of one mip at steps i < j, at least one a write, with no
    barrier on that mip at a step in (i, j]; ``steps`` lists (mip, writes) per step."""
    covered = {(b.step, m) for b in barriers
               for m in range(b.mips[0], b.mips[0] + b.mips[1])}
    out = []
    for j, later in enumerate(steps):
        for i in range(j):
            for m, w in steps[i]:
                for m2, w2 in later:
                    if m == m2 and (w or w2) and \
                            not any((k, m) in covered for k in range(i + 1, j + 1)):
                        out.append((i, j, m))
    return out


step_lists = st.lists(st.lists(st.tuples(st.integers(0, 3), st.booleans()), min_size=1,
                               max_size=3, unique_by=lambda t: t[0]), min_size=1, max_size=6)


@settings(max_examples=150, deadline=None)
@given(step_lists)
def test_random_steps_every_hazard_has_a_barrier(accesses):
    steps = [Step(f"s{k}", reads=[Part("img", mips=(m, 1)) for m, w in acc if not w],
                  writes=[Part("img", mips=(m, 1)) for m, w in acc if w])
             for k, acc in enumerate(accesses)]
    if not any(w for acc in accesses for _, w in acc):
        steps.append(Step("w", writes=Part("img", mips=(0, 1))))
        accesses = [*accesses, [(0, True)]]
    barriers = compile(one_pass(steps)).step_barriers
    assert hazards_uncovered(accesses, barriers) == []
    # and every barrier answers an access of its step to its mips
    for b in barriers:
        assert any(b.mips[0] <= m < b.mips[0] + b.mips[1] for m, _ in accesses[b.step])


def test_the_hazard_check_can_fail():
    # negative control: with the barriers dropped, the check reports the hazards
    accesses = [[(0, True)], [(0, False), (1, True)], [(1, False)]]
    assert hazards_uncovered(accesses, ()) == [(0, 1, 0), (1, 2, 1)]


# ---------------------------------------------------------------------------------------------
# mistakes a pass author can make: one-line errors naming pass, step and slot


@pytest.mark.parametrize(("steps", "message"), [
    ([Step("x", writes=Part("imgg", mips=(0, 1)))],
     r"pass 'a', step 0 'x': no slot 'imgg' \(did you mean 'img'\?\)"),
    ([Step("x", writes=Part("img", mips=(2, 3)))],
     r"step 0 'x': slot 'img': mips \(2, 3\) is out of range \('a.img' has 4 mips\)"),
    ([Step("x", writes=Part("img", mips=(0, 0)))], r"mips \(0, 0\) is out of range"),
    ([Step("x", writes=Part("img", mips=(-1, 1)))], r"mips \(-1, 1\) is out of range"),
    ([Step("x", writes=Part("img", mips=(0,)))],
     r"slot 'img': mips must be two integers \(first, count\), not \(0,\)"),
    ([Step("x", writes=Part("img", mips=(True, 1)))], r"mips must be two integers"),
    ([Step("x", writes=Part("buf", mips=(0, 1)))],
     r"slot 'buf' gives mips, but 'a.buf' is not an image"),
    ([Step("x", writes=Part("img", bytes=(0, 4)))],
     r"slot 'img' gives bytes, but 'a.img' is not a buffer"),
    ([Step("x", writes=Part("buf", bytes=(1000, 100)))],
     r"bytes \(1000, 100\) is out of range \('a.buf' has 1024 bytes\)"),
    ([Step("x", writes=Part("img", mips=(0, 1), bytes=(0, 1)))], r"gives both mips and bytes"),
    ([Step("x", reads=Part("img", mips=(0, 2)), writes=Part("img", mips=(1, 1)))],
     r"step 0 'x': overlapping parts of 'a.img' \(\[0, 2\) and \[1, 2\)\) and one is written"),
    ([Step("x", reads="buf", writes="img")],
     r"pass 'a': declares steps, but no step writes slot 'buf' \('a.buf'\)"),
    (["not a step"], r"pass 'a': steps must be rfw.graph.Step declarations"),
])
def test_bad_steps_are_one_line_errors(steps, message):
    with pytest.raises(GraphError, match=message) as e:
        compile(one_pass(steps))
    assert "\n" not in str(e.value)


def test_a_step_cannot_write_what_the_pass_only_reads():
    g = GraphBuilder("r", size=(16, 16))
    g.add_pass("src", "compute").output("t", Texture("r8unorm"))
    g.add_pass("a", "compute", side_effect=True,
               steps=[Step("x", writes=["t", "o"])]).input("t", "src.t").output(
        "o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"step 0 'x': writes slot 't', which the pass only "
                                         r"reads"):
        compile(g.build())
    # negative control: reading it is fine
    g = GraphBuilder("r", size=(16, 16))
    g.add_pass("src", "compute").output("t", Texture("r8unorm"))
    g.add_pass("a", "compute", side_effect=True,
               steps=[Step("x", reads="t", writes="o")]).input("t", "src.t").output(
        "o", Texture("r8unorm"))
    assert compile(g.build()).step_barriers == ()


def test_entering_steps_gives_their_barriers_in_order_only():
    c = compile(pyramid_graph(3))
    assert c.barriers_before_step("hiz", 0, -1) == ()
    assert [b.mips for b in c.barriers_before_step("hiz", 1, 0)] == [(0, 1)]
    with pytest.raises(GraphError, match=r"pass 'hiz' enters step 2 after step 0: steps are "
                                         r"entered in order \(step 1 next\)"):
        c.barriers_before_step("hiz", 2, 0)
    with pytest.raises(GraphError, match=r"pass 'hiz' enters step 3, but declares 3 steps "
                                         r"\(0..2\)"):
        c.barriers_before_step("hiz", 3, 2)
    with pytest.raises(GraphError, match=r"pass 'use' enters step 0 but declares no steps"):
        c.barriers_before_step("use", 0, -1)
