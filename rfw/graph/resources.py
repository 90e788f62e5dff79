"""Slot and resource declarations: what a pass says about the data it touches.

A slot is typed (how the pass touches the resource) and, for outputs, describes the
resource it creates: format, size rule, mips, layers, samples. The compiler derives
allocation, usage flags, culling, lifetimes and barriers from these declarations alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

# slot types; "texture" is a sampled read as an input and a storage write as an output
SLOT_TYPES = (
    "texture",  # sampled image read / storage image write
    "storage",  # storage image read-modify-write in place
    "attachment",  # color attachment (or storage image in compute passes)
    "depth",  # depth(-stencil) attachment
    "buffer",  # storage/uniform/indirect/vertex/index buffer
    "reference",  # ordering only as an input; in-place write as an output
    "history",  # the previous frame's value of a resource
    "shading_rate",  # fragment shading rate attachment
    "accel",  # acceleration structure: built (output) or traced against (input)
)

PASS_TYPES = ("graphics", "mesh", "compute", "ray_tracing", "transfer")

LOAD_OPS = ("clear", "load", "dont_care")

BUFFER_USAGES = frozenset({"storage", "uniform", "indirect", "vertex", "index", "transfer_src",
                           "transfer_dst"})
IMAGE_USAGES = frozenset({"sampled", "storage", "color", "depth", "depth_read", "shading_rate",
                          "transfer_src", "transfer_dst"})


@dataclass(frozen=True)
class SizeRule:
    """How big an image is.

    ``mode`` is ``"fixed"`` (``width`` x ``height`` texels), ``"output"`` (``scale`` times the
    output size given to ``compile``) or ``"relative"`` (``scale`` times the size of resource
    ``of``).
    """

    mode: str = "output"
    width: int = 0
    height: int = 0
    scale: tuple[float, float] = (1.0, 1.0)
    of: str | None = None

    @staticmethod
    def fixed(width: int, height: int) -> SizeRule:
        return SizeRule("fixed", int(width), int(height))

    @staticmethod
    def output(sx: float = 1.0, sy: float | None = None) -> SizeRule:
        return SizeRule("output", scale=(float(sx), float(sx if sy is None else sy)))

    @staticmethod
    def like(resource: str, sx: float = 1.0, sy: float | None = None) -> SizeRule:
        return SizeRule("relative", scale=(float(sx), float(sx if sy is None else sy)),
                        of=resource)

    def describe(self) -> str:
        if self.mode == "fixed":
            return f"{self.width}x{self.height}"
        scale = "" if self.scale == (1.0, 1.0) else f" scale {self.scale[0]:g},{self.scale[1]:g}"
        return ("output" if self.mode == "output" else f"like {self.of}") + scale


@dataclass(frozen=True)
class Slot:
    """A typed slot of a pass. Outputs also describe the resource they create."""

    type: str
    format: str | None = None
    size: SizeRule | None = None
    mips: int = 1
    layers: int = 1
    samples: int = 1
    bytes: int | None = None  # buffers only
    usage: frozenset[str] = frozenset()  # extra usages beyond what the type implies
    load: str | None = None  # attachments: clear | load | dont_care
    clear: tuple[float, ...] | None = None  # clear color, or (depth, stencil)
    external: bool = False  # owned by the user: never aliased, survives the frame
    read_only: bool = False  # depth test without depth writes
    stages: frozenset[str] = frozenset()  # override the shader stages the pass reads in
    optional: bool = False  # an input the pass can do without (configs drop it when unfed)
    format_of: str | None = None  # outputs: take the format of this slot's resource
    desc: str = ""

    def with_(self, **changes: Any) -> Slot:
        return replace(self, **changes)


def _slot(type_: str, format: str | None, kw: dict[str, Any]) -> Slot:
    if "usage" in kw:
        kw["usage"] = frozenset((kw["usage"],) if isinstance(kw["usage"], str) else kw["usage"])
    if "stages" in kw:
        kw["stages"] = frozenset(kw["stages"])
    if kw.get("clear") is not None:
        kw["clear"] = tuple(float(c) for c in kw["clear"])
    return Slot(type_, format, **kw)


def Texture(format: str | None = None, **kw: Any) -> Slot:
    """Sampled image as an input; storage image written by the pass as an output."""
    return _slot("texture", format, kw)


def Storage(format: str | None = None, **kw: Any) -> Slot:
    """Storage image read and written in place."""
    return _slot("storage", format, kw)


def Attachment(format: str | None = None, **kw: Any) -> Slot:
    """Color attachment; as an input it is loaded and written (blending, in-place).
    ``format_of="src"`` instead of a format: the format of slot ``src``'s resource."""
    return _slot("attachment", format, kw)


def DepthAttachment(format: str | None = "depth32float", **kw: Any) -> Slot:
    """Depth(-stencil) attachment; as an input it is loaded (read_only=True: test only)."""
    return _slot("depth", format, kw)


def Buffer(bytes: int | None = None, **kw: Any) -> Slot:
    """Buffer; usage picks how it is read (storage, uniform, indirect, vertex, index)."""
    kw.setdefault("usage", ("storage",))
    return _slot("buffer", None, {"bytes": bytes, **kw})


def Reference(**kw: Any) -> Slot:
    """Input: order after the resource's writers without touching it.
    Output: write the (existing) resource in place."""
    return _slot("reference", None, kw)


def History(**kw: Any) -> Slot:
    """The resource's value from the previous frame (sampled); empty on the first frame."""
    return _slot("history", None, kw)


def ShadingRate(**kw: Any) -> Slot:
    """Fragment shading rate image."""
    return _slot("shading_rate", None, kw)


def AccelStructure(**kw: Any) -> Slot:
    """An acceleration structure (a TLAS). Output: built or refit by the pass (the build
    stage writes it). Input: traced against by ray queries or ray-tracing pipelines. Its
    memory belongs to whoever builds it, never to the plan's heaps."""
    return _slot("accel", None, kw)


@dataclass(frozen=True)
class Binding:
    """A slot of a pass bound to a named resource (the graph edge)."""

    slot: str
    direction: str  # "in" | "out"
    spec: Slot
    resource: str


@dataclass(frozen=True)
class ResourceDecl:
    """A resource as the graph knows it before compiling (from its producer or an import)."""

    name: str
    kind: str  # "image" | "buffer" | "accel"
    format: str | None
    size: SizeRule | None
    mips: int = 1
    layers: int = 1
    samples: int = 1
    bytes: int | None = None
    external: bool = False
    producer: str | None = None  # pass name; None for imports
    slot: str | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)


@dataclass(frozen=True)
class Part:
    """What a step touches of a slot's resource: mips ``(first, count)`` of an image or bytes
    ``(offset, size)`` of a buffer; neither: all of it."""

    slot: str
    mips: tuple[int, int] | None = None
    bytes: tuple[int, int] | None = None


def _parts(parts: Any) -> tuple[Part, ...]:
    # a bare slot name means the whole resource
    if isinstance(parts, str | Part):
        parts = (parts,)
    return tuple(Part(p) if isinstance(p, str) else p for p in parts)


@dataclass(frozen=True)
class Step:
    """An ordered step inside a pass (one dispatch of a mip chain, say) and the parts of its
    slots' resources it reads and writes. The compiler plans the barriers between steps as
    it plans those between passes; the pass enters step ``i`` with ``ctx.step(i)``."""

    name: str
    reads: tuple[Part, ...] = ()
    writes: tuple[Part, ...] = ()

    def __post_init__(self) -> None:
        # lists and bare slot names are accepted: the graph is hashed, so store tuples
        object.__setattr__(self, "reads", _parts(self.reads))
        object.__setattr__(self, "writes", _parts(self.writes))
