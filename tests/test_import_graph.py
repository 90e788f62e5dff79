"""The import graph of rfw/, vkext/ and passes/ has no circle (issue 12, item 3).

Every module is parsed with ``ast``: imports at module level and inside functions both count
(a circle through a function-level import is still a circle, only a hidden one), relative
imports are resolved against the importing module, and ``from pkg import name`` is an edge to
``pkg.name`` where that is a module, else to ``pkg``. Parent packages a dotted import runs
first are not edges (a package's ``__init__`` importing its own submodules, which import
their siblings, is the normal shape, not a circle).

Still to remove (issue 12, item 3: ``rfw`` never imports ``vkext``, once backends are
plug-ins), the rfw -> vkext edges today:
    rfw.render       -> vkext.backend (render_vk), vkext.device (VkDevice),
                        vkext.mixed (render_mixed)
    rfw.raycasting   -> vkext.device (VkDevice), vkext.accel (SceneAccel),
                        vkext.raycast (raycaster and its dtypes)
    rfw.bench.worker -> vkext.mixed (MixedFrame)
"""

from __future__ import annotations

import ast
from itertools import pairwise
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rfw", "vkext", "passes")


def module_files(root: Path, packages: tuple[str, ...]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` under ``packages``."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _known(name: str, modules: dict[str, Path]) -> str | None:
    # the deepest module of ours that ``name`` starts with (attributes drop off the end)
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _targets(node: ast.AST, module: str, is_package: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    assert isinstance(node, ast.ImportFrom)
    base = node.module or ""
    if node.level:  # relative: up from the importing module's package
        package = module.split(".") if is_package else module.split(".")[:-1]
        package = package[:len(package) - (node.level - 1)]
        base = ".".join(package + ([node.module] if node.module else []))
    return [f"{base}.{a.name}" for a in node.names]


def import_graph(root: Path, packages: tuple[str, ...]) -> dict[str, dict[str, int]]:
    """module -> {imported module of ours: first line}, every import anywhere in the file."""
    modules = module_files(root, packages)
    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        edges: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(node, name, path.name == "__init__.py"):
                    found = _known(target, modules)
                    if found and found != name:
                        edges.setdefault(found, node.lineno)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, dict[str, int]]) -> list[str] | None:
    """One circle as ``[a, b, ..., a]``, or None: a depth-first search for a back edge."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, {})):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def describe(cycle: list[str], graph: dict[str, dict[str, int]]) -> str:
    return "\n".join(f"  {a} -> {b} (line {graph[a][b]})" for a, b in pairwise(cycle))


def test_no_import_cycle() -> None:
    graph = import_graph(ROOT, PACKAGES)
    assert len(graph) > 50 and "vkext.executor" in graph["vkext.backend"]  # it parsed them
    cycle = find_cycle(graph)
    assert cycle is None, "import circle:\n" + describe(cycle, graph)


def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


def test_a_cycle_through_a_function_level_relative_import_is_found(tmp_path: Path) -> None:
    # fake.x -> fake.y at module level, fake.y -> fake.sub.z inside a function,
    # fake.sub.z -> fake.x two levels up: one circle
    files = {
        "fake/__init__.py": "",
        "fake/x.py": "from .y import helper\n",
        "fake/y.py": "def helper():\n    from .sub import z\n    return z\n",
        "fake/sub/__init__.py": "",
        "fake/sub/z.py": "from ..x import helper\n",
    }
    _write(tmp_path, files)
    graph = import_graph(tmp_path, ("fake",))
    cycle = find_cycle(graph)
    assert cycle is not None and cycle[0] == cycle[-1]
    assert set(cycle) == {"fake.x", "fake.y", "fake.sub.z"}
    assert "fake.y -> fake.sub.z (line 2)" in describe(cycle, graph)

    # the same package without the function-level import has no circle
    _write(tmp_path, {"fake/y.py": "def helper():\n    return 1\n"})
    assert find_cycle(import_graph(tmp_path, ("fake",))) is None


def test_absolute_imports_and_attributes_resolve_to_modules(tmp_path: Path) -> None:
    _write(tmp_path, {
        "fake/__init__.py": "",
        "fake/a.py": "import fake.b\nfrom fake.b import VALUE\n",
        "fake/b.py": "VALUE = 1\nimport os\n",
    })
    graph = import_graph(tmp_path, ("fake",))
    assert graph["fake.a"] == {"fake.b": 1}
    assert graph["fake.b"] == {}  # os is not ours
    _write(tmp_path, {"fake/b.py": "VALUE = 1\nfrom fake import a\n"})
    assert find_cycle(import_graph(tmp_path, ("fake",))) == ["fake.a", "fake.b", "fake.a"]
