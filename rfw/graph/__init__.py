"""The frame graph: declare passes and resources, compile to order, memory and barriers."""

from .compile import CompiledGraph, Diagnostic, MemoryOptions, compile
from .errors import GraphError
from .graph import Graph, GraphBuilder, PassDecl
from .loaders import load_graph, load_raptor, load_toml, loads_raptor, loads_toml, to_toml
from .resources import (
    AccelStructure,
    Attachment,
    Buffer,
    DepthAttachment,
    History,
    Part,
    Reference,
    ShadingRate,
    SizeRule,
    Slot,
    Step,
    Storage,
    Texture,
)

__all__ = [
    "AccelStructure", "Attachment", "Buffer", "CompiledGraph", "DepthAttachment", "Diagnostic", "Graph",
    "GraphBuilder", "GraphError", "History", "MemoryOptions", "Part", "PassDecl", "Reference",
    "ShadingRate", "SizeRule", "Slot", "Step", "Storage", "Texture", "compile", "load_graph",
    "load_raptor", "load_toml", "loads_raptor", "loads_toml", "to_toml",
]
