"""Human views of a compiled graph: the text plan and Graphviz DOT."""

from __future__ import annotations

import itertools
import shutil
import subprocess
from typing import Any

from ..units import MiB
from .compile import Barrier, CompiledGraph, ResourcePlan
from .errors import GraphError


def _mib(n: int) -> str:
    return f"{n / MiB:.2f} MiB"


def _table(rows: list[list[str]], header: list[str]) -> list[str]:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return [fmt.format(*header).rstrip(), fmt.format(*("-" * w for w in widths)).rstrip(),
            *(fmt.format(*map(str, r)).rstrip() for r in rows)]


def _header(c: CompiledGraph) -> str:
    whose = "its own size" if c.size_from == "graph" else "given size"
    fixed = sorted({(r.width, r.height) for r in c.resources if r.kind == "image" and r.format})
    if fixed and not c.follow_output:  # say so when the output size sizes nothing
        sizes = ", ".join(f"{w}x{h}" for w, h in fixed)
        whose += f"; no image follows it, all have fixed sizes: {sizes}"
    return f"graph '{c.name}' at {c.size[0]}x{c.size[1]} ({whose})"


def describe(c: CompiledGraph) -> str:
    """The plan as text: order, culled/disabled passes, memory, barriers, totals."""
    out = [_header(c), ""]
    out.append(f"order ({len(c.order)} passes):")
    out += [f"  {i:>3}  {name}" for i, name in enumerate(c.order)]
    out.append(f"culled:   {', '.join(c.culled) or '-'}")
    out.append(f"disabled: {', '.join(c.disabled) or '-'}")
    out.append(f"outputs:  {', '.join(c.outputs) or '-'}")
    out.append("")
    rows = []
    for r in c.resources:
        life = "transient" if r.transient else "history" if r.history else \
            "external" if r.external else "persistent"
        shape = f"{r.width}x{r.height}" if r.kind == "image" else "-"
        rows.append([r.name, r.kind, r.format or "-", shape, f"{r.bytes:,}",
                     "-" if r.heap is None else r.heap,
                     "-" if r.offset is None else f"{r.offset:,}",
                     f"{r.first or '-'}..{r.last or '-'}", life,
                     ",".join(sorted(r.usages)) or "-"])
    out.append("memory:")
    out += ["  " + line for line in _table(rows, ["resource", "kind", "format", "size", "bytes",
                                                  "heap", "offset", "first..last", "lifetime",
                                                  "usage"])]
    out.append("")
    out += _barriers(c)
    out.append("")
    out.append("parallel levels:")
    out += [f"  {i}: {', '.join(level)}" for i, level in enumerate(c.parallel_levels)]
    out.append("")
    if c.queues is not None:
        out += _queues(c.queues)
        out.append("")
    heaps = ", ".join(f"#{i} {_mib(b)}" for i, b in enumerate(c.heaps)) or "-"
    out.append(f"heaps:              {heaps}")
    out.append(f"transient_bytes:    {c.transient_bytes:>14,}  ({_mib(c.transient_bytes)})")
    out.append(f"unaliased_bytes:    {c.unaliased_bytes:>14,}  ({_mib(c.unaliased_bytes)})")
    out.append(f"lower_bound_bytes:  {c.lower_bound_bytes:>14,}  ({_mib(c.lower_bound_bytes)})")
    out.append(f"raptor_reuse_bytes: {c.raptor_reuse_bytes:>14,}  "
               f"({_mib(c.raptor_reuse_bytes)})")
    if c.diagnostics:
        out.append("")
        out.append("diagnostics:")
        out += [f"  {d.level}: {d.message}" for d in c.diagnostics]
    return "\n".join(out)


def _barriers(c: CompiledGraph) -> list[str]:
    """Each pass's barriers before it, then those between its steps (before step N)."""
    steps = f", {len(c.step_barriers)} between steps" if c.step_barriers else ""
    out = [f"barriers ({len(c.barriers)}{steps}):"]
    entry: dict[str, list[Barrier]] = {}
    inside: dict[str, list[Barrier]] = {}
    for b in c.barriers:
        entry.setdefault(b.pass_name, []).append(b)
    for b in c.step_barriers:
        inside.setdefault(b.pass_name, []).append(b)
    for name in c.order:
        out += [_barrier_line(b, f"{b.pass_name} / {b.resource}") for b in entry.get(name, ())]
        for b in inside.get(name, ()):
            step = c.steps[name][b.step] if b.step is not None else "?"
            part = "" if b.mips is None and b.bytes is None else f" {b.part()}"
            out.append(_barrier_line(b, f"{b.pass_name} step {b.step} ({step}) / "
                                        f"{b.resource}{part}"))
    return out


def _queues(q: Any) -> list[str]:
    """Queues, submissions with their semaphore signal and waits, ownership transfers
    (``rfw.graph.queues``)."""
    out = [f"queues: {', '.join(q.queues)} ({q.mode}: {q.why})"]
    if len(q.queues) == 1:
        return out
    out.append(f"submissions ({len(q.submissions)}; a timeline semaphore per queue, "
               "values relative to the frame's base):")
    for s in q.submissions:
        waits = "; ".join(f"wait {w.queue} "
                          + ("end of last frame" if w.submission < 0 else f"= {w.value}")
                          + f" at {'|'.join(sorted(w.stages))}" for w in s.waits)
        out.append(f"  #{s.index} {s.queue:<8} [{', '.join(s.passes) or 'join'}]"
                   + (f"  {waits};" if waits else "")
                   + f"  signal {s.queue} = {s.value} after {'|'.join(sorted(s.signal_stages))}")
    if q.transfers:
        out.append(f"ownership transfers ({len(q.transfers)}):")
        for t in q.transfers:
            rel, acq = t.release.to_json(), t.acquire.to_json()
            out.append(f"  {t.resource}: {t.src} -> {t.dst}; release after {t.after} "
                       f"({rel['from']['stages']}:{rel['from']['access']}), acquire before "
                       f"{t.before} ({acq['to']['stages']}:{acq['to']['access']}); "
                       f"{rel['from']['layout']} -> {acq['to']['layout']}")
    return out


def _barrier_line(b: Barrier, what: str) -> str:
    j = b.to_json()
    src, dst = j["from"], j["to"]
    alias = f"  [takes memory of {', '.join(b.aliased)}]" if b.aliased else ""
    return (f"  {what}: {src['layout']} -> {dst['layout']}; "
            f"{src['stages']}:{src['access']} -> {dst['stages']}:{dst['access']}{alias}")


def _q(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


# what the boxes, ellipses and edges of ``to_dot`` mean, drawn beside the graph
_LEGEND = (
    '<<table border="0" cellborder="1" cellspacing="0" cellpadding="4">'
    '<tr><td colspan="2"><b>legend</b></td></tr>'
    '<tr><td bgcolor="lightblue">pass</td><td>box; runs below every pass it depends on</td></tr>'
    '<tr><td bgcolor="palegreen">transient</td><td>lives within the frame (aliasable)</td></tr>'
    '<tr><td bgcolor="lightgoldenrod">kept</td><td>imported (external), history or persistent'
    '</td></tr>'
    '<tr><td cellpadding="1"><table border="1" cellborder="0" cellpadding="2"><tr><td>'
    '<b>output</b></td></tr></table></td><td>double outline: a graph output, its value at '
    'the end of the frame</td></tr>'
    '<tr><td>solid edge</td><td>writes (pass to resource) or reads (resource to pass)</td></tr>'
    '<tr><td><font color="gray">gray edge</font></td><td>read-modify-write: the next version '
    '(v2, ...) of the same memory</td></tr>'
    '<tr><td>dashed edge</td><td>orders only, no data</td></tr></table>>')


def _res_node(r: ResourcePlan, node: str, version: int, writer: str | None, output: bool) -> str:
    color = "palegreen" if r.transient else "lightgoldenrod"
    if version > 1:  # a later version of the same memory: its name and who wrote it
        label = f"{r.name} v{version}\\nafter {writer}"
    elif r.kind == "image" and r.format:
        fmt = r.format.removeprefix("VK_FORMAT_")  # Raptor's names: shorter boxes
        label = f"{r.name}\\n{fmt} {r.width}x{r.height}"
    elif r.kind in ("image", "buffer") and r.bytes:
        label = f"{r.name}\\n{r.kind} {r.bytes} B"
    else:  # undescribed: the application owns and sizes it (Raptor's externals)
        label = f"{r.name}\\napplication-owned {r.kind}"
    style = ", peripheries=2, penwidth=1.5, fontname=\"Helvetica-Bold\"" if output else ""
    return (f"  {_q(node)} [shape=ellipse, style=filled, fillcolor={color}{style}, "
            f"label=\"{label}\"];")


def to_dot(c: CompiledGraph) -> str:
    """Passes as boxes, resources as ellipses; dashed edges order without data. Top to
    bottom (a long frame stays readable), with a legend node.

    A resource written again (read-modify-write, or a second producer) gets a node per
    version, so every edge points from what runs earlier to what runs later and dot ranks
    each pass below everything it depends on; an invisible chain through the passes in
    compiled order (``minlen=0``) keeps independent passes in that order too."""
    lines = [f"digraph {_q(c.name)} {{", "  rankdir=TB;", "  newrank=true;",
             "  nodesep=0.2;", "  ranksep=0.35;", "  node [fontname=Helvetica];",
             "  edge [fontname=Helvetica];",
             f"  legend [shape=plaintext, fontsize=10, label={_LEGEND}];"]
    for name in c.order:
        lines.append(f"  {_q('pass:' + name)} [shape=box, style=filled, fillcolor=lightblue, "
                     f"label={_q(name)}];")
    outputs = set(c.outputs)
    # each resource's versions: (node, writer); the first node is 'res:NAME'
    versions: dict[str, list[tuple[str, str | None]]] = {r.name: [] for r in c.resources}
    edges: list[str] = []

    def current(res: str) -> str:
        if not versions[res]:
            versions[res].append(("res:" + res, None))
        return versions[res][-1][0]

    for name in c.order:
        p = _q("pass:" + name)
        for a in c.accesses[name]:
            if a.resource not in versions:
                continue
            if a.role == "order":
                edges.append(f"  {_q(current(a.resource))} -> {p} [style=dashed];")
            elif a.role == "modify":  # reads one version, writes the next
                edges.append(f"  {_q(current(a.resource))} -> {p};")
                node = f"res:{a.resource}@{len(versions[a.resource]) + 1}"
                versions[a.resource].append((node, name))
                edges.append(f"  {p} -> {_q(node)} [color=gray];")
            elif a.writes:
                have = versions[a.resource]
                node = "res:" + a.resource if not have else \
                    f"res:{a.resource}@{len(have) + 1}"
                have.append((node, name))
                edges.append(f"  {p} -> {_q(node)};")
            else:
                edges.append(f"  {_q(current(a.resource))} -> {p};")
    for r in c.resources:
        have = versions[r.name] or [("res:" + r.name, None)]
        for k, (node, writer) in enumerate(have, start=1):
            lines.append(_res_node(r, node, k, writer,
                                   r.name in outputs and k == len(have)))
    lines += edges
    # independent passes keep the compiled order: each ranks no higher than the one before
    for a, b in itertools.pairwise(c.order):
        lines.append(f"  {_q('pass:' + a)} -> {_q('pass:' + b)} "
                     "[style=invis, minlen=0, weight=0];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def dot_to_svg(dot: str, **where: str) -> str | None:
    """``dot -Tsvg`` of a DOT text; None when graphviz is not installed. A failing dot
    raises GraphError, ``where`` (``file=``, ``element=``) saying what it was drawing."""
    exe = shutil.which("dot")
    if exe is None:
        return None
    done = subprocess.run([exe, "-Tsvg"], input=dot, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise GraphError(f"dot failed: {done.stderr.strip()}", **where)
    return done.stdout
