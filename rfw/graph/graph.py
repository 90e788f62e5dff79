"""The declared graph (immutable) and the Python builder that makes one.

TOML and Raptor JSON loaders produce the same ``Graph``; ``compile`` only ever sees this.
"""

from __future__ import annotations

import functools
import gc
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

from ..errors import check_identifier, is_identifier
from .errors import GraphError
from .resources import PASS_TYPES, Binding, Slot, Step, Texture


def gc_paused(fn: Callable) -> Callable:
    """``fn`` with the cycle collector paused: loading and compiling build many small acyclic
    objects, and a collection sweeping the whole heap would dominate their time."""
    @functools.wraps(fn)
    def paused(*args: Any, **kwargs: Any) -> Any:
        was = gc.isenabled()
        gc.disable()
        try:
            return fn(*args, **kwargs)
        finally:
            if was:
                gc.enable()
    return paused


def _freeze(value: Any) -> Any:
    # settings must be hashable so that compile can be memoised on the graph
    if isinstance(value, Mapping):
        return tuple(sorted((k, _freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


@dataclass(frozen=True)
class Bridge:
    """What a bridge pass (``rfw.graph.bridges``) copies: ``resource``, made on backend
    ``src``, into ``copy`` (``<resource>@<dst>``), which backend ``dst``'s passes read."""

    name: str  # the bridge pass: bridge.<resource>.<src>-<dst>
    src: str
    dst: str
    resource: str
    copy: str

    @property
    def route(self) -> str:
        """``src>dst``, as timings.json names a bridge's backend."""
        return f"{self.src}>{self.dst}"


@dataclass(frozen=True, eq=True)
class PassDecl:
    """One pass as declared: its type, its bound slots and its settings."""

    name: str
    type: str = "graphics"
    inputs: tuple[Binding, ...] = ()
    outputs: tuple[Binding, ...] = ()
    enabled: bool = True
    side_effect: bool = False  # never culled (readbacks, UI)
    backend: str | None = None  # "wgpu" or "vk" to pin the pass; None runs on the run's backend
    requires: tuple[str, ...] = ()  # device capabilities, e.g. "VK_EXT_mesh_shader"
    settings: tuple[tuple[str, Any], ...] = ()
    schema: tuple[str, ...] | None = None  # known setting names, when the pass class says
    steps: tuple[Step, ...] = ()  # ordered steps inside the pass, barriers planned between
    bridge: Bridge | None = None  # a copy between backends (rfw.graph.bridges), not a pass
    origin: str | None = field(default=None, compare=False)  # "file:line" for messages

    @cached_property
    def _hash(self) -> int:
        return hash((self.name, self.type, self.inputs, self.outputs, self.enabled,
                     self.side_effect, self.requires, self.settings, self.schema, self.backend,
                     self.steps, self.bridge))

    def __hash__(self) -> int:
        return self._hash

    @property
    def bindings(self) -> tuple[Binding, ...]:
        return self.inputs + self.outputs

    def where(self) -> str:
        return f"pass '{self.name}'" + (f" ({self.origin})" if self.origin else "")


@dataclass(frozen=True, eq=True)
class Graph:
    """A declared frame graph. Immutable: switching techniques makes a new one cheaply."""

    name: str
    passes: tuple[PassDecl, ...]
    imports: tuple[tuple[str, Slot], ...] = ()  # user-owned resources no pass produces
    outputs: tuple[str, ...] | None = None  # None: externals plus never-read resources
    size: tuple[int, int] | None = None  # default output size
    strict: bool = True
    source: str | None = field(default=None, compare=False)
    diagnostics: tuple[tuple[str, str], ...] = field(default=(), compare=False)  # from loading
    async_compute: str = "auto"  # "auto" | "on" | "off": compute beside raster (graph.queues)

    @cached_property
    def _hash(self) -> int:
        return hash((self.name, self.passes, self.imports, self.outputs, self.size, self.strict,
                     self.async_compute))

    def __hash__(self) -> int:
        return self._hash

    def pass_(self, name: str) -> PassDecl:
        for p in self.passes:
            if p.name == name:
                return p
        raise GraphError(f"no pass named '{name}'", file=self.source,
                         suggest=(name, [p.name for p in self.passes]))

    def with_enabled(self, name: str, enabled: bool = True) -> Graph:
        """The same graph with one pass switched on or off."""
        return self.with_pass(replace(self.pass_(name), enabled=enabled))

    def with_pass(self, decl: PassDecl) -> Graph:
        """The same graph with the pass of that name replaced (a technique variant)."""
        self.pass_(decl.name)
        passes = tuple(decl if p.name == decl.name else p for p in self.passes)
        return replace(self, passes=passes)

    def with_outputs(self, outputs: Iterable[str] | None) -> Graph:
        return replace(self, outputs=None if outputs is None else tuple(outputs))


class PassBuilder:
    """Collects the slots of one pass; returned by ``GraphBuilder.add_pass``."""

    def __init__(self, graph: GraphBuilder, name: str, type: str, **options: Any):
        self._graph = graph
        self.name = name
        self.type = type
        self.options = options
        self.inputs: list[Binding] = []
        self.outputs: list[Binding] = []

    def _name(self, kind: str, name: Any, slot: str | None = None) -> str:
        # slot and resource names become labels and file names: identifiers only
        if is_identifier(name):
            return name  # checked before any message is made: big graphs have many names
        where = f"pass '{self.name}'" + (f", slot '{slot}'" if slot is not None else "")
        return check_identifier(kind, name, file=self._graph.source, element=where)

    def input(self, slot: str, source: str, spec: Slot | None = None) -> PassBuilder:
        """Read ``source`` (a resource name, ``"pass.slot"`` by default) through ``slot``."""
        self._name("slot", slot)
        self._name("resource", source, slot)
        self.inputs.append(Binding(slot, "in", spec or Texture(), source))
        return self

    def output(self, slot: str, spec: Slot, *, name: str | None = None,
               target: str | None = None) -> PassBuilder:
        """Create a resource (named ``"<pass>.<slot>"`` unless ``name`` is given), or, for a
        reference slot, write ``target`` in place."""
        self._name("slot", slot)
        if spec.type == "reference":
            if target is None:
                raise GraphError(f"pass '{self.name}', slot '{slot}': a reference output needs "
                                 "target= (the resource written in place)")
            resource = target
        else:
            resource = name or f"{self.name}.{slot}"
        self._name("resource", resource, slot)
        self.outputs.append(Binding(slot, "out", spec, resource))
        return self

    def build(self) -> PassDecl:
        opts = dict(self.options)
        settings = _freeze(opts.pop("settings", {}) or {})
        schema = opts.pop("schema", None)
        return PassDecl(self.name, self.type, tuple(self.inputs), tuple(self.outputs),
                        settings=settings, schema=None if schema is None else tuple(schema),
                        requires=tuple(opts.pop("requires", ())),
                        steps=tuple(opts.pop("steps", ())), **opts)


class GraphBuilder:
    """Declare a graph in Python.

    >>> g = GraphBuilder("demo", size=(256, 256))
    >>> g.add_pass("draw").output("color", Attachment("rgba8unorm"))  # doctest: +SKIP
    >>> g.output("draw.color")                                         # doctest: +SKIP
    >>> graph = g.build()                                              # doctest: +SKIP
    """

    def __init__(self, name: str = "graph", *, size: tuple[int, int] | None = None,
                 strict: bool = True, source: str | None = None):
        self.name = name
        self.size = size
        self.strict = strict
        self.source = source
        self._passes: list[PassBuilder] = []
        self._names: set[str] = set()  # a scan per pass made big graphs quadratic
        self._imports: list[tuple[str, Slot]] = []
        self._outputs: list[str] | None = None

    def add_pass(self, name: str, type: str = "graphics", *, enabled: bool = True,
                 side_effect: bool = False, requires: Iterable[str] = (),
                 settings: Mapping[str, Any] | None = None,
                 schema: Iterable[str] | None = None, origin: str | None = None,
                 backend: str | None = None, steps: Iterable[Step] = ()) -> PassBuilder:
        check_identifier("pass", name, file=self.source)
        if type not in PASS_TYPES:
            raise GraphError(f"pass '{name}': unknown pass type '{type}'", file=self.source,
                             suggest=(type, PASS_TYPES))
        if name in self._names:
            raise GraphError(f"pass '{name}' is declared twice", file=self.source)
        p = PassBuilder(self, name, type, enabled=enabled, side_effect=side_effect,
                        requires=tuple(requires), settings=settings or {}, schema=schema,
                        origin=origin, backend=backend, steps=tuple(steps))
        self._passes.append(p)
        self._names.add(name)
        return p

    def external(self, name: str, spec: Slot) -> GraphBuilder:
        """Import a user-owned resource (never aliased) that passes read or write."""
        check_identifier("external resource", name, file=self.source)
        self._imports.append((name, spec.with_(external=True)))
        return self

    def output(self, *names: str) -> GraphBuilder:
        """Mark graph outputs: culling keeps exactly the passes these depend on."""
        for name in names:
            check_identifier("output", name, file=self.source, element="outputs")
        self._outputs = [*(self._outputs or []), *names]
        return self

    def build(self) -> Graph:
        return Graph(self.name, tuple(p.build() for p in self._passes), tuple(self._imports),
                     None if self._outputs is None else tuple(self._outputs), self.size,
                     self.strict, self.source)
