"""``format_of``: an output takes the format of another slot's resource (a post-process keeps its
input's format), resolved by the compiler; ``rfw new-pass``'s compute template uses it."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rfw.graph import Attachment, Buffer, GraphBuilder, GraphError, History, Texture, compile
from rfw.passes import storage_format
from rfw.templates import new_pass

from ..golden_util import changed_share, read_png

# the generated pass after tonemap (rgba8unorm) or, as the control, after lighting
# (rgba16float); gain 2 so the rendered check sees the pass ran
CONFIG = """name = "fo"
scene = "default"
size = [32, 18]
outputs = ["tonemap.ldr", "fx.dst"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "lighting"
use = "deferred_lighting"
inputs = {{ albedo = "gbuffer.albedo", normal = "gbuffer.normal", material = "gbuffer.material", emissive = "gbuffer.emissive", depth = "gbuffer.depth" }}

[[pass]]
name = "tonemap"
inputs = {{ hdr = "lighting.hdr" }}

[[pass]]
name = "fx"
use = "{use}"
inputs = {{ src = "{src}" }}
settings = {{ gain = 2.0 }}
"""

# the real CLI, with a plugin imported first (it is not installed)
RUN = """import sys
sys.path.insert(0, sys.argv.pop(1))
__import__(sys.argv.pop(1))
from rfw.cli import main
sys.exit(main(sys.argv[1:]))
"""


def cli(plugins: Path, module: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", RUN, str(plugins), module, *map(str, args)],
                          capture_output=True, text=True, check=False)


def fmt(graph, resource: str, **kw) -> str:
    return compile(graph, **kw).resource(resource).format


def post(src_format: str, *, kind: str = "compute", out=None, order=("src", "fx")):
    """A producer of ``src_format`` and a pass whose output follows it."""
    g = GraphBuilder("post", size=(32, 18))
    out = out or (Texture(format_of="i") if kind == "compute"
                  else Attachment(format_of="i"))
    for name in order:
        if name == "src":
            g.add_pass("src", "graphics").output("color", Attachment(src_format))
        else:
            g.add_pass("fx", kind).input("i", "src.color").output("o", out)
    return g.output("fx.o").build()


# ---------------------------------------------------------------------------------------------
# the compiler, no GPU


def test_the_output_takes_the_input_format():
    assert fmt(post("rgba8unorm"), "fx.o") == "rgba8unorm"
    assert fmt(post("rgba16float"), "fx.o") == "rgba16float"  # control: it follows, not fixed
    assert fmt(post("rgba32float", kind="graphics"), "fx.o") == "rgba32float"
    # the follower may come first in declaration order; sizes follow as before
    c = compile(post("r16float", order=("fx", "src")))
    assert (c.resource("fx.o").format, c.resource("fx.o").width) == ("r16float", 32)
    assert c.resource("fx.o").raw_bytes == c.resource("src.color").raw_bytes


def test_chains_and_history_copies_follow():
    g = GraphBuilder("chain", size=(16, 8))
    g.add_pass("c", "compute").input("x", "b.o").output("o", Texture(format_of="x"))
    g.add_pass("b", "compute").input("x", "a.o").output("o", Texture(format_of="x"))
    g.add_pass("a", "compute").output("o", Texture("rg16float"))
    g.add_pass("t", "compute").input("h", "c.o", Texture()).input("prev", "c.o", History()) \
        .output("o", Texture("r8unorm"))
    c = compile(g.output("t.o").build())
    assert [c.resource(n).format for n in ("b.o", "c.o", "c.o@prev")] == ["rg16float"] * 3


def test_srgb_becomes_its_linear_twin_only_where_stored():
    # storage images cannot be sRGB: a compute output takes the twin, an attachment keeps it
    assert fmt(post("rgba8unorm-srgb"), "fx.o") == "rgba8unorm"
    assert fmt(post("bgra8unorm-srgb"), "fx.o") == "bgra8unorm"
    assert fmt(post("rgba8unorm-srgb", kind="graphics"), "fx.o") == "rgba8unorm-srgb"
    assert fmt(post("VK_FORMAT_R8G8B8A8_SRGB"), "fx.o") == "VK_FORMAT_R8G8B8A8_UNORM"


def test_a_bridge_copy_follows_too():
    g = GraphBuilder("mixed", size=(16, 8))
    g.add_pass("a", "compute", backend="vk").output("o", Texture("rgba16float"))
    g.add_pass("b", "compute").input("x", "a.o").output("o", Texture(format_of="x"))
    g.add_pass("c", "compute").input("x", "b.o").output("o", Texture("rgba8unorm"))
    g.add_pass("d", "compute", backend="vk").input("x", "b.o").output("o", Texture("r8unorm"))
    c = compile(g.output("c.o", "d.o").build(), backend="wgpu")
    assert c.resource("b.o@vk").format == "rgba16float"


@pytest.mark.parametrize(("out", "message"), [
    (Texture(format_of="srcc"), r"pass 'fx', slot 'o': format_of 'srcc' is not a connected "
                                r"slot of the pass \(slots: i, o\)"),
    (Texture("rgba8unorm", format_of="i"), r"pass 'fx', slot 'o': declares both format "
                                           r"rgba8unorm and format_of 'i'"),
    (Texture(format_of="o"), r"pass 'fx', slot 'o': format_of forms a cycle: fx.o -> fx.o"),
])
def test_bad_format_of_names_pass_and_slot(out, message):
    with pytest.raises(GraphError, match=message):
        compile(post("rgba8unorm", out=out))
    compile(post("rgba8unorm"))  # control: the same graph with a good declaration compiles


def test_what_has_no_format_to_give():
    g = GraphBuilder("bad", size=(16, 8)).external("app", Texture(external=True))
    g.add_pass("b", "compute").output("buf", Buffer(64))
    g.add_pass("p", "compute").input("x", "app").output("o", Texture(format_of="x"))
    g.add_pass("q", "compute").input("x", "b.buf", Buffer()).output("o", Texture(format_of="x"))
    with pytest.raises(GraphError) as e:
        compile(g.output("p.o", "q.o").build())
    said = [str(e.value), *e.value.more]
    assert "pass 'p', slot 'o': format_of 'x': 'app' has no format to take" in said[0]
    assert said[1] == "pass 'q', slot 'o': format_of 'x': 'b.buf' is a buffer, not an image"
    assert len(said) == 2


def test_storage_format_qualifiers():
    assert [storage_format(f) for f in ("rgba8unorm", "rgba16float", "r32uint", "rg8snorm",
                                        "rgba16sint", "rgb10a2unorm", "rg11b10ufloat")] == \
        ["rgba8", "rgba16f", "r32ui", "rg8_snorm", "rgba16i", "rgb10_a2", "r11f_g11f_b10f"]
    for bad in ("rgba8unorm-srgb", "bgra8unorm", "r32unorm", "depth32float"):
        with pytest.raises(GraphError, match=f"format {bad} has no GLSL storage image"):
            storage_format(bad)


# ---------------------------------------------------------------------------------------------
# the template, through the CLI


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    plugins = tmp_path_factory.mktemp("plugins")
    new_pass("my_fx", plugins)
    return plugins


def plan_formats(tmp_path: Path, plugins: Path, src: str) -> dict[str, str]:
    config = tmp_path / f"{src}.toml"
    config.write_text(CONFIG.format(use="my_fx", src=src))
    done = cli(plugins, "my_fx.my_fx", "graph", "plan", config, "--json")
    assert done.returncode == 0, done.stderr
    return {r["name"]: r["format"] for r in json.loads(done.stdout)["resources"]}


def test_the_template_follows_its_input_in_the_plan(tmp_path, plugin):
    assert plan_formats(tmp_path, plugin, "tonemap.ldr")["fx.dst"] == "rgba8unorm"
    assert plan_formats(tmp_path, plugin, "lighting.hdr")["fx.dst"] == "rgba16float"  # control
    assert plan_formats(tmp_path, plugin, "gbuffer.albedo")["fx.dst"] == "rgba8unorm"  # twin


def test_the_template_after_tonemap_renders_on_both_backends(tmp_path, plugin):
    config = tmp_path / "fo.toml"
    config.write_text(CONFIG.format(use="my_fx", src="tonemap.ldr"))
    images = {}
    for backend, extra in (("wgpu", ()), ("vk", ("--validate",))):
        out = tmp_path / backend
        done = cli(plugin, "my_fx.my_fx", "run", config, "--backend", backend, "--frames", "1",
                   "--out", out, *extra)
        assert done.returncode == 0, f"{backend}: {done.stdout}{done.stderr}"
        if backend == "vk":
            assert "validation: 0 message(s)" in done.stdout
        ldr, fx = read_png(out / "tonemap.ldr.png"), read_png(out / "fx.dst.png")
        # an 8-bit storage image: gain 2 of k/255 stores 2k exactly (clamped), alpha as read
        want = np.minimum(ldr[..., :3].astype(np.int32) * 2, 255)
        assert np.array_equal(fx[..., :3], want) and np.array_equal(fx[..., 3], ldr[..., 3])
        assert changed_share(fx, ldr) > 0.5  # control: the gain did something (to all)
        images[backend] = fx
    assert np.array_equal(images["wgpu"], images["vk"])


def test_a_bad_format_of_is_one_line(tmp_path):
    plugins = tmp_path / "plugins"
    new_pass("bad_fx", plugins)
    module = plugins / "bad_fx" / "bad_fx.py"
    text = module.read_text()
    assert 'format_of="src"' in text
    module.write_text(text.replace('format_of="src"', 'format_of="srcc"'))
    config = tmp_path / "bad.toml"
    config.write_text(CONFIG.format(use="bad_fx", src="tonemap.ldr"))
    for args in (("graph", "plan", config), ("run", config, "--out", tmp_path / "out")):
        done = cli(plugins, "bad_fx.bad_fx", *args)
        assert done.returncode == 2, done.stdout + done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        assert "pass 'fx'" in lines[0] and "slot 'dst'" in lines[0]
        assert "format_of 'srcc'" in lines[0] and "did you mean 'src'" in lines[0]
    assert not (tmp_path / "out").exists()
