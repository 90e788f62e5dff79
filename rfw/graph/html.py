"""``rfw graph plan --html``: one self-contained page with the pass DAG (Graphviz, top to
bottom, with a legend), the memory timeline and the plan's totals.

The timeline draws each transient as a rectangle: x spans its lifetime (first..last pass in
execution order), y its bytes in its heap (offset..offset+bytes). Two rectangles that share
bytes never share a pass column when the plan aliases correctly, so what aliasing saved is
visible. Every rectangle carries the plan's numbers as ``data-*`` attributes.
"""

from __future__ import annotations

import html
import math
import re
import zlib

from ..units import MiB
from .errors import GraphError
from .graph import Graph
from .inspect import _mib, dot_to_svg, to_dot
from .plan import CompiledGraph, ResourcePlan

# timeline geometry, in SVG user units
_COL = 70  # one pass column
_ROW = 260  # one heap's height
_LEFT, _TOP, _BOTTOM, _RIGHT = 80, 24, 130, 16
_SLANT = math.radians(35)  # pass names under their columns

# Helvetica's advance widths (1/1000 em, its AFM) for ' '..'~': labels are measured so the
# SVG is made wide and tall enough for them; browsers draw Helvetica, Arial or a metric twin
_HELVETICA = dict(zip(map(chr, range(32, 127)), (
    278, 278, 355, 556, 556, 889, 667, 222, 333, 333, 389, 584, 278, 333, 278, 278, 556,
    556, 556, 556, 556, 556, 556, 556, 556, 556, 278, 278, 584, 584, 584, 556, 1015, 667,
    667, 722, 722, 667, 611, 778, 722, 278, 500, 667, 556, 833, 722, 778, 667, 778, 722,
    667, 611, 722, 667, 944, 667, 667, 611, 278, 278, 278, 469, 556, 222, 556, 556, 500,
    556, 556, 278, 556, 556, 222, 222, 500, 222, 833, 556, 556, 556, 556, 333, 500, 278,
    556, 500, 722, 500, 500, 500, 334, 260, 334, 584), strict=True))
_SLACK = 1.2  # a wider stand-in font (DejaVu Sans) still fits


def text_width(text: str, size: float, *, bold: bool = False) -> float:
    """How wide ``text`` is drawn at ``size`` in Helvetica, with slack for a wider font."""
    em = sum(_HELVETICA.get(ch, 1000) for ch in text) / 1000
    return em * size * _SLACK * (1.1 if bold else 1.0)


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def dangling_outputs(graph: Graph, c: CompiledGraph) -> tuple[str, ...]:
    """The graph outputs that became outputs only because nothing reads them: a graph that
    declares none (every Raptor graph) keeps each never-read resource alive to the end."""
    if graph.outputs is not None:
        return ()
    # application-owned ones are outputs because the application keeps them, read or not
    plans = {r.name: r for r in c.resources}
    return tuple(n for n in c.outputs if n in plans and not plans[n].external)


# names an application gives the image it presents (Raptor: final, taa_output, svgf_output)
_PRESENTED = re.compile(r"final|output|present|swapchain|backbuffer|ldr", re.I)


def suggested_output(c: CompiledGraph) -> str | None:
    """The image the frame most likely presents: an image output named like one, written
    last in pass order; else the image output written last."""
    rank = {name: i for i, name in enumerate(c.order)}
    plans = {r.name: r for r in c.resources}
    images = [n for n in c.outputs if n in plans and plans[n].kind == "image"]
    pool = images or [n for n in c.outputs if n in plans]
    if not pool:
        return None
    return max(pool, key=lambda n: (bool(_PRESENTED.search(n)),
                                    rank.get(plans[n].producer or "", -1), -pool.index(n)))


def outputs_note(graph: Graph, c: CompiledGraph, kept: CompiledGraph | None = None) -> str | None:
    """One line for a graph without declared outputs: which resources became outputs, and
    the ``--output`` that keeps only the presented one, given ``kept``, the plan compiled with
    it: what it would allocate, which outputs it drops and which passes it culls (those
    whose results nothing declares reading, so maybe read in ways the graph does not say,
    with the ``--output`` that keeps them). No suggestion when that plan would leave an input
    without its producer, or did not compile; no note when the suggestion changes nothing."""
    dangling = dangling_outputs(graph, c)
    pick = suggested_output(c)
    if not dangling or pick is None:
        return None
    some = f"{len(dangling)} resources nothing reads became outputs and live" \
        if len(dangling) > 1 else "1 resource nothing reads became an output and lives"
    head = (f"note: no outputs declared, so {some} to the end of the frame: "
            f"{', '.join(dangling)}; ")
    if kept is None:
        return head + f"no --output suggested: the plan with --output {pick} does not compile"
    if kept.unproduced:
        lost = ", ".join(f"'{r}' of pass '{p}' (its producer '{q}' culled)"
                         for p, _, r, q in kept.unproduced)
        return head + f"no --output suggested: --output {pick} would leave {lost} unproduced"
    culled = [p for p in kept.culled if p not in c.culled]
    dropped = [n for n in dangling if n != pick]
    if not culled and not dropped:
        return None  # declaring it would change nothing
    parts = [f"transient {_mib(c.transient_bytes)} -> {_mib(kept.transient_bytes)}"]
    if dropped:
        parts.append(f"no longer outputs: {', '.join(dropped)}")
    parts.append(f"culled: {_culled(graph, culled, pick) if culled else 'none'}")
    return head + f"keep only what you present with --output {pick} ({'; '.join(parts)})"


def _culled(graph: Graph, culled: list[str], pick: str) -> str:
    """The culled passes, and which of them no enabled pass declares reading: their results
    may be read in ways the graph does not say (Raptor's lighting reads the point shadows
    and the fog bindlessly), so the note says how to keep them."""
    read = {b.resource for p in graph.passes if p.enabled for b in p.inputs}
    declared = {p.name: p for p in graph.passes}  # compile may add passes (bridges)
    blind = []
    for name in culled:
        writes = [b.resource for b in declared[name].outputs] if name in declared else []
        if writes and not read & set(writes):
            blind.append((name, writes[0]))
    text = ", ".join(culled)
    if not blind:
        return text
    keep = " ".join(f"--output {r}" for r in (pick, *(w for _, w in blind)))
    who = "" if len(blind) == len(culled) else f"{', '.join(n for n, _ in blind)}: "
    them = "them" if len(blind) > 1 else "it"
    return f"{text} ({who}no declared reader; keep {them} with {keep})"


def dag_svg(c: CompiledGraph) -> str:
    """The DAG as inline SVG (``dot -Tsvg``, top to bottom, legend included)."""
    svg = dot_to_svg(to_dot(c), element="--html")
    if svg is None:
        raise GraphError("graphviz 'dot' is not installed: the HTML view needs it for the "
                         "pass DAG", element="--html")
    # inline: no XML prolog, doctype or generator comments inside HTML
    return svg[svg.index("<svg"):]


def _placed(c: CompiledGraph) -> list[ResourcePlan]:
    return [r for r in c.resources
            if r.transient and r.heap is not None and r.offset is not None and r.first
            and r.last]


def _colour(name: str) -> str:
    # stable per name, light enough for black labels
    return f"hsl({zlib.crc32(name.encode()) % 360}, 60%, 72%)"


def timeline_svg(c: CompiledGraph) -> str:
    """Passes on x, heap bytes on y (one band per heap), a rectangle per transient. The
    margins are measured from the labels: nothing is drawn outside the SVG."""
    placed = _placed(c)
    col = {name: i for i, name in enumerate(c.order)}
    n = max(len(c.order), 1)
    heaps = list(c.heaps) or [0]
    ticks = [[f"{b * k / 4 / MiB:.1f} MiB" for k in range(5)] for b in heaps]
    titles = [f"heap #{h}: {_mib(b)}" for h, b in enumerate(heaps)]
    left = max([_LEFT] + [text_width(t, 11) + 12 for row in ticks for t in row])
    base = _TOP + len(heaps) * (_ROW + _TOP) - _TOP + 10
    cos, sin = math.cos(_SLANT), math.sin(_SLANT)
    # a slanted name reaches right by its length and down by its length and ascent
    right = [left + i * _COL + _COL / 2 + text_width(name, 11) * cos + 0.8 * 11 * sin
             for name, i in col.items()]
    right += [left + text_width(t, 11, bold=True) for t in titles]
    right += [left + col[r.first] * _COL + 6 + text_width(r.name, 10) for r in placed]
    width = math.ceil(max([left + n * _COL, *right]) + _RIGHT)
    below = max([text_width(name, 11) * sin + 0.3 * 11 * cos for name in col] + [0.0])
    height = math.ceil(max(_TOP + len(heaps) * (_ROW + _TOP) + _BOTTOM,
                           base + below + _RIGHT))
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" class="timeline" width="{width}" '
           f'height="{height}" viewBox="0 0 {width} {height}" font-family="Helvetica" '
           'font-size="11">']
    for h, heap_bytes in enumerate(heaps):
        y0 = _TOP + h * (_ROW + _TOP)
        scale = _ROW / heap_bytes if heap_bytes else 0.0
        out.append(f'<text x="{left:g}" y="{y0 - 6}" font-weight="bold">{_e(titles[h])}</text>')
        out.append(f'<rect class="heap" x="{left:g}" y="{y0}" width="{n * _COL}" '
                   f'height="{_ROW}" fill="#f6f6f6" stroke="#999"/>')
        for k in range(5):  # byte ticks, offsets grow downwards as in a memory map
            y = y0 + _ROW * k / 4
            out.append(f'<line x1="{left - 4:g}" y1="{y:.1f}" x2="{left:g}" y2="{y:.1f}" '
                       'stroke="#999"/>')
            out.append(f'<text x="{left - 6:g}" y="{y + 4:.1f}" text-anchor="end">'
                       f'{ticks[h][k]}</text>')
        for r in (r for r in placed if r.heap == h):
            x = left + col[r.first] * _COL
            w = (col[r.last] - col[r.first] + 1) * _COL
            y, rh = y0 + r.offset * scale, max(r.bytes * scale, 1.0)
            tip = (f"{r.name}: {r.format or r.kind} {r.width}x{r.height}, {r.bytes:,} B at "
                   f"offset {r.offset:,} in heap #{h}, {r.first}..{r.last}")
            out.append(f'<rect class="transient" data-resource="{_e(r.name)}" data-heap="{h}" '
                       f'data-offset="{r.offset}" data-bytes="{r.bytes}" '
                       f'data-first="{col[r.first]}" data-last="{col[r.last]}" '
                       f'x="{x + 2:g}" y="{y:.2f}" width="{w - 4}" height="{rh:.2f}" '
                       f'fill="{_colour(r.name)}" stroke="#333" stroke-width="0.6">'
                       f'<title>{_e(tip)}</title></rect>')
            if rh >= 12:
                out.append(f'<text x="{x + 6:g}" y="{y + min(rh, 26) / 2 + 4:.1f}" '
                           f'font-size="10">{_e(r.name)}</text>')
    for name, i in col.items():  # pass names under their columns, slanted
        x = left + i * _COL + _COL / 2
        out.append(f'<text x="{x:.1f}" y="{base}" transform="rotate(35 {x:.1f} {base})">'
                   f'{_e(name)}</text>')
    out.append("</svg>")
    return "\n".join(out)


def totals(c: CompiledGraph) -> list[tuple[str, str]]:
    saved = c.unaliased_bytes - c.transient_bytes
    pct = f" ({100 * saved / c.unaliased_bytes:.0f} %)" if c.unaliased_bytes else ""
    return [("heaps", ", ".join(f"#{i} {_mib(b)}" for i, b in enumerate(c.heaps)) or "-"),
            ("transients", str(len(_placed(c)))),
            ("aliased (allocated)", f"{c.transient_bytes:,} B ({_mib(c.transient_bytes)})"),
            ("unaliased", f"{c.unaliased_bytes:,} B ({_mib(c.unaliased_bytes)})"),
            ("saved by aliasing", f"{saved:,} B ({_mib(saved)}){pct}"),
            ("lower bound", f"{c.lower_bound_bytes:,} B ({_mib(c.lower_bound_bytes)})")]


_CSS = """body{font-family:Helvetica,Arial,sans-serif;margin:24px;max-width:1400px}
h1{font-size:20px}h2{font-size:16px;margin-top:28px}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}
.note{background:#fff6d6;border:1px solid #e0c060;padding:8px}
.scroll{overflow-x:auto}svg{max-width:none}"""


def to_html(c: CompiledGraph, *, note: str | None = None) -> str:
    """The whole page: no external file, script or style is referenced."""
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in totals(c))
    res = "".join(
        f"<tr><td>{_e(r.name)}</td><td>{_e(r.format or r.kind)}</td>"
        f"<td>{r.width}x{r.height}</td><td>{r.bytes:,}</td><td>{r.heap}</td>"
        f"<td>{r.offset:,}</td><td>{_e(r.first)}..{_e(r.last)}</td></tr>" for r in _placed(c))
    body = [f"<h1>graph {_e(c.name)} at {c.size[0]}x{c.size[1]}</h1>"]
    if note:
        body.append(f'<p class="note">{_e(note)}</p>')
    body += ["<h2>passes (data flows top to bottom)</h2>",
             f'<div class="scroll">{dag_svg(c)}</div>',
             "<h2>memory timeline</h2>",
             "<p>x: passes in execution order; y: bytes in the heap (offset grows downwards); "
             "each transient is a rectangle from its first to its last pass. Rectangles "
             "sharing bytes in different columns are aliased.</p>",
             f'<table class="totals">{rows}</table>',
             f'<div class="scroll">{timeline_svg(c)}</div>',
             "<h2>transients</h2>",
             "<table><tr><th>resource</th><th>format</th><th>size</th><th>bytes</th>"
             f"<th>heap</th><th>offset</th><th>first..last</th></tr>{res}</table>"]
    page = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>rfw graph {_e(c.name)}</title><style>{_CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    # graphviz may reference nothing external, but say so loudly if it ever does
    if re.search(r'(?:href|src)="(?!#)', page):
        raise GraphError("the HTML view would reference an external file", element="--html")
    return page
