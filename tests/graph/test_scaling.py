"""The compiler scales without changing a plan: memory placement and line indexing.

``raptor_memory_plans.json`` holds the offsets the placement gave the 28 Raptor graphs before
it moved from scanning every overlapping resource to a span tree; the plans must not move.
The new placement is also checked against the scan, a plain best fit written out here, on
random lifetimes. No test times anything: growth is counted in operations.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rfw.errors import RfwError
from rfw.graph import compile, load_graph, loads_raptor, loads_toml, placement, to_toml
from rfw.graph.synthetic import chain_graph, synthetic_graph, to_raptor_json

Item = placement.Item

DATA = Path(__file__).parent.parent / "data"
RECORDED = json.loads((Path(__file__).parent / "data" / "raptor_memory_plans.json").read_text())


def _plan(c) -> dict:
    return {"heaps": list(c.heaps),
            "offsets": {r.name: [r.heap, r.offset] for r in c.resources if r.transient}}


@pytest.mark.parametrize("key", sorted(RECORDED))
def test_raptor_memory_plans_are_unchanged(key):
    name, label = key.split(" ")
    size = None if label == "own" else tuple(int(v) for v in label.split("x"))
    c = compile(load_graph(DATA / "raptor" / name), size)
    assert _plan(c) == RECORDED[key]


def test_the_recorded_plans_cover_every_raptor_graph():
    names = {p.name for p in (DATA / "raptor").glob("*.json")}
    assert len(names) == 28
    assert {k.split(" ")[0] for k in RECORDED} == names


def test_a_moved_offset_fails_the_comparison():
    # negative control: the comparison sees one resource moved by one alignment unit
    key = "chapter14_graph.json own"
    name, _ = key.split(" ")
    plan = _plan(compile(load_graph(DATA / "raptor" / name)))
    moved = json.loads(json.dumps(RECORDED[key]))
    first = sorted(moved["offsets"])[0]
    moved["offsets"][first][1] += 64 * 1024
    assert plan == RECORDED[key]
    assert plan != moved


def _scan(items: list) -> tuple[int, dict[str, int]]:
    """Best fit written out plainly: the smallest gap among the byte ranges of the placed
    items whose lifetimes overlap, lowest on ties, else on top of them."""
    placed: list[tuple[int, int, int, int]] = []
    offsets: dict[str, int] = {}
    for it in items:
        busy = sorted((s, e) for s, e, f, last in placed if f <= it.last and it.first <= last)
        best, best_gap, cursor = None, None, 0
        for s, e in busy:
            if s - cursor >= it.size and (best_gap is None or s - cursor < best_gap):
                best, best_gap = cursor, s - cursor
            cursor = max(cursor, e)
        offset = cursor if best is None else best
        placed.append((offset, offset + it.size, it.first, it.last))
        offsets[it.name] = offset
    return max((e for _, e, _, _ in placed), default=0), offsets


lifetimes = st.lists(st.tuples(st.integers(0, 60), st.integers(0, 60), st.integers(1, 8)),
                     min_size=1, max_size=60)


@settings(max_examples=300, deadline=None)
@given(lifetimes, st.booleans())
def test_span_tree_and_bucket_placements_equal_a_plain_best_fit(spans, long_lived):
    items = []
    for k, (a, b, size) in enumerate(spans):
        first, last = min(a, b), max(a, b)
        if long_lived and k % 3 == 0:
            last = 200  # graph outputs live to the end of the frame
        items.append(Item(f"r{k}", size * 256, first, last))
    expected = _scan(items)
    by_first = sorted(items, key=lambda it: (it.first, -it.size, it.name))
    assert placement._place_sweep(by_first) == _scan(by_first)
    assert placement._place_tree(items) == expected
    assert placement._place_buckets(items) == expected
    assert placement._place(items) == expected


def test_the_plain_best_fit_rejects_an_overlap():
    # negative control for the reference itself: two items alive together get disjoint bytes
    items = [Item("a", 256, 0, 5), Item("b", 256, 3, 9), Item("c", 256, 6, 9)]
    top, offsets = _scan(items)
    assert offsets == {"a": 0, "b": 256, "c": 0}
    assert top == 512


def _union_updates(items: list) -> int:
    """Range updates the span tree makes for these items (a count, not a time)."""
    calls = 0
    real = placement._Union.add

    def counting(self, start, end):
        nonlocal calls
        calls += 1
        real(self, start, end)

    placement._Union.add = counting
    try:
        placement._place_tree(items)
    finally:
        placement._Union.add = real
    return calls


def test_span_tree_work_grows_near_linearly_with_long_lived_items():
    # half the items live to the end of the frame: scanning them is quadratic, the tree
    # makes O(log n) updates per item
    def items(n):
        return [Item(f"r{k}", 256, k, n if k % 2 else k + 1) for k in range(n)]

    small, big = _union_updates(items(1000)), _union_updates(items(8000))
    assert big < 8 * 1.5 * small  # 8x the items, at most 12x the updates
    assert big > 8 * small / 1.5  # and not suspiciously little: every item is recorded


def test_scan_is_chosen_for_short_lives_and_the_tree_for_long_ones():
    short = [Item(f"r{k}", 256, k, k + 2) for k in range(5000)]
    long = [Item(f"r{k}", 256, k, 5000) for k in range(5000)]
    assert placement._scan_is_cheaper(short)
    assert not placement._scan_is_cheaper(long)


# ---------------------------------------------------------------------------------------------
# loaders index pass lines once per file


@pytest.mark.parametrize("n", [50, 400])
def test_big_files_load_equal_to_the_graph_they_were_written_from(n):
    g = synthetic_graph(n, seed=3)
    toml = loads_toml(to_toml(g))
    assert toml.passes == g.passes
    assert compile(toml).to_json() == compile(g).to_json()
    raptor = loads_raptor(to_raptor_json(chain_graph(n)))
    assert [p.name for p in raptor.passes] == [f"p{i}" for i in range(n)]


def test_pass_lines_come_from_one_sweep():
    text = to_raptor_json(chain_graph(300))
    lines = text.splitlines()
    g = loads_raptor(text)
    for p in g.passes:
        line = int(p.origin.removeprefix("line "))
        assert f'"name": "{p.name}"' in lines[line - 1]
    # negative control: the line of another pass does not hold this one's name
    assert '"name": "p7"' not in lines[int(g.passes[8].origin.removeprefix("line ")) - 1]


def test_a_pass_name_that_is_no_identifier_names_file_and_line(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('name = "g"\nsize = [4, 4]\n\n[[pass]]\nname = "a"\n'
                    'outputs.c = { type = "attachment", format = "rgba8unorm" }\n\n'
                    '[[pass]]\nname = \'../it"s\'\ninputs.x = "a.c"\n')
    with pytest.raises(RfwError) as e:
        load_graph(path)
    assert str(e.value) == (f"{path}: [[pass]] #2 (line 9): pass name '../it\"s' is not an "
                            "identifier (letters, digits, '_', '.', '-'; starting with a letter "
                            "or '_')")
