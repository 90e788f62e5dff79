"""The loaders' and compiler's fast paths keep their behaviour: a bad value still fails with
one line, a cached slot kind never hides an error, the cycle collector is left as found.

Speed itself lives in benchmarks/bench_graph.py; nothing here times anything.
"""

from __future__ import annotations

import gc
import re
import sys

import pytest

from rfw.errors import RfwError
from rfw.graph import GraphBuilder, compile, loads_raptor, loads_toml
from rfw.graph.errors import GraphError
from rfw.graph.resources import Attachment, Texture
from rfw.graph.sync import State

compile_module = sys.modules["rfw.graph.compile"]  # the package's compile() shadows it

GOOD_TOML = ('size = [64, 64]\n[[pass]]\nname = "a"\ntype = "compute"\n'
             'outputs.c = { type = "texture", format = "rgba8unorm" }\n')


@pytest.mark.parametrize("text, line", [
    ("name = ", 1),
    ('name = "g"\nsize = [64,\n64\n', 3),  # unclosed array
    ('name = "g"\nname = "h"\n', 2),  # duplicate key
    ('name = "a\\q"\n', 1),  # bad escape
])
def test_malformed_toml_is_one_line_naming_its_line(text, line):
    with pytest.raises(GraphError) as e:
        loads_toml(text, source="bad.toml")
    message = str(e.value)
    assert "\n" not in message
    assert message.startswith("bad.toml: malformed TOML: ")
    assert f"line {line}" in message


def test_well_formed_toml_loads():
    # negative control for the above: the same loader accepts a good file
    assert [p.name for p in loads_toml(GOOD_TOML).passes] == ["a"]


@pytest.mark.parametrize("snippet, message", [
    ("mips = true", "'mips': expected int, got true"),
    ("external = 1", "'external': expected bool, got 1"),
    ("scale = nan", "'scale': expected a positive finite number"),
    ("scale = -0.5", "'scale': expected a positive finite number, got -0.5"),
    ("scale = inf", "'scale': expected a positive finite number"),
    ("format = 3", "'format': expected str, got 3"),
])
def test_type_checks_still_refuse_near_misses(snippet, message):
    text = GOOD_TOML.replace('format = "rgba8unorm" }', f'format = "rgba8unorm", {snippet} }}')
    if snippet.startswith("format"):
        text = GOOD_TOML.replace('format = "rgba8unorm"', snippet)
    with pytest.raises(GraphError) as e:
        loads_toml(text, source="g.toml")
    assert "pass 'a' (line 3), output 'c': " + message in str(e.value)


@pytest.mark.parametrize("text, message", [
    ('[[pass]]\nname = "a..b"\n', "pass name 'a..b' is not an identifier"),
    ('[[pass]]\nname = "a"\noutputs."x y" = { type = "texture", format = "r8unorm" }\n',
     "slot name 'x y' is not an identifier"),
    ('[[pass]]\nname = "a"\ninputs.x = "../up"\n', "resource name '../up' is not an identifier"),
])
def test_identifier_checks_still_refuse_bad_names(text, message):
    with pytest.raises(RfwError) as e:
        loads_toml(text, source="g.toml")
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def _mismatch_graph(read_format: str):
    g = GraphBuilder("kinds", size=(64, 64))
    g.add_pass("a", "graphics").output("c", Attachment("rgba8unorm"))
    g.add_pass("b", "compute").input("t", "a.c", Texture(read_format)) \
        .output("o", Texture("rgba8unorm"))
    g.output("b.o")
    return g.build()


def test_a_slot_kind_that_failed_fails_again_after_good_ones():
    # slot kinds are checked once and remembered; only those that passed are remembered
    compile_module._CACHE.clear()
    for _ in range(2):
        with pytest.raises(GraphError, match=re.escape("declares format r8unorm but 'a.c' is "
                                                        "rgba8unorm")):
            compile(_mismatch_graph("r8unorm"))
        compile_module._CACHE.clear()
        assert compile(_mismatch_graph("rgba8unorm")).order == ("a", "b")
        compile_module._CACHE.clear()


@pytest.mark.parametrize("enabled", [True, False])
def test_loading_and_compiling_leave_the_cycle_collector_as_found(enabled):
    was = gc.isenabled()
    (gc.enable if enabled else gc.disable)()
    try:
        compile_module._CACHE.clear()
        compile(loads_toml(GOOD_TOML))
        assert gc.isenabled() is enabled
        loads_raptor('{"passes": [{"name": "a", "type": "graphics", "outputs": '
                     '[{"type": "attachment", "name": "c", "format": "rgba8unorm"}]}]}')
        assert gc.isenabled() is enabled
        for bad in (lambda: loads_toml("name = "), lambda: compile(_mismatch_graph("r8unorm"))):
            with pytest.raises(GraphError):
                bad()
            assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()


def test_merged_states_and_their_write_flags():
    read = State("GENERAL", frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_STORAGE_READ"}))
    write = State("GENERAL", frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_STORAGE_WRITE"}))
    assert not read.writes and read.write_access == frozenset()
    both = read.merge(write)
    assert both == State("GENERAL", frozenset({"COMPUTE_SHADER"}),
                         frozenset({"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE"}))
    assert both.writes and both.write_access == frozenset({"SHADER_STORAGE_WRITE"})
    assert read.merge(write) is both  # made once
    assert read.merge(read) == read and not read.merge(read).writes
