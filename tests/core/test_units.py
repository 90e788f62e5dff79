"""rfw.units: byte units and ``align_up`` are defined once (issue 12, item 7) and are right."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from rfw.units import GiB, KiB, MiB, align_up

ROOT = Path(__file__).resolve().parents[2]
UNIT_NAMES = {"KiB", "MiB", "GiB"}


def redefinitions(root: Path, packages: tuple[str, ...]) -> list[str]:
    """``file:line name`` for every unit constant assigned or ``*align*`` function defined
    at a module's top level outside ``rfw/units.py``."""
    out = []
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            if path == root / "rfw" / "units.py":
                continue
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                names = []
                if isinstance(node, ast.Assign):
                    names = [t.id for t in node.targets if isinstance(t, ast.Name)]
                elif isinstance(node, ast.FunctionDef):
                    names = [node.name]
                for name in names:
                    if name in UNIT_NAMES or "align" in name.lower():
                        out.append(f"{path.relative_to(root)}:{node.lineno} {name}")
    return out


def test_units_and_align_are_defined_once() -> None:
    assert redefinitions(ROOT, ("rfw", "vkext", "passes")) == []


def test_a_second_definition_is_found(tmp_path: Path) -> None:
    (tmp_path / "fake").mkdir()
    (tmp_path / "fake" / "mem.py").write_text(
        "MiB = 1 << 20\n\n\ndef _align(x, a):\n    return x\n", encoding="utf-8")
    assert redefinitions(tmp_path, ("fake",)) == ["fake/mem.py:1 MiB", "fake/mem.py:4 _align"]


def test_values() -> None:
    assert (KiB, MiB, GiB) == (1024, 1024 * 1024, 1024 * 1024 * 1024)


@pytest.mark.parametrize(("x", "a", "want"), [(0, 256, 0), (1, 256, 256), (256, 256, 256),
                                              (257, 256, 512), (100, 48, 144), (7, 1, 7)])
def test_align_up(x: int, a: int, want: int) -> None:
    assert align_up(x, a) == want
    assert align_up(x, a) % a == 0 and 0 <= align_up(x, a) - x < a


def test_align_up_is_not_rounding_down() -> None:
    # negative control: the round-down a wrong align would give fails the checks above
    wrong = 257 // 256 * 256
    assert wrong != align_up(257, 256) and not 0 <= wrong - 257 < 256
