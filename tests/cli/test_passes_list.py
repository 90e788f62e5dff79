"""``rfw passes``: every registered pass with its docstring's summary, slots (formats, size
rules) and settings (type, default, range), through the real CLI."""

import json
from pathlib import Path

import rfw.registry as registry

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]


def test_every_pass_is_listed(tmp_path):
    done = warm_cli("passes", cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    headers = [line.split()[0] for line in done.stdout.splitlines()
               if line and not line.startswith(" ")]
    assert headers == sorted(registry.available())
    assert len(headers) >= 10


def test_slots_and_settings_of_known_passes(tmp_path):
    done = warm_cli("passes", "tonemap", "flat", cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert "tonemap  (compute; passes.tonemap.tonemap)" in lines
    assert "    Exposure, then a filmic curve (ACES fit), then sRGB encoding." in lines
    assert "    in  hdr (texture any): linear HDR scene color" in lines
    assert "    out ldr (texture rgba8unorm, like hdr): display color" in lines
    assert "    set exposure: float = 1.0" in lines
    assert "    set ambient: float = 0.25 in 0..1" in lines  # flat's declared Range
    assert "    out depth (depth depth32float): scene depth" in lines
    assert not any(line.startswith("gbuffer") for line in lines)  # only those asked for


def test_json_carries_the_declarations(tmp_path):
    done = warm_cli("passes", "--json", "debug_view", cwd=tmp_path, tree=True)
    assert done.returncode == 0, done.stderr
    [entry] = json.loads(done.stdout)
    cls = registry.get_pass("debug_view")
    assert entry["id"] == "debug_view" and entry["module"] == cls.__module__
    assert [s["name"] for s in entry["inputs"]] == list(cls.inputs)
    assert [(s["name"], s["format"]) for s in entry["outputs"]] == \
        [(k, v.format) for k, v in cls.outputs.items()]
    assert [(s["name"], s["default"] if not isinstance(s["default"], list)
             else tuple(s["default"])) for s in entry["settings"]] == \
        [(k, d) for k, (_, d) in cls.Params.fields().items()]
    assert {s["name"]: s["type"] for s in entry["settings"]}["range"] == "tuple[float, float]"


def test_unknown_pass_is_one_line_with_a_suggestion(tmp_path):
    # negative control: a misspelt name is refused, nothing printed on stdout
    done = warm_cli("passes", "tonemap", "tonemapp", cwd=tmp_path, tree=True)
    assert done.returncode == 2
    assert done.stderr == "rfw: error: passes: unknown pass 'tonemapp' (did you mean " \
                          "'tonemap'?)\n"
    assert done.stdout == ""
    assert list(tmp_path.iterdir()) == []
