"""Random but plausible frame graphs, for benchmarks and property tests."""

from __future__ import annotations

import json
import random

from .graph import Graph, GraphBuilder
from .resources import Attachment, Buffer, DepthAttachment, SizeRule, Storage, Texture

_FORMATS = ("rgba8unorm", "rgba16float", "r32float", "rg16float", "rgba32float", "r8unorm")


def synthetic_graph(passes: int, *, seed: int = 0, window: int = 8, fan_in: int = 3,
                    modify: float = 0.1, buffers: float = 0.1) -> Graph:
    """``passes`` passes; each reads up to ``fan_in`` resources made in the previous ``window``
    passes and makes one or two new ones; some write an earlier resource in place."""
    rng = random.Random(seed)
    g = GraphBuilder(f"synthetic_{passes}_{seed}", size=(1920, 1080))
    made: list[tuple[int, str, str]] = []  # (pass index, resource, kind)
    oldest = 0  # made[oldest:] were made in the last ``window`` passes (a scan was quadratic)
    for i in range(passes):
        compute = rng.random() < 0.5
        p = g.add_pass(f"p{i}", "compute" if compute else "graphics")
        while oldest < len(made) and made[oldest][0] < i - window:
            oldest += 1
        recent = made[oldest:]
        for k, (_, res, kind) in enumerate(rng.sample(recent, min(len(recent),
                                                                  rng.randint(1, fan_in)))):
            if kind == "buffer":
                p.input(f"in{k}", res, Buffer(usage=("storage",)))
            elif kind == "image" and compute and rng.random() < modify:
                p.input(f"in{k}", res, Storage())  # read-modify-write in place
            else:
                p.input(f"in{k}", res, Texture())
        for k in range(rng.randint(1, 2)):
            if rng.random() < buffers:
                p.output(f"out{k}", Buffer(rng.choice((1, 4, 16, 64)) * 4096))
                made.append((i, f"p{i}.out{k}", "buffer"))
                continue
            scale = rng.choice((1.0, 1.0, 0.5, 0.25))
            if not compute and k == 0 and rng.random() < 0.2:
                p.output(f"out{k}", DepthAttachment("depth32float", size=SizeRule.output(scale)))
                made.append((i, f"p{i}.out{k}", "depth"))
                continue
            fmt = rng.choice(_FORMATS)
            spec = (Texture if compute else Attachment)(fmt, size=SizeRule.output(scale))
            p.output(f"out{k}", spec)
            made.append((i, f"p{i}.out{k}", "image"))
        if not compute:  # one framebuffer size per render pass
            p.outputs = [o.__class__(o.slot, o.direction, o.spec.with_(size=SizeRule.output()),
                                     o.resource) if o.spec.type in ("attachment", "depth")
                         else o for o in p.outputs]
    g.output(made[-1][1])
    return g.build()


def chain_graph(passes: int, *, format: str = "rgba8unorm") -> Graph:
    """``passes`` passes in a line, each reading the previous one's colour: the deepest graph
    of its size, with one live resource at a time."""
    g = GraphBuilder(f"chain_{passes}", size=(1920, 1080))
    g.add_pass("p0").output("color", Attachment(format))
    for i in range(1, passes):
        g.add_pass(f"p{i}").input("src", f"p{i - 1}.color").output("color", Attachment(format))
    return g.build()


_RAPTOR_OUT = {"texture": "attachment", "attachment": "attachment", "depth": "attachment",
               "buffer": "buffer"}
_RAPTOR_IN = {"texture": "texture", "storage": "attachment", "attachment": "attachment",
              "depth": "attachment", "buffer": "buffer"}


def to_raptor_json(graph: Graph) -> str:
    """A graph as a Raptor engine JSON frame graph, for loader benchmarks: attachments keep
    their format and output scale, buffers become application-owned, as Raptor has them."""
    passes = []
    for p in graph.passes:
        ins = [{"type": _RAPTOR_IN[b.spec.type], "name": b.resource} for b in p.inputs]
        outs = []
        for b in p.outputs:
            out: dict = {"type": _RAPTOR_OUT[b.spec.type], "name": b.resource}
            if out["type"] == "attachment":
                scale = b.spec.size.scale if b.spec.size else (1.0, 1.0)
                out.update(format=b.spec.format, resolution_scale=list(scale),
                           load_operation="VK_ATTACHMENT_LOAD_OP_CLEAR")
            outs.append(out)
        passes.append({"name": p.name, "type": p.type if p.type == "compute" else "",
                       "inputs": ins, "outputs": outs})
    return json.dumps({"name": graph.name, "passes": passes}, indent=4)
