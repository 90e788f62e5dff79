"""Step 1d of ``compile``: the ordered steps inside a pass and the sub-resources they touch.

A pass may declare steps (``PassDecl.steps``), each reading and writing parts of its slots'
resources: a range of mips of an image, a range of bytes of a buffer, or all of it. Here
they are checked and turned into :class:`StepAccess` spans; ``barriers.plan_step_barriers``
plans the barriers between them. Each step access is merged into the pass's access of the
resource, so the barrier before the pass makes earlier work visible to every step.
"""

from __future__ import annotations

from dataclasses import replace

from .accesses import _state_of, _usages
from .errors import did_you_mean
from .graph import PassDecl
from .plan import Access, StepAccess, _Problems
from .resources import Part, ResourceDecl, Step
from .sync import merge_states

# the span of a buffer of unknown size (external, undescribed): "all of it"
WHOLE_BUFFER = 1 << 62


def derive_steps(passes: list[PassDecl], resources: dict[str, ResourceDecl],
                 accesses: dict[str, tuple[Access, ...]], problems: _Problems
                 ) -> dict[str, tuple[tuple[StepAccess, ...], ...]]:
    """Each pass's step accesses, in step order; widens ``accesses`` to cover them."""
    out: dict[str, tuple[tuple[StepAccess, ...], ...]] = {}
    for p in passes:
        if not p.steps:
            continue
        if not all(isinstance(s, Step) for s in p.steps):
            problems.error(f"{p.where()}: steps must be rfw.graph.Step declarations")
            continue
        steps = tuple(_step_accesses(p, k, s, resources, accesses[p.name], problems)
                      for k, s in enumerate(p.steps))
        _check_writers(p, steps, accesses[p.name], problems)
        accesses[p.name] = _cover(p, accesses[p.name], steps, problems)
        out[p.name] = steps
    return out


def whole(r: ResourceDecl) -> int:
    """The end of a resource's span: its mips, its bytes, or one (acceleration structures)."""
    if r.kind == "image":
        return r.mips
    if r.kind == "buffer":
        return r.bytes or WHOLE_BUFFER
    return 1


def _where(p: PassDecl, k: int, step: Step) -> str:
    return f"{p.where()}, step {k} '{step.name}'"


def _step_accesses(p: PassDecl, k: int, step: Step, resources: dict[str, ResourceDecl],
                   accesses: tuple[Access, ...], problems: _Problems
                   ) -> tuple[StepAccess, ...]:
    # a part both read and written by one step is read-modify-write: merge the flags first
    flags: dict[tuple[str, int, int], list[bool]] = {}
    slot_of: dict[tuple[str, int, int], str] = {}
    for parts, write in ((step.reads, False), (step.writes, True)):
        for part in parts:
            found = _part_span(p, k, step, part, resources, accesses, write, problems)
            if found is None:
                continue
            key = found
            flags.setdefault(key, [False, False])[write] = True
            slot_of[key] = part.slot
    _check_overlaps(p, k, step, flags, problems)
    out = []
    for (resource, lo, hi), (reads, writes) in flags.items():
        b = next(b for b in p.bindings if b.slot == slot_of[(resource, lo, hi)])
        r = resources[b.resource]
        role = "modify" if reads and writes else "produce" if writes else "read"
        state = _state_of(_usages(p, b, r), p.type, role, False, r.format, r.kind,
                          b.spec.stages)
        out.append(StepAccess(k, resource, lo, hi, state))
    return tuple(out)


def _part_span(p: PassDecl, k: int, step: Step, part: Part,
               resources: dict[str, ResourceDecl], accesses: tuple[Access, ...], write: bool,
               problems: _Problems) -> tuple[str, int, int] | None:
    """(resource, lo, hi) of a step's part, or None after reporting why it is not one."""
    where = _where(p, k, step)
    slots = [b.slot for b in p.bindings]
    if not isinstance(part, Part) or part.slot not in slots:
        name = part.slot if isinstance(part, Part) else repr(part)
        problems.error(f"{where}: no slot '{name}'" + did_you_mean(str(name), slots))
        return None
    access = next((a for a in accesses if part.slot in a.slots), None)
    if access is None:  # its resource is missing: reported (or warned about) already
        return None
    if access.state is None:
        problems.error(f"{where}: slot '{part.slot}' only orders the pass; a step cannot "
                       "touch it")
        return None
    if write and not access.writes:
        problems.error(f"{where}: writes slot '{part.slot}', which the pass only reads")
        return None
    r = resources[access.resource]
    span = _span(where, part, r, problems)
    return None if span is None else (access.resource, *span)


def _span(where: str, part: Part, r: ResourceDecl, problems: _Problems
          ) -> tuple[int, int] | None:
    if part.mips is not None and part.bytes is not None:
        problems.error(f"{where}: slot '{part.slot}' gives both mips and bytes")
        return None
    if part.mips is None and part.bytes is None:
        return 0, whole(r)
    what, kind = ("mips", "image") if part.mips is not None else ("bytes", "buffer")
    if r.kind != kind:
        problems.error(f"{where}: slot '{part.slot}' gives {what}, but '{r.name}' is not "
                       f"{'an image' if kind == 'image' else 'a buffer'}")
        return None
    pair = part.mips if part.mips is not None else part.bytes
    if not (isinstance(pair, tuple) and len(pair) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in pair)):
        problems.error(f"{where}: slot '{part.slot}': {what} must be two integers "
                       f"(first, count), not {pair!r}")
        return None
    first, count = pair
    end = whole(r)
    if first < 0 or count < 1 or first + count > end:
        limit = f"'{r.name}' has {end} {what}" if end != WHOLE_BUFFER else "sizes are positive"
        problems.error(f"{where}: slot '{part.slot}': {what} ({first}, {count}) is out of "
                       f"range ({limit})")
        return None
    return first, first + count


def _check_overlaps(p: PassDecl, k: int, step: Step, flags: dict[tuple[str, int, int],
                    list[bool]], problems: _Problems) -> None:
    # one step is one unordered batch of work: a write must not overlap another part
    spans = sorted(flags.items())
    for i, ((res, lo, hi), (_, writes)) in enumerate(spans):
        for (res2, lo2, hi2), (_, writes2) in spans[i + 1:]:
            if res2 == res and lo2 < hi and lo < hi2 and (writes or writes2):
                problems.error(f"{_where(p, k, step)}: overlapping parts of '{res}' "
                               f"([{lo}, {hi}) and [{lo2}, {hi2})) and one is written")


def _check_writers(p: PassDecl, steps: tuple[tuple[StepAccess, ...], ...],
                   accesses: tuple[Access, ...], problems: _Problems) -> None:
    # a write outside every step would race with the steps: the plan could not order it
    written = {sa.resource for s in steps for sa in s if sa.state.writes}
    for a in accesses:
        if a.writes and a.resource not in written:
            problems.error(f"{p.where()}: declares steps, but no step writes slot "
                           f"'{a.slots[0]}' ('{a.resource}')")


def _cover(p: PassDecl, accesses: tuple[Access, ...],
           steps: tuple[tuple[StepAccess, ...], ...], problems: _Problems
           ) -> tuple[Access, ...]:
    """The pass's accesses widened by its steps' states, so that the barrier before the pass
    makes earlier work visible to every step."""
    by_resource = {a.resource: a for a in accesses}
    for s in steps:
        for sa in s:
            a = by_resource[sa.resource]
            state = merge_states(a.state, sa.state)
            if state is None:
                problems.error(f"{p.where()}, step {sa.step}: uses '{sa.resource}' in layout "
                               f"{sa.state.layout}, the pass has it in {a.state.layout}")
                continue
            by_resource[sa.resource] = replace(a, state=state)
    return tuple(by_resource[a.resource] for a in accesses)
