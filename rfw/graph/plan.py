"""What the compiler works on and produces: the validated declaration, and the compiled
plan (order, resources, memory, barriers) executors follow without deciding anything."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from .errors import GraphError
from .graph import Graph, PassDecl
from .resources import BUFFER_USAGES, IMAGE_USAGES, ResourceDecl
from .sync import State

# step executions (cache misses), so tests and benchmarks can see what a recompile redid
STATS: Counter[str] = Counter()

# pass types whose attachments are real render targets (compute writes them as storage)
RASTER = frozenset({"graphics", "mesh"})
MAX_DIMENSION = 65536  # beyond any device's image limit: a size rule gone wrong
KNOWN_USAGES = BUFFER_USAGES | IMAGE_USAGES | {"accel_build", "accel_read"}
IMPLIED_CAPS = {"mesh": ("VK_EXT_mesh_shader",), "ray_tracing": ("VK_KHR_ray_tracing_pipeline",)}


@dataclass(frozen=True)
class MemoryOptions:
    """Placement rules for transient resources."""

    alias: bool = True
    image_alignment: int = 64 * 1024
    buffer_alignment: int = 256
    # (resource, bytes) a device reports for a resource, replacing the texel-count estimate:
    # drivers pad rows and tiles, and a plan must hold what the driver will bind
    sizes: tuple[tuple[str, int], ...] = ()


@dataclass(frozen=True)
class Diagnostic:
    level: str  # "error" | "warning" | "info"
    message: str

    def to_json(self) -> dict[str, str]:
        return {"level": self.level, "message": self.message}


@dataclass(frozen=True)
class Access:
    """One pass touching one resource (all its slots on that resource merged)."""

    pass_name: str
    resource: str
    role: str  # produce | modify | read | order | history
    usages: frozenset[str]
    state: State | None  # None: ordering only
    slots: tuple[str, ...]
    load: str | None = None

    @property
    def writes(self) -> bool:
        return self.role in ("produce", "modify")


@dataclass(frozen=True)
class ResourcePlan:
    name: str
    kind: str  # image | buffer | accel
    format: str | None
    width: int
    height: int
    mips: int
    layers: int
    samples: int
    raw_bytes: int  # texel or buffer bytes
    bytes: int  # raw_bytes rounded up to the placement alignment
    usages: frozenset[str]
    producer: str | None
    first: str | None
    last: str | None
    transient: bool
    external: bool
    history: bool
    heap: int | None = None
    offset: int | None = None

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "format": self.format,
                "width": self.width, "height": self.height, "bytes": self.bytes,
                "heap": self.heap, "offset": self.offset, "first": self.first,
                "last": self.last, "transient": self.transient}


@dataclass(frozen=True)
class Barrier:
    pass_name: str
    resource: str
    src: State
    dst: State
    aliased: tuple[str, ...] = ()  # resources whose memory this one takes over
    # a barrier between steps of a pass: the step it comes before and the part it covers
    step: int | None = None
    mips: tuple[int, int] | None = None  # (first, count); None: every mip
    bytes: tuple[int, int] | None = None  # (offset, size); None: the whole buffer

    def to_json(self) -> dict[str, Any]:
        src = self.src.to_json()
        if self.aliased:
            src["aliased"] = list(self.aliased)
        out = {"pass": self.pass_name, "resource": self.resource, "from": src,
               "to": self.dst.to_json()}
        if self.step is not None:
            out["step"] = self.step
            out.update({k: list(v) for k, v in (("mips", self.mips), ("bytes", self.bytes))
                        if v is not None})
        return out

    def part(self) -> str:
        """The sub-resource it covers, for people: ``mips 2..3``, ``bytes 0..255`` or ``all``."""
        if self.mips is not None:
            first, count = self.mips
            return f"mip {first}" if count == 1 else f"mips {first}..{first + count - 1}"
        if self.bytes is not None:
            offset, size = self.bytes
            return f"bytes {offset}..{offset + size - 1}"
        return "all"


@dataclass(frozen=True)
class StepAccess:
    """One step of a pass touching a span of one resource: ``[lo, hi)`` of its mips (images)
    or bytes (buffers)."""

    step: int
    resource: str
    lo: int
    hi: int
    state: State


@dataclass(frozen=True)
class CompiledGraph:
    name: str
    size: tuple[int, int]
    order: tuple[str, ...]
    culled: tuple[str, ...]
    disabled: tuple[str, ...]
    resources: tuple[ResourcePlan, ...]
    heaps: tuple[int, ...]
    transient_bytes: int
    unaliased_bytes: int
    lower_bound_bytes: int
    raptor_reuse_bytes: int
    barriers: tuple[Barrier, ...]
    parallel_levels: tuple[tuple[str, ...], ...]
    diagnostics: tuple[Diagnostic, ...]
    accesses: dict[str, tuple[Access, ...]] = field(compare=False)  # per scheduled pass
    edges: tuple[tuple[str, str, str], ...] = ()  # (from, to, "data" | "order")
    outputs: tuple[str, ...] = ()
    # where the output size came from: "graph" (its own) or "given" (the caller's)
    size_from: str = field(default="graph", compare=False)
    # images sized from the output size (directly or through others); 0: all fixed
    follow_output: int = field(default=0, compare=False)
    step_barriers: tuple[Barrier, ...] = ()  # inside passes, before the step they name
    steps: dict[str, tuple[str, ...]] = field(default_factory=dict, compare=False)  # names
    # queues, submissions, semaphores and ownership transfers (rfw.graph.queues); None: one
    # graphics queue, one submission
    queues: Any = None
    # (pass, slot, resource, its culled producer) of kept inputs the cull left unproduced
    unproduced: tuple[tuple[str, str, str, str], ...] = ()
    # scheduled bridge passes (PassDecl.bridge: copies between backends, or a backend's
    # half of one), in order: what executors copy through the host instead of recording
    bridges: tuple[str, ...] = ()
    # what compiling found before it placed memory: rfw.graph.compile.place starts there
    front: Any = field(default=None, compare=False, repr=False)

    def barriers_before_step(self, pass_name: str, index: int,
                             previous: int) -> tuple[Barrier, ...]:
        """The barriers before step ``index`` of a pass that is in step ``previous`` (-1:
        none yet). Steps are entered in order, none skipped: a skipped step's barriers
        would be missing."""
        names = self.steps.get(pass_name, ())
        if not names:
            raise GraphError(f"pass '{pass_name}' enters step {index} but declares no steps "
                             "(Pass.steps)")
        if not (isinstance(index, int) and 0 <= index < len(names)):
            raise GraphError(f"pass '{pass_name}' enters step {index!r}, but declares "
                             f"{len(names)} steps (0..{len(names) - 1})")
        if index != previous + 1:
            raise GraphError(f"pass '{pass_name}' enters step {index} after step {previous}: "
                             f"steps are entered in order (step {previous + 1} next)")
        return tuple(b for b in self.step_barriers
                     if b.pass_name == pass_name and b.step == index)

    def resource(self, name: str) -> ResourcePlan:
        for r in self.resources:
            if r.name == name:
                return r
        raise KeyError(name)

    def to_json(self) -> dict[str, Any]:
        return {
            "order": list(self.order),
            "culled": list(self.culled),
            "disabled": list(self.disabled),
            "resources": [r.to_json() for r in self.resources],
            "heaps": [{"index": i, "bytes": b} for i, b in enumerate(self.heaps)],
            "transient_bytes": self.transient_bytes,
            "unaliased_bytes": self.unaliased_bytes,
            "lower_bound_bytes": self.lower_bound_bytes,
            "raptor_reuse_bytes": self.raptor_reuse_bytes,
            "barriers": [b.to_json() for b in self.barriers],
            "step_barriers": [b.to_json() for b in self.step_barriers],
            "parallel_levels": [list(level) for level in self.parallel_levels],
            "queues": None if self.queues is None else self.queues.to_json(),
            "diagnostics": [d.to_json() for d in self.diagnostics],
        }


# ---------------------------------------------------------------------------------------------
# the result of validation: everything later steps need, nothing they must re-derive


@dataclass
class Declared:
    passes: list[PassDecl]  # enabled, in declaration order
    disabled: list[str]
    resources: dict[str, ResourceDecl]
    accesses: dict[str, tuple[Access, ...]]
    edges: dict[tuple[int, int], str]  # (from, to) pass indices -> "data" | "order"
    outputs: tuple[str, ...]
    history: dict[str, str]  # history copy -> resource it follows
    diagnostics: list[Diagnostic]
    history_of: dict[str, str] = field(default_factory=dict)  # resource -> its history copy
    # per pass with steps: each step's accesses, in step order
    steps: dict[str, tuple[tuple[StepAccess, ...], ...]] = field(default_factory=dict)


class _Problems:
    """Collects errors (raised together) and warnings (kept as diagnostics)."""

    def __init__(self, graph: Graph, strict: bool):
        self.graph, self.strict = graph, strict
        self.errors: list[str] = []
        self.diagnostics = [Diagnostic(level, msg) for level, msg in graph.diagnostics]

    def error(self, message: str) -> None:
        self.errors.append(message)

    def lenient(self, message: str) -> None:
        # an error in strict mode, a warning in lenient mode
        if self.strict:
            self.errors.append(message)
        else:
            self.diagnostics.append(Diagnostic("warning", message))

    def info(self, message: str) -> None:
        self.diagnostics.append(Diagnostic("info", message))

    def raise_if_any(self) -> None:
        if self.errors:
            raise GraphError(self.errors[0], file=self.graph.source, more=self.errors[1:])
