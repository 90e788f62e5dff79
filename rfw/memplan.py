"""``rfw graph plan --what-if``: transient memory over every combination of sizes and
toggles, without a GPU, and a budget a CI job checks (exit 1 over it).

Each ``--what-if KEY=V1,V2,...`` names one axis; the table has a row per combination (their
cross product, first axis slowest). ``size`` takes ``720p``, ``1080p``, ``1440p``, ``4k``
(``2160p``) or ``WxH``; any other key is what ``rfw run --set`` takes for a run config (a
variant, ``<pass>.enabled``, ``<pass>.<setting>``), and ``<pass>.enabled`` for a graph file.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import is_run_config, parse_size
from .errors import RfwError
from .graph import CompiledGraph, Graph, MemoryOptions, compile, load_graph
from .graph.memory_model import Profile, predict
from .units import MiB

NAMED_SIZES = {"720p": (1280, 720), "1080p": (1920, 1080), "1440p": (2560, 1440),
               "4k": (3840, 2160), "2160p": (3840, 2160)}


class WhatIfError(RfwError):
    """A ``--what-if`` that names no axis, value or key the graph knows."""


def size_of(text: str) -> tuple[int, int]:
    """``720p``/``1080p``/``1440p``/``4k`` or ``WxH``."""
    named = NAMED_SIZES.get(text.strip().lower())
    if named is not None:
        return named
    try:
        return parse_size(text)
    except ValueError as e:
        raise WhatIfError(f"--what-if size={text}: {e} or one of "
                          f"{', '.join(NAMED_SIZES)}") from None


def axes(items: list[str]) -> list[tuple[str, list[str]]]:
    """``["size=720p,4k", "ssao.enabled=on,off"]`` -> ``[("size", ["720p", "4k"]), ...]``."""
    out: list[tuple[str, list[str]]] = []
    for item in items:
        key, eq, values = item.partition("=")
        key = key.strip()
        vals = [v.strip() for v in values.split(",")]
        if not eq or not key or not all(vals):
            raise WhatIfError(f"--what-if '{item}': expected KEY=V1,V2,... (e.g. "
                              "size=720p,1080p,4k or ssao.enabled=on,off)")
        if key in (k for k, _ in out):
            raise WhatIfError(f"--what-if '{key}' is given twice: give its values once, "
                              "comma-separated")
        if key == "size":
            for v in vals:
                size_of(v)
        out.append((key, vals))
    return out


@dataclass(frozen=True)
class Row:
    settings: tuple[tuple[str, str], ...]
    size: tuple[int, int]
    transient_bytes: int  # aliased (or not, with --no-alias): what the heaps hold
    unaliased_bytes: int

    def label(self) -> str:
        return " ".join(f"{k}={v}" for k, v in self.settings) or "(as declared)"

    def to_json(self) -> dict[str, Any]:
        return {"settings": dict(self.settings), "size": list(self.size),
                "transient_bytes": self.transient_bytes,
                "unaliased_bytes": self.unaliased_bytes}


def _graph_for(file: str, combo: list[tuple[str, str]], *, strict: bool | None,
               caps: list[str] | None,
               size: tuple[int, int] | None) -> tuple[Graph, tuple[int, int] | None]:
    """The graph of ``file`` with one combination applied, and its size (None: its own)."""
    size = next((size_of(v) for k, v in combo if k == "size"), size)
    rest = [(k, v) for k, v in combo if k != "size"]
    if Path(file).suffix.lower() == ".toml" and is_run_config(file):
        from .config import apply_overrides, build, load_config, resolve_auto

        cfg = load_config(file)
        if caps is not None:
            cfg, _ = resolve_auto(cfg, caps)
        sets = [f"{k}={v}" for k, v in rest]
        if size is not None:
            sets.append(f"size={size[0]}x{size[1]}")
        return build(apply_overrides(cfg, sets)).graph, None
    graph = load_graph(file, strict=strict)
    for key, value in rest:
        name, _, what = key.partition(".")
        if what != "enabled":
            raise WhatIfError(f"--what-if '{key}': a graph file takes size and "
                              "<pass>.enabled (run configs take any --set key)")
        on = value.lower()
        if on not in ("on", "off", "true", "false", "1", "0"):
            raise WhatIfError(f"--what-if {key}={value}: expected on or off")
        graph = graph.with_enabled(name, on in ("on", "true", "1"))
    return graph, size


def table(file: str, what_if: list[str], *, profile: Profile | None = None,
          strict: bool | None = None, caps: list[str] | None = None, alias: bool = True,
          outputs: list[str] | None = None, cull: bool = True,
          backend: str | None = None, size: tuple[int, int] | None = None) -> list[Row]:
    """One row per combination of the ``what_if`` axes: the plan's transient bytes
    (``profile``: as that device's driver would size them; else the compiler's estimate).
    ``size`` is the output size of combinations without a ``size`` axis (None: the graph's)."""
    spec = axes(what_if)
    keys = [k for k, _ in spec]
    rows = []
    for values in itertools.product(*(vals for _, vals in spec)):
        combo = list(zip(keys, values, strict=True))
        graph, at = _graph_for(file, combo, strict=strict, caps=caps, size=size)
        if outputs:
            graph = graph.with_outputs(outputs)
        plan = plan_for(graph, at, caps=caps, alias=alias, profile=profile, cull=cull,
                        backend=backend)
        rows.append(Row(tuple(combo), plan.size, plan.transient_bytes, plan.unaliased_bytes))
    return rows


def plan_for(graph: Graph, size: tuple[int, int] | None, *, caps: list[str] | None,
             alias: bool, profile: Profile | None, cull: bool = True,
             backend: str | None = None) -> CompiledGraph:
    plan = compile(graph, size, caps, cull_passes=cull, memory=MemoryOptions(alias=alias),
                   backend=backend)
    return plan if profile is None else predict(plan, profile, alias=alias)


def text(rows: list[Row], *, profile: Profile | None, budget: float | None) -> str:
    # the size axis shows as the size it names
    keys = [k for k, _ in rows[0].settings if k != "size"] if rows else []
    head = [*keys, "size", "transient MiB", "unaliased MiB", "transient B"]
    body = [[*(v for k, v in r.settings if k != "size"), f"{r.size[0]}x{r.size[1]}",
             f"{r.transient_bytes / MiB:.2f}", f"{r.unaliased_bytes / MiB:.2f}",
             f"{r.transient_bytes:,}"] for r in rows]
    if budget is not None:
        head.append("budget")
        for line, r in zip(body, rows, strict=True):
            line.append("over" if r.transient_bytes > budget * MiB else "ok")
    widths = [max(len(str(c)) for c in col) for col in zip(head, *body, strict=True)]
    out = ["  ".join(str(c).ljust(w) for c, w in zip(line, widths, strict=True)).rstrip()
           for line in [head, *body]]
    src = f"device profile '{profile.name}'" if profile else \
        "the compiler's estimate (texel bytes; --device-profile for a driver's padding)"
    return "\n".join([*out, f"transient bytes from {src}"])


def worst(rows: list[Row]) -> Row:
    return max(rows, key=lambda r: r.transient_bytes)


def budget_line(rows: list[Row], budget: float) -> str | None:
    """One line naming the worst combination when it exceeds ``budget`` MiB, else None."""
    w = worst(rows)
    if w.transient_bytes <= budget * MiB:
        return None
    return (f"over budget: {w.label()} at {w.size[0]}x{w.size[1]} needs "
            f"{w.transient_bytes / MiB:.2f} MiB of transient memory, the budget is "
            f"{budget:g} MiB")
