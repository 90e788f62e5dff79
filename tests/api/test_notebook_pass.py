"""A pass class defined where there is no file (issue 21, item 6): a notebook cell, stdin,
``python -c``. Its shader comes as text (``shader_source``) or from ``folder=``; the
pictures are checked analytically (inverted = 255 - colour, exactly), with ``amount=0`` as
the control, and a class with neither is refused in one line."""

from __future__ import annotations

import base64
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"

SCRIPT = '''
import sys
import numpy as np
import rfw
from rfw import ComputePass, Settings, Tex2D, register_pass

backend, how = sys.argv[1], sys.argv[2]
TEXT = open("examples/invert.comp.glsl").read()
where = {"folder": "examples"} if how == "folder" else {}


@register_pass("stdin_invert", **where)
class StdinInvertPass(ComputePass):
    """Inverts a display color."""

    shader = "invert.comp.glsl"
    shader_source = TEXT if how == "text" else None
    inputs = {"color": Tex2D()}
    outputs = {"inverted": Tex2D("rgba8unorm", size_of="color")}

    class Params(Settings):
        amount: float = 1.0

    def record(self, ctx):
        ctx.dispatch(threads=ctx.extent("inverted"), t_color=ctx.sampled("color"),
                     o_inverted=ctx.storage("inverted"), u_params=self.params)


cfg = rfw.make_config("stdin", [{"name": "flat"}, {"name": "inv", "use": "stdin_invert",
                                "inputs": {"color": "flat.color"}}],
                      outputs=["flat.color", "inv.inverted"], size=(24, 16))
for amount in (1.0, 0.0):
    r = rfw.run(cfg, f"inv.amount={amount}", backend=backend)
    c = r.images["flat.color"][..., :3].astype(int)
    i = r.images["inv.inverted"][..., :3].astype(int)
    print(amount, int(np.abs(i - (255 - c)).max()), int(np.abs(i - c).max()),
          len(np.unique(c.reshape(-1, 3), axis=0)))
'''


def _run(args: list[str], stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], input=stdin, cwd=ROOT, capture_output=True,
                          text=True, timeout=300, check=False)


@pytest.mark.parametrize(("how", "backend"), [("text", "wgpu"), ("text", "vk"),
                                              ("folder", "wgpu")])
def test_a_pass_from_stdin_renders(how, backend):
    if backend == "vk":
        pytest.importorskip("vulkan")
    done = _run(["-", backend, how], SCRIPT)
    assert done.returncode == 0, done.stderr
    rows = [line.split() for line in done.stdout.splitlines()]
    (a1, inv1, _, colours), (a0, inv0, same0, _) = rows
    assert (a1, inv1) == ("1.0", "0")  # every pixel 255 - colour, exactly
    assert int(colours) >= 4  # the scene has colours to invert (not one flat sky)
    # control: amount 0 leaves the colour, which the same check refuses
    assert (a0, same0) == ("0.0", "0") and int(inv0) > 100


def test_a_pass_from_python_c_renders_and_one_without_shaders_is_refused():
    done = _run(["-c", SCRIPT, "wgpu", "text"])
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0].split()[:2] == ["1.0", "0"]
    # the same class without text or folder: refused where it is defined, one line
    code = ("import rfw\n@rfw.register_pass('lost')\nclass LostPass(rfw.ComputePass):\n"
            "    shader = 'lost.comp.glsl'\n")
    for args, stdin in ((["-c", code], None), (["-"], code)):
        done = _run(args, stdin)
        assert done.returncode == 1
        last = done.stderr.strip().splitlines()[-1]
        assert last.startswith("rfw.graph.errors.GraphError: pass 'lost': pass class LostPass "
                               "is not defined in a file"), last
        assert "shader_source" in last and "folder=" in last
        assert "OSError" not in done.stderr and "inspect.py" not in done.stderr


def test_notebook_pass_runs_in_a_kernel():
    nbclient = pytest.importorskip("nbclient")
    nbformat = pytest.importorskip("nbformat")
    pytest.importorskip("ipykernel")
    import rfw

    nb = nbformat.read(EXAMPLES / "notebook_pass.ipynb", as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")  # kept clean
    nbclient.NotebookClient(nb, timeout=240, kernel_name="python3",
                            resources={"metadata": {"path": str(EXAMPLES)}}).execute()
    outs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    results = [o["data"] for o in outs if o.output_type == "execute_result"]
    shown, checks, same = results
    assert shown["text/plain"].startswith("<rfw.Result 'notebook_pass' on ")
    assert "flat.color" in shown["text/html"] and "invert.inverted" in shown["text/html"]
    # inverted exactly; amount=0 (the control) leaves the colour: 255 off somewhere
    assert checks["text/plain"] == "(0, 255)"
    assert same["text/plain"] == "True"  # the folder= pass renders the same image
    printed = "".join(o.get("text", "") for o in outs if o.output_type == "stream")
    assert "pass 'notebook_lost': pass class LostPass is not defined in a file" in printed
    assert not [o for o in outs if o.output_type == "error"]
    # what the notebook displays is the scene rfw renders (flat, 32x18)
    png = np.asarray(Image.open(io.BytesIO(base64.b64decode(shown["image/png"]))))
    ref = rfw.run(ROOT / "configs" / "flat.toml", size=(32, 18), backend="wgpu")
    assert np.array_equal(png, ref.images["flat.color"])
