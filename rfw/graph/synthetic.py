"""Random but plausible frame graphs, for benchmarks and property tests."""

from __future__ import annotations

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
    for i in range(passes):
        compute = rng.random() < 0.5
        p = g.add_pass(f"p{i}", "compute" if compute else "graphics")
        recent = [m for m in made if m[0] >= i - window]
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
