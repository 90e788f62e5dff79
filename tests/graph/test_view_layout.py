"""The drawings of ``rfw graph dot`` and ``rfw graph plan --html``, read back from their SVGs:
every DAG edge points down (a pass below everything it depends on, passes in compiled
order), graph outputs are drawn apart from transients, and no timeline label leaves the SVG.
Each check is also run on a hand-made drawing it must catch."""

import contextlib
import io
import math
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from PIL import ImageFont

from ..conftest import rfw_cli

ROOT = Path(__file__).resolve().parents[2]
BOOK = ROOT.parent / "shared" / "data" / "raptor-graphs"
LOCAL = ROOT / "tests" / "data" / "raptor"
CHAPTER13 = next((d / "chapter13_graph.json" for d in (BOOK, LOCAL)
                  if (d / "chapter13_graph.json").is_file()), LOCAL / "chapter13_graph.json")
CONFIGS = sorted((ROOT / "configs").glob("*.toml"))
SVG = "{http://www.w3.org/2000/svg}"

pytestmark = pytest.mark.skipif(shutil.which("dot") is None, reason="graphviz dot draws the DAG")


def rfw(*args, cwd, inproc=False):
    """``rfw ARGS`` in a subprocess, or (``inproc``: the loops over every graph) through the
    same ``rfw.cli.main`` in this process, which saves a start per graph."""
    if inproc:
        from rfw.cli import main

        out, err = io.StringIO(), io.StringIO()
        with contextlib.chdir(cwd), contextlib.redirect_stdout(out), \
                contextlib.redirect_stderr(err):
            code = main([*map(str, args)])
        assert code == 0, err.getvalue()
        return out.getvalue()
    done = rfw_cli(*args, cwd=cwd, tree=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


def book_graphs():
    graphs = sorted(BOOK.glob("chapter*_graph*.json")) or sorted(LOCAL.glob("chapter*.json"))
    return graphs


# ---------------------------------------------------------------------------------------------
# the DAG


def drawn(svg_text):
    """Node centres (y grows downwards), node shapes and edges of a dot SVG."""
    root = ET.fromstring(svg_text)
    centre, shapes, edges = {}, {}, []
    for g in root.iter(f"{SVG}g"):
        title = g.find(f"{SVG}title")
        if title is None:
            continue
        if g.get("class") == "node":
            ellipses = g.findall(f"{SVG}ellipse")
            if ellipses:
                centre[title.text] = float(ellipses[0].get("cy"))
            else:
                poly = g.find(f"{SVG}polygon")
                ys = [float(p.split(",")[1]) for p in poly.get("points").split()] \
                    if poly is not None else [0.0]
                centre[title.text] = (min(ys) + max(ys)) / 2
            shapes[title.text] = g
        elif g.get("class") == "edge":
            tail, head = title.text.replace("&#45;", "-").split("->")
            edges.append((tail, head))
    return centre, shapes, edges


def upward(svg_text):
    """The edges whose head is not drawn below their tail."""
    centre, _, edges = drawn(svg_text)
    return [(a, b) for a, b in edges if not centre[b] > centre[a]]


def dag_of(graph, tmp_path, inproc=False):
    out = tmp_path / f"{graph.stem}.dot"
    rfw("graph", "dot", graph, "-o", out, cwd=tmp_path, inproc=inproc)
    return out.read_text(encoding="utf-8"), out.with_suffix(".svg").read_text(encoding="utf-8")


def plan_of(graph, tmp_path):
    text = rfw("graph", "plan", graph, cwd=tmp_path)
    order = re.findall(r"^\s+\d+\s+(\S+)$", text.split("culled:")[0], re.M)
    outputs = re.search(r"^outputs:\s+(.*)$", text, re.M).group(1).split(", ")
    return order, [o for o in outputs if o != "-"]


def test_chapter13_dag_runs_top_to_bottom(tmp_path):
    dot, svg = dag_of(CHAPTER13, tmp_path)
    assert upward(svg) == []
    centre, _, edges = drawn(svg)
    order, _ = plan_of(CHAPTER13, tmp_path)
    assert len(order) == 13
    # the review's case: lighting reads what gbuffer_pass_late writes back in place
    assert centre["pass:gbuffer_pass_late"] < centre["pass:lighting_pass"]
    # passes follow the compiled order where nothing else decides (never drawn above an
    # earlier pass)
    ys = [centre["pass:" + p] for p in order]
    assert ys == sorted(ys), list(zip(order, ys, strict=True))
    # the read-modify-write goes to the next version of the resource, which lighting reads
    assert ("pass:gbuffer_pass_late", "res:gbuffer_colour@2") in edges
    assert ("res:gbuffer_colour@2", "pass:lighting_pass") in edges
    assert "constraint=false" not in dot
    # compact: top to bottom, not a strip (it was 2735x818 pt)
    width, height = (float(v) for v in re.search(
        r'<svg width="([\d.]+)pt" height="([\d.]+)pt"', svg).groups())
    assert width / height < 1.6, (width, height)


def test_every_book_graph_and_config_draws_its_edges_downwards(tmp_path):
    graphs = book_graphs() + CONFIGS
    assert len(graphs) >= 28 + 5 or not BOOK.is_dir()
    for graph in graphs:
        _, svg = dag_of(graph, tmp_path, inproc=True)
        assert upward(svg) == [], graph.name
        width, height = (float(v) for v in re.search(
            r'<svg width="([\d.]+)pt" height="([\d.]+)pt"', svg).groups())
        assert width / height < 3.5, (graph.name, width, height)


def test_an_edge_drawn_upward_is_caught(tmp_path):
    # negative control: the old drawing of a read-modify-write, the write back not ranked
    dot = ('digraph g { "pass:a" -> "res:x"; "res:x" -> "pass:b"; "res:x" -> "pass:c"; '
           '"pass:b" -> "res:x" [constraint=false]; "pass:b" -> "pass:c" [style=invis]; }')
    svg = subprocess.run(["dot", "-Tsvg"], input=dot, capture_output=True, text=True,
                         check=True).stdout
    assert upward(svg) == [("pass:b", "res:x")]


# ---------------------------------------------------------------------------------------------
# outputs


def test_graph_outputs_have_the_output_style(tmp_path):
    for graph in (CHAPTER13, ROOT / "configs" / "deferred_ssao_shadows.toml"):
        dot, svg = dag_of(graph, tmp_path)
        _, shapes, _ = drawn(svg)
        _, outputs = plan_of(graph, tmp_path)
        assert outputs
        latest = {}
        for node in shapes:  # an output's value at the end of the frame: its last version
            if node.startswith("res:"):
                name = node[4:].split("@")[0]
                latest[name] = max(latest.get(name, node), node, key=lambda n: (len(n), n))
        double = {n for n, g in shapes.items() if len(g.findall(f"{SVG}ellipse")) == 2}
        assert double == {latest[o] for o in outputs}, graph.name
        for o in outputs:
            assert re.search(rf'"{re.escape(latest[o])}" \[[^\]]*peripheries=2', dot)
        # negative control: a transient that is no output has one outline, no output style
        transient = next(n for n, g in shapes.items() if n.startswith("res:")
                         and n not in double and 'fill="palegreen"' in ET.tostring(
                             g, encoding="unicode"))
        assert len(shapes[transient].findall(f"{SVG}ellipse")) == 1
        assert not re.search(rf'"{re.escape(transient)}" \[[^\]]*peripheries', dot)
        # and the legend says what the double outline is
        assert "double outline" in svg and ">output<" in svg


# ---------------------------------------------------------------------------------------------
# the memory timeline

_FONTS = Path("/usr/share/fonts/truetype/dejavu")


def _font(size, bold):
    # DejaVu Sans, wider than Helvetica: what a browser without Helvetica or Arial may draw
    path = _FONTS / ("DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf")
    return ImageFont.truetype(str(path), size) if path.is_file() else \
        ImageFont.load_default(size)


def outside(svg_text):
    """The timeline's text elements whose drawn box is not inside the SVG."""
    root = ET.fromstring(svg_text)
    width, height = float(root.get("width")), float(root.get("height"))
    size0 = float(root.get("font-size", "11"))
    out = []
    for t in root.iter(f"{SVG}text"):
        size = float(t.get("font-size", size0))
        text = "".join(t.itertext())
        w = _font(round(size * 10), t.get("font-weight") == "bold").getlength(text) / 10
        x, y = float(t.get("x")), float(t.get("y"))
        x0 = {"end": x - w, "middle": x - w / 2}.get(t.get("text-anchor"), x)
        corners = [(x0, y - 0.8 * size), (x0 + w, y - 0.8 * size), (x0, y + 0.25 * size),
                   (x0 + w, y + 0.25 * size)]
        rot = re.match(r"rotate\(([-\d.]+) ([-\d.]+) ([-\d.]+)\)", t.get("transform", ""))
        if rot:
            a, cx, cy = (float(v) for v in rot.groups())
            c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
            corners = [(cx + (px - cx) * c - (py - cy) * s, cy + (px - cx) * s + (py - cy) * c)
                       for px, py in corners]
        if not all(0 <= px <= width and 0 <= py <= height for px, py in corners):
            out.append(text)
    return out


def timeline_of(graph, tmp_path, inproc=False):
    page = tmp_path / "plan.html"
    rfw("graph", "plan", graph, "--html", page, cwd=tmp_path, inproc=inproc)
    text = page.read_text(encoding="utf-8")
    return re.search(r'<svg xmlns="http://www.w3.org/2000/svg" class="timeline".*?</svg>',
                     text, re.S).group(0)


def test_every_timeline_label_lies_inside_the_svg(tmp_path):
    graphs = book_graphs() + CONFIGS
    for graph in graphs:
        svg = timeline_of(graph, tmp_path, inproc=True)
        assert outside(svg) == [], graph.name
    # the review's case: chapter 13's last pass name, slanted under the last column
    svg = timeline_of(CHAPTER13, tmp_path)
    assert "temporal_anti_aliasing_pass</text>" in svg
    # and the page's DAG is the one drawn downwards
    page = (tmp_path / "plan.html").read_text(encoding="utf-8")
    dag = page[page.index("<svg"):page.index("</svg>") + len("</svg>")]
    assert "pass:lighting_pass" in dag and upward(dag) == []


def test_a_clipped_label_is_caught(tmp_path):
    # negative control: chapter 13's timeline as it was drawn, 16 units right of the last
    # column, with its last pass name slanted out of it
    svg = timeline_of(CHAPTER13, tmp_path)
    root = ET.fromstring(svg)
    heap = next(r for r in root.iter(f"{SVG}rect") if r.get("class") == "heap")
    right = float(heap.get("x")) + float(heap.get("width")) + 16
    old = re.sub(r'width="\d+"', f'width="{right:g}"', svg, count=1)
    assert outside(old) == ["temporal_anti_aliasing_pass"]
    # and a label pushed off the top, or a long one at the right edge
    assert outside(svg.replace("</svg>", '<text x="10" y="5">top</text></svg>')) == ["top"]
    edge = float(root.get("width")) - 40
    wide = svg.replace("</svg>", f'<text x="{edge:g}" y="300">a_long_name</text></svg>')
    assert outside(wide) == ["a_long_name"]
