"""Step 1b of ``compile``, second half: outputs declared ``format_of=<slot>`` take the format of
the resource bound to that slot of the same pass (a post-process keeps its input's format).

Resolved after every resource is declared, so the resource followed may be produced later in
declaration order or follow another one in turn; a cycle is an error. An sRGB format written
as a storage image (a compute pass's output) becomes its linear twin: ``rgba8unorm-srgb`` ->
``rgba8unorm``."""

from __future__ import annotations

from dataclasses import replace

from .accesses import _usages, slot_where
from .errors import did_you_mean
from .formats import format_info
from .graph import PassDecl
from .plan import _Problems
from .resources import Binding, ResourceDecl


def resolve_formats_of(passes: list[PassDecl], resources: dict[str, ResourceDecl],
                       problems: _Problems) -> None:
    """Fill in the format of every ``format_of`` output in ``resources``."""
    follows: dict[str, tuple[str, str, str]] = {}  # resource -> (followed, format_of, where)
    uses: dict[str, list[tuple[PassDecl, Binding]]] = {}
    for p in passes:
        bound = {b.slot: b.resource for b in p.bindings}
        for b in p.bindings:
            uses.setdefault(b.resource, []).append((p, b))
        for b in p.outputs:
            of, where = b.spec.format_of, slot_where(p, b)
            if of is None or b.spec.type == "reference" or b.resource not in resources:
                continue
            if b.spec.format is not None:
                problems.error(f"{where}: declares both format {b.spec.format} and "
                               f"format_of '{of}' (keep one)")
            elif of not in bound:
                problems.error(f"{where}: format_of '{of}' is not a connected slot of the pass "
                               f"(slots: {', '.join(bound)})" + did_you_mean(of, bound))
            else:
                follows[b.resource] = (bound[of], of, where)
    for name in follows:
        _follow(name, follows, uses, resources, problems, [])


def _follow(name: str, follows: dict[str, tuple[str, str, str]],
            uses: dict[str, list[tuple[PassDecl, Binding]]],
            resources: dict[str, ResourceDecl], problems: _Problems,
            stack: list[str]) -> str | None:
    r = resources.get(name)
    if r is None or name not in follows or r.format is not None:
        return None if r is None else r.format
    source, of, where = follows[name]
    if name in stack:
        problems.error(f"{where}: format_of forms a cycle: " + " -> ".join([*stack, name]))
        return None
    fmt = _follow(source, follows, uses, resources, problems, [*stack, name])
    got = resources.get(source)
    if got is None:
        problems.error(f"{where}: format_of '{of}': '{source}' is not a resource of the graph")
        return None
    if got.kind != "image":
        problems.error(f"{where}: format_of '{of}': '{source}' is a {got.kind}, not an image")
        return None
    if fmt is None:
        if source not in follows:  # a followed failure was reported already
            problems.error(f"{where}: format_of '{of}': '{source}' has no format to take "
                           "(declare this output's format)")
        return None
    # no device stores to sRGB images: a storage-written copy takes the linear twin (the
    # same bytes per texel; the shader stores linear values, as it reads them)
    r = replace(r, format=fmt)
    if format_info(fmt).srgb and any("storage" in _usages(p, b, r) for p, b in uses[name]):
        r = replace(r, format=linear_twin(fmt))
    resources[name] = r
    return r.format


def linear_twin(fmt: str) -> str:
    """The format with the same texels, unorm instead of sRGB-encoded."""
    twin = fmt.replace("-srgb", "") if not fmt.startswith("VK_FORMAT_") else \
        fmt.replace("_SRGB", "_UNORM")
    format_info(twin)  # every sRGB format has one; a table change should fail loudly
    return twin
