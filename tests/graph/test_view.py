"""``rfw graph plan --html``: one self-contained page, the DAG top to bottom with a legend,
and a memory timeline whose rectangles are the plan's placements (read back from the SVG)."""

import itertools
import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "deferred_ssao_shadows.toml"
RAPTOR = ROOT / "tests" / "data" / "raptor" / "chapter8_graph.json"
SVG = "{http://www.w3.org/2000/svg}"

pytestmark = pytest.mark.skipif(__import__("shutil").which("dot") is None,
                                reason="graphviz dot draws the DAG")


def page(tmp_path, graph, *extra):
    out = tmp_path / "plan.html"
    done = warm_cli("graph", "plan", graph, "--html", out, *extra, cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    assert f"wrote {out}" in done.stdout
    plan = warm_cli("graph", "plan", graph, "--json", *extra, cwd=tmp_path, tree=True)
    assert plan.returncode == 0, plan.stderr
    return out.read_text(encoding="utf-8"), json.loads(plan.stdout), done.stdout


def timeline(text):
    svg = re.search(r'<svg xmlns="http://www.w3.org/2000/svg" class="timeline".*?</svg>', text,
                    re.S)
    assert svg, "no timeline SVG"
    root = ET.fromstring(svg.group(0))
    return [r.attrib for r in root.iter(f"{SVG}rect") if r.get("class") == "transient"], \
        [r.attrib for r in root.iter(f"{SVG}rect") if r.get("class") == "heap"]


def overlaps(rects):
    """Pairs sharing bytes of one heap, and whether they also share a pass column."""
    out = []
    for a, b in itertools.combinations(rects, 2):
        if a["data-heap"] != b["data-heap"]:
            continue
        a0, b0 = int(a["data-offset"]), int(b["data-offset"])
        if a0 < b0 + int(b["data-bytes"]) and b0 < a0 + int(a["data-bytes"]):
            time = int(a["data-first"]) <= int(b["data-last"]) and \
                int(b["data-first"]) <= int(a["data-last"])
            out.append((a["data-resource"], b["data-resource"], time))
    return out


def test_page_is_self_contained_with_dag_legend_and_totals(tmp_path):
    text, plan, _ = page(tmp_path, CONFIG, "--size", "32x18")
    assert text.startswith("<!DOCTYPE html>")
    # nothing outside the file: no scripts, stylesheets, images or links by URL
    assert not re.search(r'(?:src|href)\s*=\s*["\'](?!#)', text)
    assert "<link" not in text and "<script" not in text and "<img" not in text
    assert text.count("<svg") == 2  # the DAG and the timeline, inline
    dag = text[text.index("<svg"):text.index("</svg>")]
    assert ">legend<" in dag
    for name in plan["order"]:
        assert f">{name}</text>" in dag
    # top to bottom: each pass's box sits below the one it depends on (gbuffer -> lighting)
    ys = {m.group(1): float(m.group(2)) for m in re.finditer(
        r'<title>pass:([^<]+)</title>\s*<polygon[^>]*points="[-\d.]+,(-?[\d.]+)', dag)}
    assert ys["gbuffer"] < ys["lighting"] < ys["tonemap"] < ys["fxaa"], ys
    for label in ("aliased (allocated)", "unaliased", "saved by aliasing"):
        assert f"<th>{label}</th>" in text
    assert f"{plan['transient_bytes']:,} B" in text
    assert f"{plan['unaliased_bytes']:,} B" in text


def test_timeline_rectangles_are_the_plans_placements(tmp_path):
    text, plan, _ = page(tmp_path, CONFIG, "--size", "32x18")
    rects, heaps = timeline(text)
    transients = [r for r in plan["resources"] if r["transient"] and r["heap"] is not None]
    assert len(transients) >= 8
    assert len(rects) == len(transients)  # one rectangle per transient, no more
    order = {name: i for i, name in enumerate(plan["order"])}
    by_name = {r["data-resource"]: r for r in rects}
    assert len(heaps) == len(plan["heaps"])
    for r in transients:
        rect = by_name[r["name"]]
        assert (int(rect["data-heap"]), int(rect["data-offset"]), int(rect["data-bytes"])) == \
            (r["heap"], r["offset"], r["bytes"])
        assert (int(rect["data-first"]), int(rect["data-last"])) == \
            (order[r["first"]], order[r["last"]])
        # drawn where the numbers say: y from the offset, height from the bytes
        heap = heaps[r["heap"]]
        scale = float(heap["height"]) / plan["heaps"][r["heap"]]["bytes"]
        assert float(rect["y"]) == pytest.approx(float(heap["y"]) + r["offset"] * scale,
                                                 abs=0.01)
        assert float(rect["height"]) == pytest.approx(max(r["bytes"] * scale, 1.0), abs=0.01)
        assert float(rect["y"]) + float(rect["height"]) <= \
            float(heap["y"]) + float(heap["height"]) + 0.01


def test_aliased_resources_share_bytes_never_passes(tmp_path):
    text, plan, _ = page(tmp_path, CONFIG, "--size", "32x18")
    rects, _ = timeline(text)
    pairs = overlaps(rects)
    assert pairs, "aliasing should make rectangles share bytes"
    assert [p for p in pairs if p[2]] == []  # ... but never at the same time
    assert plan["transient_bytes"] < plan["unaliased_bytes"]
    # negative control for the check itself: stretch an aliased rectangle over every pass
    a = pairs[0][0]
    bad = [dict(r) for r in rects]
    for r in bad:
        if r["data-resource"] == a:
            r["data-first"], r["data-last"] = "0", str(len(plan["order"]) - 1)
    assert any(p[2] for p in overlaps(bad))


def test_without_aliasing_nothing_shares_bytes(tmp_path):
    # negative control: the same graph planned without aliasing
    text, plan, _ = page(tmp_path, CONFIG, "--size", "32x18", "--no-alias")
    rects, _ = timeline(text)
    assert len(rects) >= 8
    assert overlaps(rects) == []
    assert plan["transient_bytes"] == plan["unaliased_bytes"]


def test_raptor_graph_names_its_dangling_outputs(tmp_path):
    text, _, stdout = page(tmp_path, RAPTOR)
    notes = [line for line in stdout.splitlines() if line.startswith("note: no outputs")]
    assert len(notes) == 1, stdout
    assert "depth, final" in notes[0] and "--output final" in notes[0]
    assert "--output final" in text and "depth, final" in text
    # the suggestion is the presented image, and the bytes it quotes are its plan's
    done = warm_cli("graph", "plan", RAPTOR.with_name("chapter13_graph.json"), cwd=tmp_path,
                    tree=True)
    [note] = [line for line in done.stdout.splitlines() if line.startswith("note:")]
    assert "1 resource nothing reads became an output and lives" in note
    assert ": visibility_motion_vectors; " in note and "--output taa_output (" in note
    before, after = map(float, re.search(r"transient ([\d.]+) MiB -> ([\d.]+) MiB",
                                         note).groups())
    for extra, quoted in (((), before), (("--output", "taa_output"), after)):
        plan = warm_cli("graph", "plan", RAPTOR.with_name("chapter13_graph.json"), "--json",
                        *extra, cwd=tmp_path, tree=True)
        assert f"{json.loads(plan.stdout)['transient_bytes'] / 2**20:.2f}" == f"{quoted:.2f}"
    assert after < before
    # a graph given its output, and an rfw config (outputs declared), get no note
    for graph, extra in ((RAPTOR, ("--output", "final")), (CONFIG, ())):
        done = warm_cli("graph", "plan", graph, *extra, cwd=tmp_path, tree=True)
        assert done.returncode == 0, done.stderr
        assert "note: no outputs" not in done.stdout


def test_html_onto_a_folder_is_one_line(tmp_path):
    folder = tmp_path / "taken"
    folder.mkdir()
    done = warm_cli("graph", "plan", CONFIG, "--size", "32x18", "--html", folder, cwd=tmp_path,
                    tree=True)
    assert done.returncode == 2
    assert done.stderr == (f"rfw: error: {folder}: --html: exists and is a folder, not a regular "
                           "file: refused as an output\n")
    assert done.stdout == ""  # checked before the plan is printed
    assert [p.name for p in tmp_path.rglob("*")] == ["taken"]
    # a missing folder is made, as for every other output
    out = tmp_path / "new" / "plan.html"
    done = warm_cli("graph", "plan", CONFIG, "--size", "32x18", "--html", out, cwd=tmp_path,
                    tree=True)
    assert done.returncode == 0, done.stderr
    assert out.is_file()
