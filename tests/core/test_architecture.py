"""The architecture issue 22 asks for, checked on the source (AST): passes import only the
pass API; no ``ctx.replay()`` call in passes; the environment is read in one module and the
run options in one; the executor core's responsibilities are defined once, not per backend.
Each rule is a function run on the tree and, as its negative control, on a snippet that
breaks it."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PASS_API = "rfw.authoring"
ALLOWED_IN_PASSES = {"numpy", "__future__"} | set(sys.stdlib_module_names)


def _sources(folder: str) -> dict[str, ast.Module]:
    return {str(f.relative_to(ROOT)): ast.parse(f.read_text(encoding="utf-8"))
            for f in sorted((ROOT / folder).rglob("*.py")) if "__pycache__" not in f.parts}


def pass_import_problems(name: str, tree: ast.Module) -> list[str]:
    """Imports of a pass module that are not the pass API, the standard library or numpy."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = "." * node.level + (node.module or "")
            ok = node.level == 0 and (module == PASS_API or module.split(".")[0]
                                      in ALLOWED_IN_PASSES)
        elif isinstance(node, ast.Import):
            module = ", ".join(a.name for a in node.names)
            ok = all(a.name.split(".")[0] in ALLOWED_IN_PASSES for a in node.names)
        else:
            continue
        if not ok:
            out.append(f"{name}:{node.lineno} imports {module}")
    return out


def replay_calls(name: str, tree: ast.Module) -> list[str]:
    """``ctx.replay(...)`` calls: replay is declared (``replay = "auto"``), never called."""
    return [f"{name}:{n.lineno}" for n in ast.walk(tree)
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
            and n.func.attr == "replay"]


def environ_reads(name: str, tree: ast.Module) -> list[str]:
    """Uses of ``os.environ`` / ``os.getenv`` (reads or writes)."""
    def reads(n: ast.AST) -> bool:
        if isinstance(n, ast.ImportFrom):  # from os import environ
            return n.module == "os" and any(a.name in ("environ", "getenv") for a in n.names)
        return isinstance(n, ast.Attribute) and n.attr in ("environ", "getenv") and \
            isinstance(n.value, ast.Name) and n.value.id == "os"

    return [f"{name}:{n.lineno}" for n in ast.walk(tree) if reads(n)]


def option_variable_reads(name: str, tree: ast.Module, variables: set[str]) -> list[str]:
    """String constants naming a run option's environment variable (RFW_VK_BUNDLES, ...):
    what reads it, outside the options module."""
    return [f"{name}:{n.lineno} {n.value}" for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and n.value in variables]


def test_passes_import_only_the_pass_api():
    problems = [p for name, tree in _sources("passes").items()
                for p in pass_import_problems(name, tree)]
    assert problems == []
    bad = ast.parse("from vkext.meshlet import draw_meshlets\n"
                    "from ..visbuffer.visbuffer import triangle_bits\n"
                    "from rfw.backends.scene_data import material_bytes\nimport wgpu\n"
                    "from rfw.authoring import Pass\nimport numpy as np\nimport struct\n")
    assert len(pass_import_problems("x.py", bad)) == 4  # negative control


def test_no_pass_calls_replay():
    assert [c for name, tree in _sources("passes").items()
            for c in replay_calls(name, tree)] == []
    assert replay_calls("x.py", ast.parse("if ctx.replay(size):\n    pass\n")) == ["x.py:1"]


def test_the_environment_is_read_in_one_module():
    # rfw.env reads and checks every RFW_* variable; these others read the process's
    # environment for what is not rfw's: whether there is a display, XDG_CACHE_HOME, and
    # the environment a child process (a bench worker, a registry client) starts with
    others = {"rfw/view.py", "rfw/meshlet_view/__init__.py", "rfw/spirv.py",
              "rfw/bench/runner.py", "rfw/scene/fetch/download.py",
              "rfw/bench/gpus.py"}  # CUDA_VISIBLE_DEVICES: CUDA's ordinals of a Ray task
    found = {}
    for folder in ("rfw", "vkext", "passes"):
        for name, tree in _sources(folder).items():
            if name != "rfw/env.py" and environ_reads(name, tree):
                found[name] = environ_reads(name, tree)
    assert set(found) <= others, found
    assert environ_reads("x.py", ast.parse("import os\nos.environ['RFW_POISON'] = '1'\n"))


def test_run_options_are_read_only_by_the_options_module():
    from rfw.options import ENVIRONMENT

    variables = set(ENVIRONMENT.values())
    found = [r for folder in ("rfw", "vkext", "passes")
             for name, tree in _sources(folder).items()
             if name not in ("rfw/options.py", "rfw/env.py")
             for r in option_variable_reads(name, tree, variables)]
    assert found == []
    snippet = ast.parse("from rfw import env\nbundles = env.get('RFW_VK_BUNDLES')\n")
    assert option_variable_reads("x.py", snippet, variables) == ["x.py:2 RFW_VK_BUNDLES"]


# what the core (rfw.exec) defines: no backend defines these names again
CORE_NAMES = {"PassTiming", "pass_timings", "Samplers", "replay_key", "settings_key",
              "history_pairs", "SetupContext", "ExecutorCore", "check_instance_limits",
              "InFlight", "run_frames"}
# top-level names both backends define, each a backend's own primitive, not a core duty:
# a compiled pipeline with its reflected layout, and what one frame in flight owns
SHARED_PRIMITIVES = {"Program", "FrameSlot"}


def _top_level(folder: str) -> dict[str, str]:
    return {node.name: name for name, tree in _sources(folder).items() for node in tree.body
            if isinstance(node, ast.FunctionDef | ast.ClassDef)}


def test_core_responsibilities_are_not_defined_per_backend():
    wgpu, vk = _top_level("rfw/backends/wgpu"), _top_level("vkext")
    assert {n: wgpu[n] for n in CORE_NAMES & set(wgpu)} == {}
    assert {n: vk[n] for n in CORE_NAMES & set(vk)} == {}
    assert set(wgpu) & set(vk) == SHARED_PRIMITIVES
    # negative control: a backend module that defines its own timing record is caught
    snippet = ast.parse("class PassTiming:\n    pass\n")
    assert CORE_NAMES & {n.name for n in snippet.body}
