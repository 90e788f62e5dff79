"""What ``Pass.record(ctx)`` may call: the one pass-context protocol every backend implements.

A pass reaches its resources by slot name and records work through these methods only; it
never touches a backend's executor, device or private objects, so the same ``record`` runs
on every backend (``rfw.backends.wgpu.PassContext``, ``vkext.context.VkPassContext``
and any plug-in's). What a method returns (a texture view, an image binding, a sampler) is
backend-specific: a pass hands it on to ``dispatch`` or ``draw_scene`` unopened.

Features only some devices have extend it: :class:`RayTracingContext` (a pass that declares
``requires = ("VK_KHR_ray_tracing_pipeline",)``). :func:`signature_problems` says where a
context class falls short of a protocol (tests/core/test_context.py checks the built-in
backends with it).
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from .shaders import ShaderError

# what ctx.sampler offers, in WebGPU's names (every backend maps them)
FILTERS = ("linear", "nearest")
ADDRESSES = ("clamp-to-edge", "repeat", "mirror-repeat")
COMPARES = ("never", "less", "equal", "less-equal", "greater", "not-equal", "greater-equal",
            "always")
# what draw_scene draws: the scene's triangles, or its strokes (points, line segments)
TOPOLOGIES = ("triangle-list", "line-list", "point-list")


@runtime_checkable
class PassContext(Protocol):
    """The pass-facing context: slots, their resources, and ways to record work."""

    pass_: Any  # the recording pass
    scene: Any  # the uploaded scene (rfw.authoring.SceneView), or None without one
    frame: int  # frames recorded before this one

    # slots and resources -------------------------------------------------------------------
    def resource(self, slot: str) -> str:
        """The graph resource bound to ``slot`` (an error naming the pass's slots if none)."""

    def has(self, slot: str) -> bool:
        """Whether the slot is connected (optional inputs may not be)."""

    def extent(self, slot: str) -> tuple[int, int]:
        """Width and height of an image slot."""

    def format(self, slot: str) -> str:
        """The slot's format, by its WebGPU name where it has one."""

    def mips(self, slot: str) -> int:
        """Mip levels of an image slot."""

    def texture(self, slot: str) -> Any:
        """The slot's image, to bind whole."""

    def view(self, slot: str, *, mip: int | None = None) -> Any:
        """The slot's image view; ``mip``: of that one level only."""

    def sampled(self, slot: str) -> Any:
        """The slot's image as a sampled binding (depth images: their depth aspect)."""

    def storage(self, slot: str, *, mip: int | None = None) -> Any:
        """The slot's image as a storage binding; ``mip``: of that one level only."""

    def buffer(self, slot: str) -> Any:
        """The buffer behind a buffer slot."""

    def sampler(self, *, filter: str = "linear", address: str = "clamp-to-edge",
                compare: str | None = None) -> Any:
        """A sampler the backend makes once (``filter``: linear | nearest; ``address``:
        clamp-to-edge | repeat | mirror-repeat; ``compare``: a depth comparison)."""

    # recording -----------------------------------------------------------------------------
    def step(self, index: int) -> None:
        """Enter step ``index`` of the pass's declared steps (``Pass.steps``): the graph's
        barriers between steps (a mip written, then read) are recorded here."""

    def program(self, kind: str, *, shader: str | None = None,
                defines: dict[str, object] | None = None) -> Any:
        """The pass's compiled ``shader`` (default: its own) of ``kind`` (compute | render)."""

    def dispatch(self, *, threads: tuple[int, ...], shader: str | None = None,
                 entry: str = "main", defines: dict[str, object] | None = None,
                 **bindings: Any) -> None:
        """Run a compute shader over ``threads`` (rounded up to whole workgroups); bindings
        are matched by name against the shader."""

    def draw_scene(self, *, color: Sequence[tuple[str, Any]] = (),
                   depth: tuple[str, Any] | None = None, shader: str | None = None,
                   defines: dict[str, object] | None = None, depth_compare: str = "less",
                   depth_write: bool = True, cull: str = "back", camera: str = "main",
                   blend: dict | None = None, alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
                   topology: str = "triangle-list", **bindings: Any) -> int:
        """Draw the scene's instances into ``color`` [(slot, clear or None)] and ``depth``
        (slot, clear or None); returns the draws. ``topology`` line-list or point-list
        draws the scene's strokes (``Scene.strokes``) with those primitives; where the
        scene has none and nothing is cleared, nothing is recorded."""

    def render_pass(self, *, color: Sequence[tuple[str, Any]] = (),
                    depth: tuple[str, Any] | None = None,
                    depth_read_only: bool = False) -> Any:
        """Begin rendering into ``color`` and ``depth``; the returned pass is ended with
        ``end()``."""


@runtime_checkable
class RayTracingContext(PassContext, Protocol):
    """A context on a device with ray-tracing pipelines and acceleration structures."""

    def accel(self, slot: str) -> Any:
        """The acceleration structures behind an ``AccelStructure`` slot."""

    def set_accel(self, slot: str, accel: Any) -> None:
        """Publish the structures this pass builds for its ``AccelStructure`` output."""

    def build_accel(self, slot: str, accel: Any, *, update: bool = False) -> None:
        """Record the top-level build (``update``: a refit) of ``accel`` and publish it for
        the ``AccelStructure`` output ``slot``."""

    def trace_rays(self, *, size: tuple[int, ...], shader: str | None = None,
                   miss: str | None = None, closest_hit: str | None = None,
                   any_hit: str | None = None, defines: dict[str, object] | None = None,
                   max_recursion: int = 1, **bindings: Any) -> None:
        """Launch ``size`` rays from the raygen ``shader`` (default: the pass's)."""


def check_topology(pass_name: str, topology: Any) -> None:
    """A ShaderError naming the pass for a ``draw_scene`` topology rfw has no draw of."""
    if topology not in TOPOLOGIES:
        raise ShaderError(f"pass '{pass_name}': draw_scene topology must be one of "
                          f"{', '.join(TOPOLOGIES)}, not {topology!r}")


def nothing_to_draw(scene: Any, topology: str, color: Sequence[tuple[str, Any]],
                    depth: tuple[str, Any] | None) -> bool:
    """Whether a stroke draw may be left out whole: the uploaded scene (GpuScene, VkScene:
    its ``.scene``) has nothing of ``topology`` and no target is cleared, so it costs the
    pass no render pass at all."""
    if topology == "triangle-list" or any(clear is not None for _, clear in color):
        return False
    if depth is not None and depth[1] is not None:
        return False
    return scene.scene.draw_count(topology) == 0


def check_sampler(filter: str, address: str, compare: str | None) -> None:
    """A ShaderError unless ``ctx.sampler``'s arguments are among the offered ones."""
    for what, value, allowed in (("filter", filter, FILTERS), ("address", address, ADDRESSES),
                                 ("compare", compare, (None, *COMPARES))):
        if value not in allowed:
            raise ShaderError(f"sampler {what} {value!r} is none of "
                              f"{', '.join(str(a) for a in allowed)}")


def members(protocol: type) -> dict[str, Any]:
    """The protocol's methods and attributes by name (its bases' included)."""
    out: dict[str, Any] = {}
    for klass in reversed(protocol.__mro__):
        if klass is object or klass is Protocol or not getattr(klass, "_is_protocol", False):
            continue
        out.update({n: None for n in getattr(klass, "__annotations__", {})})
        out.update({n: v for n, v in vars(klass).items()
                    if callable(v) and not n.startswith("_")})
    return out


def signature_problems(cls: type, protocol: type = PassContext) -> list[str]:
    """Where ``cls`` falls short of ``protocol``: a missing method, or one a call the
    protocol allows would fail on or treat differently (a parameter missing, of another
    kind or default, or a required one the protocol lacks). Attributes the protocol names
    are set per instance and not checked here."""
    problems = []
    for name, want in members(protocol).items():
        if want is None:
            continue
        have = getattr(cls, name, None)
        if not callable(have):
            problems.append(f"{cls.__name__} has no {name}()")
            continue
        problems += [f"{cls.__name__}.{name}: {p}"
                     for p in _compatible(inspect.signature(want), inspect.signature(have))]
    return problems


def _compatible(want: inspect.Signature, have: inspect.Signature) -> list[str]:
    """Why a call that ``want`` accepts could fail on, or mean something else to, ``have``."""
    out = []
    params = dict(have.parameters)
    varkw = any(p.kind is p.VAR_KEYWORD for p in params.values())
    for name, w in want.parameters.items():
        if w.kind is w.VAR_KEYWORD:
            if not varkw:
                out.append(f"takes no **{name}")
            continue
        h = params.pop(name, None)
        if h is None:
            if not (varkw and w.kind is w.KEYWORD_ONLY):
                out.append(f"has no parameter '{name}'")
            continue
        if h.kind is not w.kind:
            out.append(f"'{name}' is {h.kind.description}, not {w.kind.description}")
        elif w.default is not w.empty and h.default != w.default:
            out.append(f"'{name}' defaults to {h.default!r}, not {w.default!r}")
    extra = [n for n, p in params.items() if p.default is p.empty
             and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if extra:
        out.append(f"requires {', '.join(extra)}, which the protocol does not pass")
    return out
