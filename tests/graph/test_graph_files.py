"""Graph files through the real CLI: the plan's header and one error line for bad files."""

from __future__ import annotations

import json
import random
import subprocess
import tomllib
from pathlib import Path

import pytest
import tomli_w

from rfw.errors import RfwError
from rfw.graph import compile, loads_raptor, loads_toml
from rfw.graph.inspect import describe, to_dot

from ..conftest import rfw_cli

DATA = Path(__file__).parent.parent / "data"
ROOT = Path(__file__).parents[2]


def _raptor_outputs(path: Path, key: str) -> list[str]:
    data = json.loads(path.read_text())
    return [o["name"] for p in data["passes"] for o in p.get("outputs", []) if key in o]


def _plan_sizes(path: Path, *args: object) -> tuple[str, dict[str, tuple[int, int]]]:
    text = rfw_cli("graph", "plan", path, *args, cwd=ROOT)
    js = rfw_cli("graph", "plan", path, "--json", *args, cwd=ROOT)
    assert text.returncode == 0 and js.returncode == 0, text.stderr + js.stderr
    sizes = {r["name"]: (r["width"], r["height"]) for r in json.loads(js.stdout)["resources"]}
    return text.stdout.splitlines()[0], sizes


@pytest.mark.parametrize("args, size, whose", [((), (1280, 800), "its own size"),
                                               (("--size", "640x360"), (640, 360),
                                                "given size")])
def test_plan_header_is_the_size_its_scaled_resources_follow(args, size, whose):
    path = DATA / "raptor" / "chapter10_graph.json"
    header, sizes = _plan_sizes(path, *args)
    assert header == f"graph 'gltf_graph' at {size[0]}x{size[1]} ({whose})"
    scaled = [n for n in _raptor_outputs(path, "resolution_scale") if n in sizes]
    assert len(scaled) >= 5
    assert all(sizes[n] == size for n in scaled)


def test_plan_header_says_when_every_image_has_a_fixed_size():
    # chapter 14 declares every image 1280x800: a given 1280x720 sizes nothing
    path = DATA / "raptor" / "chapter14_graph.json"
    header, sizes = _plan_sizes(path, "--size", "1280x720")
    assert header == ("graph 'gltf_graph' at 1280x720 (given size; no image follows it, all "
                      "have fixed sizes: 1280x800)")
    fixed = [n for n in _raptor_outputs(path, "resolution") if n in sizes]
    assert len(fixed) >= 5
    assert all(sizes[n] == (1280, 800) for n in fixed)
    assert (1280, 720) not in sizes.values()


def _one_error_line(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("rfw: error: ")
    return lines[0].removeprefix("rfw: error: ")


TOML_HEAD = 'name = "g"\nsize = [64, 64]\n\n[[pass]]\nname = "a"\ntype = "compute"\n'


BAD_FILES = [
    ("bad.toml", TOML_HEAD.encode() + b"# caf\xc3\x28\n",
     "not UTF-8 text: byte 0xc3 at line 7, column 6"),
    ("bad.json", b'{"name": "g",\n "passes": [{"name": "\xff"}]}',
     "not UTF-8 text: byte 0xff at line 2, column 23"),
    ("usage.toml", (TOML_HEAD + 'outputs.b = { type = "buffer", bytes = 64, '
                    'usage = ["storaeg"] }\n').encode(),
     "pass 'a' (line 5), output 'b': 'usage': unknown usage 'storaeg' (did you mean "
     "'storage'?)"),
    ("name.json", b'{"passes": [\n {"name": "ok"},\n {"name": "/abs/x"}]}',
     "passes[1] (line 3): pass name '/abs/x' is not an identifier (letters, digits, '_', "
     "'.', '-'; starting with a letter or '_')"),
    ("mips.toml", (TOML_HEAD + 'outputs.c = { format = "rgba8unorm", mips = 99 }\n').encode(),
     "pass 'a', slot 'c': 'a.c': mips=99 exceeds the full chain of 7 for 64x64"),
    ("empty.json", b'{"name": "g", "passes": []}', "graph 'passes': the graph has no passes"),
    ("deep.json", b'{"passes": ' + b"[" * 100000 + b"]" * 100000 + b"}",
     "malformed JSON: nested too deeply"),
    ("deep.toml", b"a = " + b"[" * 100000 + b"]" * 100000 + b"\n",
     "malformed TOML: nested too deeply"),
    ("type.json", b'{"passes": [{"name": "a", "outputs": [{"type": "attachment", '
                  b'"name": "c", "format": "rgba8unorm", "resolution": [0, 4]}]}]}',
     "pass 'a' (line 1), output 'c': 'resolution': a size must be two positive integers, "
     "got [0, 4]"),
]


# ids by file name: the deep files' contents would make a node id (and the
# PYTEST_CURRENT_TEST variable a subprocess inherits) longer than exec allows
@pytest.mark.parametrize("name, content, expected", BAD_FILES, ids=[f[0] for f in BAD_FILES])
def test_bad_graph_files_give_one_line_naming_file_and_element(tmp_path, name, content,
                                                               expected):
    path = tmp_path / name
    path.write_bytes(content)
    assert _one_error_line(rfw_cli("graph", "plan", path, cwd=ROOT)) == f"{path}: {expected}"


def test_a_good_file_is_no_error(tmp_path):
    # negative control for the cases above: the same head with a valid output plans
    path = tmp_path / "good.toml"
    path.write_text(TOML_HEAD + 'outputs.c = { format = "rgba8unorm", mips = 7 }\n')
    done = rfw_cli("graph", "plan", path, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("graph 'g' at 64x64 (its own size)")


# ---------------------------------------------------------------------------------------------
# mutated graphs: loaded and compiled, or refused with one RfwError line; nothing else

_VALUES = (None, 0, -1, 1.5, float("nan"), 10**30, "", "x", "../x", [], [1], {}, {"a": 1}, True,
           "rgba8unorm", [1, 2], [0, 0], [-1.0, 2.0], "VK_FORMAT_D32_SFLOAT", 1e308)


def _paths(d, path=()):
    yield path
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _paths(v, (*path, k))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _paths(v, (*path, i))


def _mutate(d, rng: random.Random):
    d = json.loads(json.dumps(d))
    path = rng.choice([p for p in _paths(d) if p])
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    if rng.random() < 0.3:
        del parent[path[-1]]
    else:
        parent[path[-1]] = rng.choice(_VALUES)
    return d


def _no_none(x):
    if isinstance(x, dict):
        return {k: _no_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, list):
        return [_no_none(v) for v in x if v is not None]
    return x


@pytest.mark.parametrize("source", ["three_ways/deferred.json", "raptor/chapter14_graph.json",
                                    "three_ways/deferred.toml", "default_graph.toml"])
def test_mutated_graphs_load_or_raise_one_rfw_error_line(source):
    text = (DATA / source).read_text()
    toml = source.endswith(".toml")
    base = tomllib.loads(text) if toml else json.loads(text)
    rng = random.Random(source)
    outcomes = {"ok": 0, "error": 0}
    for _ in range(150):
        d = _mutate(base, rng)
        if rng.random() < 0.3:
            d = _mutate(d, rng)
        try:
            g = loads_toml(tomli_w.dumps(_no_none(d)), source="g.toml") if toml else \
                loads_raptor(json.dumps(d), source="g.json")
            c = compile(g)
            describe(c)
            to_dot(c)
            outcomes["ok"] += 1
        except RfwError as e:
            assert "\n" not in str(e) and str(e).startswith("g."), str(e)
            outcomes["error"] += 1
    # the mutations reach both outcomes: neither all refused nor all accepted
    assert outcomes["ok"] > 0 and outcomes["error"] > 0, outcomes
