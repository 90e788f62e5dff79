"""examples/: each script run headless in a subprocess at 32x18, its output checked
(issue 14, item 2)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from .golden_util import changed_share

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
NUMBER = r"[-+]?\d+\.\d+"


def example(name: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    # headless: no display, matplotlib's Agg
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MPLBACKEND")}
    return subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def test_every_example_is_tested():
    tested = {"ab_setting.py", "sweep_plot.py", "plugin_pass.py", "api_tour.ipynb",
              "notebook_pass.ipynb"}  # the last by tests/api/test_notebook_pass.py
    # _common.py is what the scripts share, not an example
    assert {p.name for p in EXAMPLES.iterdir() if p.suffix in (".py", ".ipynb")
            and not p.name.startswith("_")} == tested


AB_ROW = re.compile(rf"^(\w+)\s+({NUMBER})\s+({NUMBER})-({NUMBER})\s+({NUMBER})\s+({NUMBER})-"
                    rf"({NUMBER})\s+({NUMBER})\s+([-+]\d+\.\d)% (.+)$", re.MULTILINE)


def ab_rows(stdout: str) -> dict[str, tuple[list[float], str]]:
    """pass -> ([A ms, A lo, A hi, B ms, B lo, B hi, B/A, change %], mark)."""
    return {m[1]: ([float(v) for v in m.groups()[1:9]], m[10])
            for m in AB_ROW.finditer(stdout)}


def test_ab_setting(tmp_path):
    done = example("ab_setting.py", "lighting.ambient=0.2", "lighting.ambient=1.5",
                   "--size", "32x18", "--frames", "2", "--repeats", "6", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    # interleaved: A and B take turns going first
    assert "6 renders a side of 2 frames, order AB BA AB BA AB BA)" in done.stdout
    rows = ab_rows(done.stdout)
    assert list(rows) == ["gbuffer", "lighting", "tonemap", "total"]
    for (a, a_lo, a_hi, b, b_lo, b_hi, ratio, change), mark in rows.values():
        assert a_lo <= a <= a_hi and b_lo <= b <= b_hi  # medians inside their CIs
        # B/A and the change are of the unrounded medians: within the printed ones' rounding
        low, high = (b - 5e-4) / (a + 5e-4), (b + 5e-4) / max(a - 5e-4, 1e-9)
        assert low - 5e-4 <= ratio <= high + 5e-4
        assert 100 * (low - 1) - 0.05 <= change <= 100 * (high - 1) + 0.05
        assert mark in ("*", "(n.s.)")  # 6 renders a side: enough for a mark
    # the summary line names exactly the passes marked * (no timing is asserted)
    moved = re.search(r"^beyond the noise \(95% CI of the ratio clear of 1\): (.+)$", done.stdout,
                      re.MULTILINE)
    marked = [n for n, (_, mark) in rows.items() if mark == "*" and n != "total"]
    assert moved[1] == (", ".join(marked) or "no pass")
    changed = re.search(rf"image tonemap\.ldr: mean \|B-A\| ({NUMBER}), ({NUMBER})% of pixels",
                        done.stdout)
    assert float(changed[1]) > 1.0 and float(changed[2]) > 50.0
    # negative controls: A against itself changes no pixel, and 2 renders a side are too
    # few for any mark: each change says why instead
    same = example("ab_setting.py", "lighting.ambient=0.2", "lighting.ambient=0.2",
                   "--size", "32x18", "--frames", "1", "--repeats", "2", cwd=tmp_path)
    assert same.returncode == 0, same.stderr
    assert "image tonemap.ldr: mean |B-A| 0.0000, 0.0% of pixels changed" in same.stdout
    assert "order AB BA)" in same.stdout
    few = ab_rows(same.stdout)
    assert list(few) == ["gbuffer", "lighting", "tonemap", "total"]
    assert {mark for _, mark in few.values()} == {"(n=2<6: no mark)"}
    assert "no marks: n=2<6 (use --repeats 6 or more)" in same.stdout
    assert "beyond the noise" not in same.stdout
    assert list(tmp_path.iterdir()) == []  # it writes nothing


def test_ab_setting_bad_setting_is_one_line(tmp_path):
    done = example("ab_setting.py", "lighting.ambient=0.2", "lighting.ambiant=1",
                   "--size", "32x18", "--frames", "1", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        f"ab_setting: error: {ROOT / 'configs' / 'deferred.toml'}: pass 'lighting': unknown "
        "setting 'ambiant' (did you mean 'ambient'?)"]


def _line_colours(png: Path, n: int) -> list[int]:
    # pixels of each of matplotlib's first n line colours (tab:blue, tab:orange, ...)
    import matplotlib.colors as mc
    from matplotlib import rcParams

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    counts = []
    for c in rcParams["axes.prop_cycle"].by_key()["color"][:n]:
        rgb = np.array([round(v * 255) for v in mc.to_rgb(c)])
        counts.append(int((np.abs(img - rgb).max(axis=2) <= 2).sum()))
    return counts


def test_sweep_plot(tmp_path):
    done = example("sweep_plot.py", "ssao.samples", "4", "16", "--size", "32x18",
                   "--frames", "1", "--repeats", "6", "--out", "sweep.png", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "GPU ms, median [95% CI] over 6 renders of 1 frames"
    header, *rows = [line.split() for line in lines[1:4]]
    passes = ["shadow", "gbuffer", "ssao", "lighting", "tonemap", "fxaa"]
    assert header == ["ssao.samples", *passes]
    assert [r[0] for r in rows] == ["4", "16"]
    for r in rows:  # each cell: median [lo-hi], the median inside its CI
        cells = re.findall(rf"({NUMBER}) \[({NUMBER})-({NUMBER})\]", " ".join(r[1:]))
        assert len(cells) == len(passes)
        assert all(0 <= float(lo) <= float(m) <= float(hi) for m, lo, hi in cells)
    # the second value against the first: marked passes only, or that none moved
    versus = re.fullmatch(r"ssao\.samples=16 vs 4: (.+)", lines[4])
    assert versus and (versus[1] == "no pass beyond the noise" or all(
        re.fullmatch(r"\w+ [-+]\d+\.\d% \*", x) for x in versus[1].split(", "))), lines[4]
    png = tmp_path / "sweep.png"
    assert Image.open(png).size == (640, 400)
    assert all(c > 20 for c in _line_colours(png, len(passes)))  # a line per pass
    # negative control: the same axes without lines show none of those colours
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    ax.set_xlabel("ssao.samples")
    fig.savefig(tmp_path / "empty.png")
    plt.close(fig)
    assert _line_colours(tmp_path / "empty.png", len(passes)) == [0] * len(passes)
    # negative control of the marks: 2 renders per value are too few, and it says so
    few = example("sweep_plot.py", "ssao.samples", "4", "16", "--size", "32x18",
                  "--frames", "1", "--repeats", "2", "--out", "few.png", cwd=tmp_path)
    assert few.returncode == 0, few.stderr
    assert "ssao.samples=16 vs 4: no marks: n=2<6 (use --repeats 6 or more)" in few.stdout


def test_sweep_plot_bad_key_is_one_line(tmp_path):
    done = example("sweep_plot.py", "ssao.sample", "4", "--size", "32x18", "--frames", "1",
                   cwd=tmp_path)
    assert done.returncode == 2
    assert len(done.stderr.splitlines()) == 1
    assert "pass 'ssao': unknown setting 'sample' (did you mean 'samples'?)" in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_plugin_pass(tmp_path):
    done = example("plugin_pass.py", "--size", "32x18", "--out", "out", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "max |inverted - (255 - color)| = 0" in done.stdout
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == ["flat.color.png", "invert.inverted.png",
                                                     "timings.json"]
    color = np.asarray(Image.open(out / "flat.color.png")).astype(int)
    inverted = np.asarray(Image.open(out / "invert.inverted.png")).astype(int)
    assert np.array_equal(inverted[..., :3], 255 - color[..., :3])
    assert np.array_equal(inverted[..., 3], color[..., 3])
    # negative control: amount=0 leaves the color as it is, so the same check fails there
    done = example("plugin_pass.py", "--size", "32x18", "--out", "zero", "--set",
                   "invert.amount=0", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    kept = np.asarray(Image.open(tmp_path / "zero" / "invert.inverted.png")).astype(int)
    assert np.array_equal(kept, color)
    assert changed_share(kept[..., :3], 255 - color[..., :3]) > 0.5  # every pixel


def test_plugin_pass_bad_setting_is_one_line(tmp_path):
    done = example("plugin_pass.py", "--size", "32x18", "--out", "out", "--set",
                   "invert.amount=2", cwd=tmp_path)
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("plugin_pass: error: <python: plugin_demo>")
    assert "'amount'" in lines[0]
    assert not (tmp_path / "out").exists()


def test_plugin_pass_bad_size_is_a_usage_error(tmp_path):
    done = example("plugin_pass.py", "--size", "32xq", "--out", "out", cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.splitlines()[-1] == ("plugin_pass.py: error: argument --size: "
                                            "expected WxH (e.g. 1920x1080), got '32xq'")
    assert not (tmp_path / "out").exists()


def test_notebook_runs_and_shows_results(tmp_path):
    # executed in a real kernel, as Jupyter would: each result displays as PNG and HTML
    import base64
    import io

    # the test extra installs them; a GPU machine without them (device_env.sh) skips
    nbclient = pytest.importorskip("nbclient")
    nbformat = pytest.importorskip("nbformat")
    pytest.importorskip("ipykernel")

    import rfw

    nb = nbformat.read(EXAMPLES / "api_tour.ipynb", as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")  # kept clean
    nbclient.NotebookClient(nb, timeout=240, kernel_name="python3",
                            resources={"metadata": {"path": str(EXAMPLES)}}).execute()
    results = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
               if o.output_type == "execute_result"]
    assert results[1]["data"]["text/plain"] == "(1, 1)"  # one device, one scene load
    shown = [o["data"] for o in results if "image/png" in o["data"]
             and o["data"]["text/plain"].startswith("<rfw.Result")]
    assert len(shown) == 2
    # the A/B: per pass medians with CIs and a mark, which passes moved, a chart of the CIs
    ab = results[4]["data"]["text/plain"]
    marks = re.findall(rf"'(\w+)': '{NUMBER} \[{NUMBER}-{NUMBER}\] -> {NUMBER} "
                       rf"\[{NUMBER}-{NUMBER}\] ms: [-+]\d+\.\d% (\*|\(n\.s\.\))'", ab)
    assert [name for name, _ in marks] == ["gbuffer", "lighting", "tonemap"], ab
    moved = ", ".join(name for name, mark in marks if mark == "*") or "none"
    assert results[5]["data"]["text/plain"] == (
        f"'changed significantly (95% CI of the ratio clear of 1): {moved}'")
    chart = results[6]["data"]
    assert chart["text/plain"].startswith("<Figure") and "image/png" in chart
    for data in shown:
        assert data["text/plain"].startswith("<rfw.Result 'deferred' on ")
        assert "<td>gbuffer</td>" in data["text/html"] and "base64," in data["text/html"]
    a, b = (np.asarray(Image.open(io.BytesIO(base64.b64decode(d["image/png"]))))
            for d in shown)
    # the first display is the picture rfw renders for that config; the second (exposure
    # 2.5) is not: the negative control
    ref = rfw.run(ROOT / "configs" / "deferred.toml", size=(32, 18), frames=1)
    assert np.array_equal(a, ref.images["tonemap.ldr"])
    assert changed_share(b, ref.images["tonemap.ldr"]) > 0.5  # every pixel


def _refused(done: subprocess.CompletedProcess, script: str, expected: str) -> None:
    # one line, before any render: nothing on stdout (the sweep's table comes after it)
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stdout == "" and "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error: "), done.stderr
    assert expected in lines[0], lines[0]


def test_sweep_plot_out_folder_is_checked_before_the_sweep(tmp_path):
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "adir").mkdir()
    args = ["ssao.samples", "4", "--size", "32x18", "--frames", "1"]
    done = example("sweep_plot.py", *args, "--out", "afile/folder/sw.png", cwd=tmp_path)
    _refused(done, "sweep_plot", f"{tmp_path / 'afile'}: --out: not a folder")
    done = example("sweep_plot.py", *args, "--out", "adir", cwd=tmp_path)
    _refused(done, "sweep_plot", "adir: --out: is a folder, not a PNG")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["adir", "afile"]
    assert (tmp_path / "afile").read_text() == "mine"
    # negative control: a folder that is missing but can be made is made, after the sweep
    done = example("sweep_plot.py", *args, "--out", "missing/folder/sw.png", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert Image.open(tmp_path / "missing" / "folder" / "sw.png").size == (640, 400)


def test_plugin_pass_out_folder_is_checked_before_rendering(tmp_path):
    (tmp_path / "afile").write_text("mine")
    for out in ("afile", "afile/sub"):
        done = example("plugin_pass.py", "--size", "32x18", "--out", out, cwd=tmp_path)
        _refused(done, "plugin_pass", f"{tmp_path / 'afile'}: --out: not a folder")
    assert [p.name for p in tmp_path.iterdir()] == ["afile"]
    # negative control: a missing nested folder is made
    done = example("plugin_pass.py", "--size", "32x18", "--out", "a/b", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "a" / "b" / "invert.inverted.png").is_file()


def readme_python() -> str:
    """The README's pasteable Python example: the first python block of its API section."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("### Python API and notebooks", 1)[1]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


def test_the_readme_python_example_runs_as_written(tmp_path):
    from .conftest import tree_env

    (tmp_path / "configs").symlink_to(ROOT / "configs")
    code = readme_python()
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=tree_env(),
                       capture_output=True, text=True, timeout=300, check=False)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert [line.split(" ", 1)[0] for line in lines] == ["wgpu", "vk"], lines
    for line in lines:  # the override reached the graph: the shadow pass ran and was timed
        assert line.split(" ", 1)[1].startswith("(180, 320, 4) {'shadow': "), line
    saved = tmp_path / "out" / "api"
    assert sorted(f.name for f in saved.iterdir()) == ["timings.json", "tonemap.ldr.png"]
    # the control: the same example with the override left out has no shadow pass
    p = subprocess.run([sys.executable, "-c", code.replace(', "shadow.enabled=true"', "")],
                       cwd=tmp_path, env=tree_env(), capture_output=True, text=True,
                       timeout=300, check=False)
    assert p.returncode == 0 and "'shadow'" not in p.stdout, p.stdout
