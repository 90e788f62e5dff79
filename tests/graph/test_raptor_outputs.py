"""Raptor's ``reference`` inputs and the ``--output`` suggestion, through ``rfw graph plan``.

A ``reference`` input in Raptor is an edge to a resource the pass reads by itself (depth of
field copies ``lighting`` and samples ``depth``): rfw loads it as a read, so culling keeps
its producer. The note of a graph without outputs names what its ``--output`` would cull and
stop keeping, and is only made when that plan leaves no input without its producer.
"""

import json
import re
import tomllib
from pathlib import Path

import pytest
import tomli_w

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = sorted((ROOT / "tests" / "data" / "raptor").glob("*.json"))
LOST = "no kept pass produces"


def plan(graph, *extra, cwd):
    done = warm_cli("graph", "plan", graph, "--json", *extra, cwd=cwd, tree=True)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def note_of(graph, cwd):
    done = warm_cli("graph", "plan", graph, cwd=cwd, tree=True)
    assert done.returncode == 0, done.stderr
    notes = [line for line in done.stdout.splitlines() if line.startswith("note:")]
    assert len(notes) <= 1, done.stdout
    return notes[0] if notes else None


def warnings(p):
    return [d["message"] for d in p["diagnostics"] if d["level"] == "warning"]


def attachment(name, fmt="VK_FORMAT_B8G8R8A8_UNORM"):
    return {"type": "attachment", "name": name, "format": fmt, "resolution": [64, 64],
            "op": "VK_ATTACHMENT_LOAD_OP_CLEAR"}


# the reader comes first in the file, as depth_of_field_pass does in chapter 4; 'stats' is
# application-owned (a buffer without a size), 'debug_view' is read by nothing
GRAPH = {"name": "ref", "passes": [
    {"name": "post", "inputs": [{"type": "reference", "name": "scene"},
                                {"type": "reference", "name": "depth"},
                                {"type": "reference", "name": "stats"}],
     "outputs": [attachment("final")]},
    {"name": "shade", "outputs": [attachment("scene")]},
    {"name": "depth_pre", "outputs": [attachment("depth", "VK_FORMAT_D32_SFLOAT")]},
    {"name": "count", "type": "compute", "outputs": [{"type": "buffer", "name": "stats"}]},
    {"name": "debug", "outputs": [attachment("debug_view")]},
]}


def write_graph(tmp_path):
    path = tmp_path / "ref.json"
    path.write_text(json.dumps(GRAPH), encoding="utf-8")
    return path


def old_mapping(tmp_path, path):
    """The graph as rfw loaded it before: Raptor's reference inputs ordering only (the
    TOML ``rfw graph convert`` wrote then)."""
    done = warm_cli("graph", "convert", path, cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    data = tomllib.loads(done.stdout)
    [post] = [p for p in data["pass"] if p["name"] == "post"]
    assert {s["type"] for s in post["inputs"].values()} == {"texture", "buffer"}  # now: reads
    for slot in post["inputs"].values():
        slot["type"] = "reference"
        slot.pop("usage", None)
    old = tmp_path / "old.toml"
    old.write_text(tomli_w.dumps(data), encoding="utf-8")
    return old


def test_reference_inputs_keep_their_producers(tmp_path):
    p = plan(write_graph(tmp_path), "--output", "final", cwd=tmp_path)
    # only the pass nothing reads is culled; the reader follows what it reads
    assert p["culled"] == ["debug"]
    assert p["order"].index("post") == 3 and set(p["order"][:3]) == {"shade", "depth_pre",
                                                                      "count"}
    assert not [w for w in warnings(p) if LOST in w]
    res = {r["name"]: r for r in p["resources"]}
    assert res["scene"]["last"] == res["depth"]["last"] == "post"  # alive until read
    assert res["scene"]["transient"] and res["depth"]["transient"]
    # the read is synchronised: the writes are made visible to the reading pass
    to = {(b["pass"], b["resource"]): b["to"] for b in p["barriers"]}
    assert to[("post", "scene")]["layout"] == "SHADER_READ_ONLY_OPTIMAL"
    assert to[("post", "depth")]["layout"] == "DEPTH_READ_ONLY_OPTIMAL"
    # without --output, the resources it reads are no dangling outputs either
    assert "the frame: final, debug_view;" in note_of(tmp_path / "ref.json", tmp_path)


def test_the_old_mapping_is_caught(tmp_path):
    # negative control: reference inputs as ordering only, as rfw read them before, lose
    # their producers to --output final; each such input is named with its resource
    old = old_mapping(tmp_path, write_graph(tmp_path))
    p = plan(old, "--output", "final", cwd=tmp_path)
    assert set(p["culled"]) == {"shade", "depth_pre", "count", "debug"}
    lost = [w for w in warnings(p) if LOST in w]
    assert len(lost) == 3, lost
    assert any(re.fullmatch(r"pass 'post'( \(line \d+\))?, slot 'scene': no kept pass produces "
                            r"'scene' \(its producer 'shade' is culled: no graph output "
                            r"needs it\)", w) for w in lost), lost
    # ordering only reads nothing: said, not refused, also when strict
    strict = plan(old, "--output", "final", "--strict", cwd=tmp_path)
    assert len([w for w in warnings(strict) if LOST in w]) == 3
    # and the note suggests no --output that would do that
    note = note_of(old, tmp_path)
    assert note is not None and "keep only what you present" not in note
    assert "no --output suggested: --output final would leave 'scene' of pass 'post' (its " \
           "producer 'shade' culled)" in note, note


def test_the_note_names_what_the_suggestion_culls_and_drops(tmp_path):
    path = write_graph(tmp_path)
    note = note_of(path, tmp_path)
    assert note == ("note: no outputs declared, so 2 resources nothing reads became outputs "
                    "and live to the end of the frame: final, debug_view; keep only what you "
                    "present with --output final (transient 0.19 MiB -> 0.19 MiB; no longer "
                    "outputs: debug_view; culled: debug (no declared reader; keep it with "
                    "--output final --output debug_view))"), note
    # the way to keep it does keep it
    kept = plan(path, "--output", "final", "--output", "debug_view", cwd=tmp_path)
    assert kept["culled"] == []


def _suggestion(note):
    """(pick, culled, no longer outputs, culled without a declared reader, --output args
    that keep those) as the note states them."""
    m = re.search(r"keep only what you present with --output (\S+) \(transient [\d.]+ MiB -> "
                  r"[\d.]+ MiB(?:; no longer outputs: ([^;]+))?; culled: (.*)\)$", note)
    assert m, note
    pick, dropped, culled = m.groups()
    c = re.fullmatch(r"([\w, ]+?)(?: \((?:([\w, ]+): )?no declared reader; keep (?:it|them) "
                     r"with (.*)\))?", culled)
    assert c, culled
    names = [] if c.group(1) == "none" else c.group(1).split(", ")
    blind = c.group(2).split(", ") if c.group(2) else names if c.group(3) else []
    keep = c.group(3).split()[1::2] if c.group(3) else []
    return pick, names, dropped.split(", ") if dropped else [], blind, keep


@pytest.mark.parametrize("path", RAPTOR, ids=[p.stem for p in RAPTOR])
def test_every_raptor_suggestion_is_a_valid_graph(tmp_path, path):
    full = plan(path, cwd=tmp_path)
    note = note_of(path, tmp_path)
    if note is None:
        return
    assert "no --output suggested" not in note  # every book graph has a valid suggestion
    pick, culled, dropped, blind, keep = _suggestion(note)
    kept = plan(path, "--output", pick, cwd=tmp_path)
    # it compiles, leaves no input without its producer, and culls what the note says
    assert not [w for w in warnings(kept) if LOST in w]
    assert [n for n in kept["culled"] if n not in full["culled"]] == culled
    owned = {r["name"] for r in full["resources"] if not r["transient"]}
    assert dropped == [n for n in _outputs(path, tmp_path) if n != pick and n not in owned]
    # a pass nothing declares reading is kept by the --output the note gives for it
    assert bool(blind) == bool(keep) and keep[:1] in ([pick], [])
    if keep:
        back = plan(path, *[a for r in keep for a in ("--output", r)], cwd=tmp_path)
        assert set(blind) <= set(back["order"]) and not set(blind) & set(back["culled"])
        assert not [w for w in warnings(back) if LOST in w]


def _outputs(path, cwd):
    # the text plan names the graph outputs (the JSON plan leaves them out)
    done = warm_cli("graph", "plan", path, cwd=cwd, tree=True)
    [line] = [x for x in done.stdout.splitlines() if x.startswith("outputs:")]
    names = line.split(":", 1)[1].strip()
    return [] if names == "-" else names.split(", ")


def test_chapter4_keeps_depth_of_field_inputs(tmp_path):
    # the review's case: --output final used to leave only depth_of_field_pass
    path = ROOT / "tests" / "data" / "raptor" / "chapter4_graph.json"
    p = plan(path, "--output", "final", cwd=tmp_path)
    assert p["culled"] == [] and p["order"][-1] == "depth_of_field_pass"
    assert not [r for r in p["resources"] if r["first"] is None]  # nothing unproduced
    assert note_of(path, tmp_path) is None  # final is all it leaves: nothing to suggest


@pytest.mark.parametrize("name", ["chapter8_graph", "chapter13_graph", "chapter15_graph"])
def test_bindless_results_are_named_when_culled(tmp_path, name):
    note = note_of(ROOT / "tests" / "data" / "raptor" / f"{name}.json", tmp_path)
    shadows = "point_shadows_pass"
    fog = [] if name == "chapter8_graph" else ["volumetric_fog_pass"]
    culled = ", ".join([shadows, *fog])
    outputs = " ".join(f"--output {r}" for r in ["point_shadows_depth",
                                                  *(["volumetric_fog_texture"] if fog else [])])
    them = "them" if fog else "it"
    assert f"culled: {culled} (no declared reader; keep {them} with --output " in note, note
    assert note.endswith(f" {outputs}))"), note


def test_only_passes_without_a_declared_reader_are_flagged(tmp_path):
    # negative control: 'debug' has a reader ('debug_post', culled too); only the end of the
    # chain is flagged, and keeping it keeps the chain
    graph = json.loads(json.dumps(GRAPH))
    graph["passes"].append({"name": "debug_post", "inputs": [{"type": "texture",
                                                              "name": "debug_view"}],
                            "outputs": [attachment("debug_post_view")]})
    path = tmp_path / "chain.json"
    path.write_text(json.dumps(graph), encoding="utf-8")
    note = note_of(path, tmp_path)
    assert note.endswith("no longer outputs: debug_post_view; culled: debug, debug_post "
                         "(debug_post: no declared reader; keep it with --output final "
                         "--output debug_post_view))"), note
    kept = plan(path, "--output", "final", "--output", "debug_post_view", cwd=tmp_path)
    assert kept["culled"] == []
