"""The import graph of rfw/, vkext/ and passes/: no circle, and rfw never imports vkext
(issue 12, item 3: backends are plug-ins that rfw finds through the ``rfw.backends``
entry points, so the core stays importable, and testable, without Vulkan).

Every module is parsed with ``ast``: imports at module level and inside functions both count
(a circle through a function-level import is still a circle, only a hidden one), relative
imports are resolved against the importing module, and ``from pkg import name`` is an edge to
``pkg.name`` where that is a module, else to ``pkg``. Parent packages a dotted import runs
first are not edges (a package's ``__init__`` importing its own submodules, which import
their siblings, is the normal shape, not a circle). ``importlib.import_module("...")`` and
``__import__("...")`` with a literal name count as imports too.

``python tests/test_import_graph.py`` prints the package-level graph (the closing note of
issue 12 quotes it).
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


def _dynamic(node: ast.AST) -> list[str]:
    # import_module("pkg.mod") / __import__("pkg.mod") with a literal name
    if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)):
        return []
    f = node.func
    called = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
    return [node.args[0].value] if called in ("import_module", "__import__") else []


def import_graph(root: Path, packages: tuple[str, ...]) -> dict[str, dict[str, int]]:
    """module -> {imported module of ours: first line}, every import anywhere in the file."""
    modules = module_files(root, packages)
    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        edges: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                targets = _targets(node, name, path.name == "__init__.py")
            else:
                targets = _dynamic(node)
            for target in targets:
                found = _known(target, modules)
                if found and found != name:
                    edges.setdefault(found, node.lineno)
        graph[name] = edges
    return graph


def package_of(module: str, *, top: bool = False) -> str:
    """The package a module is drawn in: rfw's subpackages on their own (rfw.graph,
    rfw.backends, ...), rfw's top-level modules as ``rfw``, vkext whole, every pass folder
    as ``passes``; ``top``: rfw, vkext or passes."""
    parts = module.split(".")
    if parts[0] == "rfw" and len(parts) > 2 and not top:
        return ".".join(parts[:2])
    return parts[0]


def package_graph(graph: dict[str, dict[str, int]], *,
                  top: bool = False) -> dict[tuple[str, str], int]:
    """(package, package) -> how many module edges run between them (none within one)."""
    out: dict[tuple[str, str], int] = {}
    for a, edges in graph.items():
        for b in edges:
            key = (package_of(a, top=top), package_of(b, top=top))
            if key[0] != key[1]:
                out[key] = out.get(key, 0) + 1
    return dict(sorted(out.items()))


def show_packages(graph: dict[str, dict[str, int]]) -> str:
    """The top-level edges, then rfw's subpackages', with module edge counts."""
    lines = []
    for top, title in ((True, "packages"), (False, "with rfw's subpackages")):
        lines.append(f"  {title}:")
        lines += [f"    {a} -> {b} ({n} module edge{'s' * (n != 1)})"
                  for (a, b), n in package_graph(graph, top=top).items()]
    return "\n".join(lines)


def edges_into(graph: dict[str, dict[str, int]], src: str,
               dst: str) -> list[tuple[str, str, int]]:
    """(module, imported module, line) of every import from package ``src`` into ``dst``."""
    return [(a, b, line) for a, edges in sorted(graph.items()) for b, line in edges.items()
            if a.split(".")[0] == src and b.split(".")[0] == dst]


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
    assert cycle is None, ("import circle:\n" + describe(cycle, graph)
                           + "\npackage-level import graph:\n" + show_packages(graph))


def test_rfw_never_imports_vkext() -> None:
    graph = import_graph(ROOT, PACKAGES)
    assert "vkext.executor" in graph["vkext.backend"]  # vkext's own edges were parsed
    found = edges_into(graph, "rfw", "vkext")
    assert not found, ("rfw imports vkext (reach it through the rfw.backends entry points):\n"
                       + "\n".join(f"  {a} -> {b} (line {line})" for a, b, line in found)
                       + "\npackage-level import graph:\n" + show_packages(graph))
    assert ("vkext", "rfw") in package_graph(graph)  # the design's direction: it sees edges
    # nor the built-in passes: they register through the rfw.passes entry points
    assert not edges_into(graph, "rfw", "passes"), edges_into(graph, "rfw", "passes")


def test_imports_into_a_forbidden_package_are_found(tmp_path: Path) -> None:
    # the negative control: a core package reaching into its extension at module level,
    # inside a function (relative to nothing: absolute) and through import_module
    _write(tmp_path, {
        "core/__init__.py": "",
        "core/a.py": "import ext.x\n",
        "core/sub/__init__.py": "",
        "core/sub/b.py": "def f():\n    from ext import y\n    return y\n",
        "core/c.py": "import importlib\ndef g():\n    return importlib.import_module('ext.x')\n",
        "core/d.py": "from .a import ext\n",  # an attribute of core.a, not an edge into ext
        "ext/__init__.py": "",
        "ext/x.py": "from core import a\n",
        "ext/y.py": "",
    })
    graph = import_graph(tmp_path, ("core", "ext"))
    assert edges_into(graph, "core", "ext") == [("core.a", "ext.x", 1), ("core.c", "ext.x", 3),
                                                ("core.sub.b", "ext.y", 2)]
    assert edges_into(graph, "ext", "core") == [("ext.x", "core.a", 1)]
    assert "    core -> ext (3 module edges)" in show_packages(graph)
    # without them, nothing is found
    _write(tmp_path, {"core/a.py": "", "core/sub/b.py": "", "core/c.py": ""})
    assert edges_into(import_graph(tmp_path, ("core", "ext")), "core", "ext") == []


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


if __name__ == "__main__":
    g = import_graph(ROOT, PACKAGES)
    print(f"{len(g)} modules in {', '.join(PACKAGES)}; package-level imports:")
    print(show_packages(g))
    print(f"circle: {describe(c, g) if (c := find_cycle(g)) else 'none'}; "
          f"rfw -> vkext imports: {len(edges_into(g, 'rfw', 'vkext'))}")
