"""rfw.env: every RFW_* variable is read and checked in one place, and documented.

The readers directly (no GPU); tests/cli/test_edge_numbers.py drives them through the CLI."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from rfw import env
from rfw.errors import RfwError

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "environment.md"
NAME = re.compile(r"\bRFW_[A-Z0-9]+(?:_[A-Z0-9]+)*\b")
# shader include guards (RFW_SCENE_GLSL) and stdout line markers of two benchmarks
NOT_VARIABLES = re.compile(r"RFW_\w+_GLSL|RFW_POINT|RFW_RECORD")
READ_HERE = re.compile(r"""(?:environ(?:\.get)?\s*[(\[]|getenv\(|setenv\()\s*["'](RFW_\w+)"""
                       r"""|^\s*(?:[A-Z_]+=\S+\s+)*(RFW_\w+)=""", re.M)


def names_in_package(text: str) -> set[str]:
    """Every RFW_ name in rfw/vkext/passes source: each is a variable rfw reads."""
    return {n for n in NAME.findall(text) if not NOT_VARIABLES.fullmatch(n)}


def names_read(text: str) -> set[str]:
    """RFW_ names a test or benchmark reads or sets (os.environ, setenv, VAR=... in sh)."""
    return {a or b for a, b in READ_HERE.findall(text)}


def documented(doc: str) -> set[str]:
    return set(re.findall(r"`(RFW_\w+)`", doc))


def _sources(*folders: str, suffixes: tuple[str, ...] = (".py",)) -> str:
    # this file's negative controls hold names nobody reads
    return "\n".join(p.read_text(errors="replace") for f in folders
                     for p in sorted((ROOT / f).rglob("*")) if p.suffix in suffixes
                     and p.is_file() and p != Path(__file__).resolve())


def test_every_variable_in_the_source_is_documented_and_has_a_reader():
    package = names_in_package(_sources("rfw", "vkext", "passes"))
    others = names_read(_sources("tests", "benchmarks", suffixes=(".py", ".sh")))
    doc = documented(DOC.read_text())
    assert package >= {"RFW_FETCH", "RFW_VK_BUNDLES", "RFW_GPU"}  # the grep finds them
    assert sorted(package - doc) == [] and sorted(others - doc) == []
    # what rfw itself reads is checked by rfw.env; nothing is documented that nobody reads
    assert package == set(env.READERS)
    assert doc <= package | others


def test_a_name_missing_from_the_docs_is_caught():
    # negative controls: the same functions catch a new variable in the package, in a test
    # and in a shell script, and leave out what is no variable
    code = 'x = os.environ.get("RFW_NOT_DOCUMENTED")\n#include RFW_SCENE_GLSL\n'
    assert names_in_package(code) == {"RFW_NOT_DOCUMENTED"}
    assert names_read('monkeypatch.setenv("RFW_NEW_KNOB", "1")\n') == {"RFW_NEW_KNOB"}
    assert names_read("  RFW_SH_KNOB=1 python3 -m pytest\n") == {"RFW_SH_KNOB"}
    doc = documented(DOC.read_text())
    assert "RFW_NOT_DOCUMENTED" not in doc and "RFW_FETCH" in doc


def test_only_rfw_env_reads_rfw_variables_from_the_environment():
    reads = re.compile(r"""(?:environ(?:\.get)?\s*[(\[]|getenv\()\s*(["']RFW_|[A-Z_]+_ENV\b)""")
    found = [str(p.relative_to(ROOT)) for f in ("rfw", "vkext", "passes")
             for p in sorted((ROOT / f).rglob("*.py")) if reads.search(p.read_text())]
    assert found == []
    # negative control: the pattern sees an ad-hoc read, by name or by constant
    assert reads.search('os.environ.get("RFW_X", "1")')
    assert reads.search("os.environ.get(SPAN_ENV, '0')")


@pytest.mark.parametrize(("name", "raw", "value"), [
    ("RFW_FETCH", "1", True), ("RFW_FETCH", "0", False), ("RFW_FETCH", " YES ", True),
    ("RFW_FETCH", "off", False), ("RFW_FETCH", "", False), ("RFW_FETCH", "  ", False),
    ("RFW_VK_BUNDLES", "0", False), ("RFW_VK_BUNDLES", "", True), ("RFW_VK_BUNDLES", "1", True),
    ("RFW_VK_FRAME_REPLAY", "0", False), ("RFW_VK_FRAME_SPAN", "1", True),
    ("RFW_VK_FRAME_SPAN", "", False), ("RFW_POISON", "true", True),
    ("RFW_GPU", "0", 0), ("RFW_GPU", "3", 3), ("RFW_GPU", "", None), ("RFW_GPU", "+1", 1),
    ("RFW_GPU", "uuid:" + "AB" * 16, "uuid:" + "ab" * 16),
    ("RFW_GPU", "GPU-6b2b8a3c-1d2e-4f50-8a9b-0c1d2e3f4a5b", "uuid:6b2b8a3c1d2e4f508a9b0c1d2e3f4a5b"),
    ("RFW_FAKE_GPUS", "2", 2),
    ("RFW_FRAMES_IN_FLIGHT", "1", 1), ("RFW_FRAMES_IN_FLIGHT", "8", 8),
    ("RFW_ORDER_SEED", "4294967295", 4294967295), ("RFW_ORDER_SEED", "", None),
    ("RFW_VK_ASYNC_QUEUE", "graphics", "graphics"), ("RFW_VK_ASYNC_QUEUE", "", "family"),
    ("RFW_RAYCAST_MAPPED", "hits", "hits"), ("RFW_RAYCAST_MAPPED", "", "auto"),
    ("RFW_VIEW_FORMAT", "rgba8unorm-srgb", "rgba8unorm-srgb"), ("RFW_VIEW_FORMAT", "", None),
    ("RFW_COMMIT", "v1.2-3-gabc+dirty", "v1.2-3-gabc+dirty"), ("RFW_COMMIT", " ", None),
])
def test_valid_values_and_empty_as_unset(monkeypatch, name, raw, value):
    monkeypatch.setenv(name, raw)
    assert env.get(name) == value
    env.check_all()


@pytest.mark.parametrize(("name", "raw", "says"), [
    ("RFW_FETCH", "maybe", "expected 0 or 1 (or true/false, yes/no, on/off), not 'maybe'"),
    ("RFW_VK_BUNDLES", "2", "expected 0 or 1 (or true/false, yes/no, on/off), not '2'"),
    ("RFW_GPU", "gpu0", "expected a device index (from 0), uuid:<32 hex digits> or "
                        "GPU-<uuid>, not 'gpu0'"),
    ("RFW_GPU", "uuid:12ab", "or GPU-<uuid>, not 'uuid:12ab'"),  # 4 hex digits, not 32
    ("RFW_GPU", "-1", "expected a device index (from 0), not '-1'"),
    ("RFW_GPU", "²", "or GPU-<uuid>, not '²'"),  # isdigit() took it
    ("RFW_GPU", "1_0", "not '1_0'"), ("RFW_GPU", "1.0", "not '1.0'"),
    ("RFW_FRAMES_IN_FLIGHT", "9", "expected a whole number from 1 to 8, not '9'"),
    ("RFW_FRAMES_IN_FLIGHT", "0", "from 1 to 8, not '0'"),
    ("RFW_ORDER_SEED", "4294967296", "expected a seed (from 0 to 4294967295)"),
    ("RFW_VK_ASYNC_QUEUE", "Family", "expected family or graphics, not 'Family'"),
    ("RFW_RAYCAST_MAPPED", "yes", "expected 0, 1, rays, hits, host or auto, not 'yes'"),
    ("RFW_VIEW_FORMAT", "rgba16float", "expected bgra8unorm, rgba8unorm, bgra8unorm-srgb or "
                                       "rgba8unorm-srgb, not 'rgba16float'"),
    ("RFW_COMMIT", "abc def", "expected a commit"),
    ("RFW_CACHE_SPIRV", str(Path(__file__)), "expected a folder (that path is a file)"),
])
def test_a_bad_value_is_one_line_naming_the_variable(monkeypatch, name, raw, says):
    monkeypatch.setenv(name, raw)
    with pytest.raises(RfwError) as err:
        env.get(name)
    line = str(err.value)
    assert line.startswith(f"{name}: ") and says in line and "\n" not in line
    with pytest.raises(RfwError, match=f"^{name}: "):
        env.check_all()  # the same refusal, for every command
    monkeypatch.delenv(name)  # control: unset, the variable's default passes
    env.get(name)
    env.check_all()


def test_a_long_value_is_shortened_and_control_characters_are_escaped(monkeypatch):
    monkeypatch.setenv("RFW_FETCH", "x" * 500 + "\n\x1b[2J")
    with pytest.raises(RfwError) as err:
        env.get("RFW_FETCH")
    line = str(err.value)
    assert len(line) < 160 and "\n" not in line and "\x1b" not in line


def test_a_folder_that_does_not_exist_yet_is_fine(monkeypatch, tmp_path):
    monkeypatch.setenv("RFW_CACHE", "~/not-there-yet")
    assert env.get("RFW_CACHE") == Path.home() / "not-there-yet"
    monkeypatch.setenv("RFW_CACHE_MESHLETS", str(tmp_path))
    assert env.get("RFW_CACHE_MESHLETS") == tmp_path


def test_the_readers_use_the_bounds_of_their_modules():
    from rfw.config import MAX_FRAMES_IN_FLIGHT
    from rfw.view import present_format

    assert MAX_FRAMES_IN_FLIGHT == env.MAX_FRAMES_IN_FLIGHT
    assert present_format("bgra8unorm-srgb") == "bgra8unorm"
    try:
        from vkext import raycast
    except ImportError:  # no Vulkan bindings here
        return
    assert set(env.RAYCAST_PLACEMENTS) == set(raycast.PLACEMENTS) | {"auto"}
