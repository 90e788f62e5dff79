"""The CLI's error boundary (issue 11, items 2 and 3), through the real CLI in a subprocess
(forked from a warm one, tests/cli/warm.py; the closed-pipe case starts its own).

Every bad input exits 2 with exactly one stderr line ``rfw: error: FILE: ELEMENT: message``
and no traceback; nothing is written outside ``--out``; a failed run leaves no
``timings.json`` and no unmarked image of an earlier run. Controls beside the bad cases
show that good values pass the same checks.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from .warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
DEFERRED = ROOT / "configs" / "deferred.toml"
MESHLET = ROOT / "configs" / "meshlet.toml"
RAPTOR = ROOT / "tests" / "data" / "raptor" / "chapter4_graph.json"
SMALL = ["--size", "64x36", "--frames", "1"]

# a small valid config; cases below break one thing in it
BASE = """name = "t"
size = [64, 36]
outputs = ["tonemap.ldr"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", emissive = "gbuffer.emissive", depth = "gbuffer.depth" }

[[pass]]
name = "tonemap"
inputs = { hdr = "lighting.hdr" }
"""


def rfw(*args: object, cwd: Path) -> subprocess.CompletedProcess:
    return warm_cli(*args, cwd=cwd, env={"HOME": str(cwd / "home"),
                                         "XDG_CACHE_HOME": str(cwd / "cache")})


def error_line(done: subprocess.CompletedProcess, *needles: str) -> str:
    """The one error line, after checking exit 2, no traceback and every needle in it."""
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 2, (done.returncode, done.stderr)
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def files_under(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and not p.is_symlink()
            and not str(p.relative_to(root)).startswith(("home", "cache", "out"))}


def seed_out(out: Path) -> None:
    out.mkdir()
    (out / "tonemap.ldr.png").write_bytes(b"an old image")
    (out / "timings.json").write_text('{"old": true}\n')


def assert_earlier_results_kept(out: Path) -> None:
    # issue 21: a failed run leaves --out as it was, byte for byte, with nothing added
    assert sorted(p.name for p in out.iterdir()) == ["timings.json", "tonemap.ldr.png"]
    assert (out / "tonemap.ldr.png").read_bytes() == b"an old image"
    assert (out / "timings.json").read_text() == '{"old": true}\n'


def config(text: str = BASE, **replace: str) -> str:
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


# (id, config text or None for deferred.toml, extra arguments, words the line must name)
BAD_RUNS = [
    ("frames-string", 'frames = "two"\n' + BASE, [], ["c.toml", "frames", "'two'"]),
    ("camera-int", "camera = 5\n" + BASE, [], ["c.toml", "camera"]),
    ("camera-yfov-nan", BASE + "[camera]\nyfov = nan\n", [], ["c.toml", "camera.yfov",
                                                              "finite"]),
    ("variant-int", BASE + "[variants]\nx = 5\n", [], ["c.toml", "variants.x"]),
    ("input-int", config(**{'hdr = "lighting.hdr"': "hdr = 5"}), [],
     ["c.toml", "pass 'tonemap'", "inputs.hdr"]),
    ("int-setting-huge", BASE + "settings = { curve = 99999999999999 }\n", [],
     ["c.toml", "pass 'tonemap'", "setting 'curve'", "32-bit"]),
    ("float-setting-inf", BASE + "settings = { exposure = inf }\n", [],
     ["c.toml", "pass 'tonemap'", "setting 'exposure'", "finite"]),
    ("set-nan", None, ["--set", "lighting.ambient=nan"],
     ["deferred.toml", "pass 'lighting'", "setting 'ambient'", "finite"]),
    ("set-int-word", None, ["--set", "tonemap.curve=fast"],
     ["deferred.toml", "setting 'curve'", "'fast'"]),
    ("set-frames-negative", None, ["--set", "frames=-2"], ["deferred.toml", "frames"]),
    ("set-input-escape", None, ["--set", "tonemap.inputs.hdr=../../x"],
     ["deferred.toml", "tonemap.inputs.hdr", "'../../x'"]),
    ("pass-name-parent", config(**{'name = "tonemap"': 'name = "../../x"'}), [],
     ["c.toml", "'../../x'", "not an identifier"]),
    ("pass-name-absolute", config(**{'name = "tonemap"': 'name = "/abs/x"'}), [],
     ["c.toml", "'/abs/x'", "not an identifier"]),
    ("pass-name-control", config(**{'name = "tonemap"': 'name = "a\\u0007b"'}), [],
     ["c.toml", "not an identifier"]),
    ("output-name-parent", config(**{'outputs = ["tonemap.ldr"]': 'outputs = ["../x"]'}), [],
     ["c.toml", "outputs", "'../x'"]),
    ("variant-name-parent", BASE + '[variants."../v"]\ndefault = "a"\na = {}\n', [],
     ["c.toml", "variant name '../v'"]),
    ("unknown-pass-id", config(**{'use = "deferred_lighting"': 'use = "deferred_lightin"'}), [],
     ["c.toml", "pass 'lighting'", "did you mean 'deferred_lighting'"]),
    ("invalid-utf8", b'name = "\xff"\n' + BASE.encode(), [], ["c.toml", "line 1", "UTF-8"]),
    ("bad-toml-line", BASE + "\n[[pass]\n", [], ["c.toml", f"line {BASE.count(chr(10)) + 2},",
                                                     "malformed TOML"]),
    ("nested-too-deep", "frames = " + "[" * 2000 + "]" * 2000 + "\n" + BASE, [],
     ["c.toml", "line 1", "frames is nested too deeply"]),
    ("scene-missing", 'scene = "nope.glb"\n' + BASE, [], ["c.toml", "scene", "nope.glb"]),
    ("frames-negative", None, ["--frames", "-2"], ["--frames", "-2"]),
    ("frames-zero", None, ["--frames", "0"], ["--frames", "between 1 and"]),
    ("size-zero", None, ["--size", "0x5"], ["--size", "positive"]),
    ("size-huge", None, ["--size", "20000x5"], ["--size", "16384"]),
    ("validate-without-vk", None, ["--backend", "wgpu", "--validate"],
     ["deferred.toml", "--validate"]),
]


@pytest.mark.parametrize("text,extra,needles", [c[1:] for c in BAD_RUNS],
                         ids=[c[0] for c in BAD_RUNS])
def test_bad_run_input_is_one_line_and_keeps_earlier_results(tmp_path, text, extra,
                                                                needles):
    if text is not None:
        (tmp_path / "c.toml").write_bytes(text if isinstance(text, bytes) else text.encode())
    seed_out(tmp_path / "out")
    before = files_under(tmp_path)
    cfg = ["c.toml"] if text is not None else [DEFERRED]
    args = [*cfg, *(SMALL if "--size" not in extra and "--frames" not in extra else []),
            *extra, "--out", "out"]
    error_line(rfw("run", *args, cwd=tmp_path), *needles)
    assert files_under(tmp_path) == before  # nothing written outside --out
    assert_earlier_results_kept(tmp_path / "out")


def test_a_good_run_replaces_the_earlier_results(tmp_path):
    # control: the same folder, the same checks, a valid run: its outputs replace the old
    # ones, and an older version's failure mark goes
    (tmp_path / "c.toml").write_text(config(**{'name = "tonemap"': 'name = "tonemap"\n'
                                                                   'settings = { curve = 0 }'}))
    seed_out(tmp_path / "out")
    error_line(rfw("run", "c.toml", "--frames", "0", "--out", "out", cwd=tmp_path))
    assert_earlier_results_kept(tmp_path / "out")
    (tmp_path / "out" / "RUN-FAILED.txt").write_text("from an older rfw")
    done = rfw("run", "c.toml", "--set", "tonemap.exposure=0.5", *SMALL, "--out", "out",
               cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["timings.json",
                                                                     "tonemap.ldr.png"]
    assert (tmp_path / "out" / "tonemap.ldr.png").read_bytes().startswith(b"\x89PNG")
    assert json.loads((tmp_path / "out" / "timings.json").read_text())["frames"] == 1


def test_a_symlinked_output_cannot_write_elsewhere(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    out = tmp_path / "out"
    out.mkdir()
    (out / "tonemap.ldr.png").symlink_to(victim)
    error_line(rfw("run", DEFERRED, *SMALL, "--out", "out", cwd=tmp_path),
               "tonemap.ldr.png", "outside the output folder")
    assert victim.read_text() == "keep me"


def test_out_that_is_a_file_is_one_line(tmp_path):
    (tmp_path / "out").write_text("a file")
    error_line(rfw("run", DEFERRED, *SMALL, "--out", "out", cwd=tmp_path), "out", "--out")
    assert (tmp_path / "out").read_text() == "a file"


def test_scene_in_a_config_is_relative_to_the_config(tmp_path):
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (sub / "c.toml").write_text('scene = "tri.obj"\n' + BASE)
    done = rfw("run", "sub/c.toml", *SMALL, "--out", "out", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "out" / "timings.json").read_text())["triangles"] == 1
    # --scene on the command line stays relative to the working folder
    error_line(rfw("run", "sub/c.toml", "--scene", "tri.obj", *SMALL, "--out", "o2",
                   cwd=tmp_path), "scene", "tri.obj")


def test_raptor_names_must_be_identifiers(tmp_path):
    doc = json.loads(RAPTOR.read_text())
    doc["passes"][0]["name"] = "../../evil"
    (tmp_path / "g.json").write_text(json.dumps(doc))
    error_line(rfw("graph", "plan", "g.json", cwd=tmp_path), "g.json", "'../../evil'")


@pytest.mark.parametrize("command", ["plan", "dot", "convert"])
def test_graph_commands_take_run_configs(tmp_path, command):
    done = rfw("graph", command, DEFERRED, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for name in ("gbuffer", "lighting", "tonemap"):
        assert name in done.stdout


def test_graph_plan_of_a_broken_run_config_names_it(tmp_path):
    (tmp_path / "c.toml").write_text(config(**{'hdr = "lighting.hdr"': 'hdr = "lighting.hdrr"'}))
    error_line(rfw("graph", "plan", "c.toml", cwd=tmp_path), "c.toml", "pass 'tonemap'", "'hdrr'")


def test_graph_plan_into_a_closed_pipe_is_quiet(tmp_path):
    # enough output to fill the pipe: a chain of passes, read one line, then hang up
    lines = ['name = "chain"', "size = [64, 64]"]
    for i in range(400):
        lines += ["[[pass]]", f'name = "p{i}"', 'type = "compute"']
        if i:
            lines += [f'inputs.src = {{ from = "p{i - 1}.out", type = "texture" }}']
        lines += ['outputs.out = { type = "texture", format = "VK_FORMAT_R8G8B8A8_UNORM" }']
    (tmp_path / "g.toml").write_text("\n".join(lines) + "\n")
    proc = subprocess.Popen([sys.executable, "-m", "rfw.cli", "graph", "plan", "g.toml"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait(timeout=120) == 0 and first.startswith(b"graph 'chain'")
    assert err == ""
    # control: the whole plan is larger than a pipe holds, so the write above did fail
    full = rfw("graph", "plan", "g.toml", cwd=tmp_path)
    assert full.returncode == 0 and len(full.stdout) > 1 << 16


def test_argparse_errors_are_one_line(tmp_path):
    error_line(rfw("run", "--frames", "two", cwd=tmp_path), "--frames", "'two'")
    error_line(rfw("meshlets", "show", "default", "--cone-weight", "nan", cwd=tmp_path),
               "--cone-weight")
    error_line(rfw(cwd=tmp_path), "usage")


def test_new_pass_refuses_names_that_leave_its_folder(tmp_path):
    error_line(rfw("new-pass", "../evil", "--dir", "p", cwd=tmp_path), "'../evil'")
    assert not (tmp_path / "evil").exists() and not (tmp_path / "p").exists()


def test_meshlet_config_runs_on_the_backend_its_pins_need(tmp_path):
    done = rfw("run", MESHLET, *SMALL, "--out", "out", cwd=tmp_path)
    if done.returncode == 2 and "VK_EXT_mesh_shader" in done.stderr:
        pytest.skip("the device has no mesh shaders")
    assert done.returncode == 0, done.stderr
    timings = json.loads((tmp_path / "out" / "timings.json").read_text())
    assert timings["backend"] == "vk"
    assert "culling" in timings
