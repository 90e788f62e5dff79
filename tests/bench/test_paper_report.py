"""Paper-ready reports (issue 14, item 5), through the CLI on synthetic results: one
self-contained HTML file, results.csv, error bars, significance marks, colour-mapped
differences with a legend, tables that fit, per-device tables and ``compare --out``."""

from __future__ import annotations

import csv
import json
import re
import zlib
from pathlib import Path

import numpy as np
import pytest

from rfw.bench.images import diff_image
from rfw.bench.report import write_report
from rfw.bench.stats import significant
from rfw.bench.summary import summarize_results

from ..cli.warm import warm_cli
from .synthetic import record

# every place an HTML page can load another file from
REF = re.compile(r"""(?:src|href|srcset|poster|data)\s*=\s*['"]?([^'"\s>]+)"""
                 r"""|url\(\s*['"]?([^'")]+)""", re.I)


def relative_refs(page: str) -> list[str]:
    """References to other files (anything but an embedded ``data:`` URI or an anchor)."""
    found = [a or b for a, b in REF.findall(page)]
    return [f for f in found if not f.startswith(("data:", "#"))]


def _png(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(path)


def write_results(out: Path, variants: dict[str, dict], *, repeats: int = 3) -> Path:
    """``variants``: label -> {passes, noise, spread, image (HxWx3 uint8), device}.

    ``spread``: every pass's frames evenly spaced over median x (1 -/+ spread), so the
    median is exact and the spread (hence the CI) is chosen."""
    lines = []
    for r in range(repeats):
        for label, v in variants.items():
            rec = record(label, r, v["passes"], noise=v.get("noise", 0.01),
                         seed=zlib.crc32(label.encode()) % 1000)
            if "spread" in v:
                rng = np.random.default_rng(r)
                for p in rec["passes"]:
                    mid = v["passes"][p["name"]]
                    p["gpu_ms"] = rng.permutation(
                        mid * (1 + v["spread"] * np.linspace(-1, 1, 21))).tolist()
                rec["frame"]["gpu_ms"] = [sum(x) for x in zip(
                    *(p["gpu_ms"] for p in rec["passes"]), strict=True)]
            rec["device"] = v.get("device", "synthetic")
            if "image" in v:
                rel = f"runs/{rec['variant_id']}/r{r}/image.png"
                _png(out / rel, v["image"])
                rec["image"] = rel
            lines.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return out


def _image(value: int = 100) -> np.ndarray:
    return np.full((18, 32, 3), value, np.uint8)


def test_html_is_one_file_with_csv_and_tables_that_fit(tmp_path):
    changed = _image()
    changed[3:6, 4:9] = 40
    out = write_results(tmp_path / "b", {
        "deferred@wgpu": {"passes": {"gbuffer": 10.0, "lighting": 2.0}, "image": _image()},
        "forward@wgpu": {"passes": {"forward": 8.0}, "image": changed}})
    done = warm_cli("bench", "report", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    page = (out / "report.html").read_text()
    # negative control: the check finds what the old report had (a relative PNG)
    assert relative_refs("<a href='images/x.png'><img src='charts/p.png'></a>") == [
        "images/x.png", "charts/p.png"]
    assert relative_refs(page) == []
    imgs = re.findall(r"<img src='([^']+)'", page)
    assert len(imgs) >= 6 and all(s.startswith("data:image/png;base64,") for s in imgs)
    # the page still opens alone: copy it somewhere with nothing beside it
    alone = tmp_path / "alone" / "report.html"
    alone.parent.mkdir()
    alone.write_text(page)
    assert relative_refs(alone.read_text()) == []
    # every table sits in a box that scrolls sideways; images never exceed their cell
    assert page.count("<table>") == page.count("<div class='wide'><table>") > 3
    assert ".wide{max-width:100%;overflow-x:auto" in page and "img{max-width:100%" in page
    # results.csv beside results.jsonl: one row per variant, pass and metric
    rows = list(csv.DictReader((out / "results.csv").open()))
    lighting = next(r for r in rows if r["variant"] == "deferred@wgpu"
                    and r["pass"] == "lighting" and r["metric"] == "gpu_ms")
    s = next(v for v in summarize_results([json.loads(x) for x in
                                           (out / "results.jsonl").read_text().splitlines()])
             if v.label == "deferred@wgpu").passes[1]["gpu_ms"]
    assert float(lighting["median"]) == pytest.approx(s["median"], abs=1e-6)
    assert float(lighting["ci_lo"]) < float(lighting["median"]) < float(lighting["ci_hi"])
    assert {r["pass"] for r in rows if r["variant"] == "forward@wgpu"} == {"frame", "forward"}


def _vs_reference(md: str) -> dict[str, str]:
    """variant -> its 'vs reference' cell, from report.md's image table."""
    head = next(x for x in md.splitlines() if x.startswith("| variant | image |"))
    col = [c.strip() for c in head.strip("|").split("|")].index("vs reference")
    out = {}
    for line in md.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) > col and "![" in line and cells[0].endswith("@wgpu"):
            out[cells[0]] = cells[col]
    return out


def test_significance_mark_only_where_cis_do_not_overlap(tmp_path):
    out = write_results(tmp_path / "b", {
        "ref@wgpu": {"passes": {"p": 10.0}, "spread": 0.02, "image": _image()},
        # +15 % in both, but one is drowned in noise (overlapping CIs)
        "noisy@wgpu": {"passes": {"p": 11.5}, "spread": 0.8, "image": _image()},
        "clear@wgpu": {"passes": {"p": 11.5}, "spread": 0.02, "image": _image()}})
    variants = {v.label: v for v in summarize_results(
        [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()])}
    ref = variants["ref@wgpu"].frame["gpu_ms"]
    noisy, clear = variants["noisy@wgpu"].frame["gpu_ms"], variants["clear@wgpu"].frame["gpu_ms"]
    # the setup is what the test claims: +15 % each, CIs overlapping for one only
    assert noisy["median"] / ref["median"] - 1 == pytest.approx(0.15)
    assert clear["median"] / ref["median"] - 1 == pytest.approx(0.15)
    assert noisy["ci_lo"] <= ref["ci_hi"] and not significant(ref, noisy)
    assert significant(ref, clear)
    done = warm_cli("bench", "report", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    cells = _vs_reference((out / "report.md").read_text())
    assert cells["ref@wgpu"] == "reference"
    assert cells["clear@wgpu"] == "+15.0% *"
    assert cells["noisy@wgpu"] == "+15.0% (n.s.)"


def test_difference_map_neither_saturates_nor_hides(tmp_path):
    ref = _image(0)
    big = ref.copy()
    big[1, 1], big[2, 2] = 200, 100  # two large changes must stay apart
    rgb, top = diff_image(ref, big)
    assert top == 200
    assert tuple(rgb[1, 1]) != tuple(rgb[2, 2]) and not (rgb[0, 0]).any()
    assert rgb[2, 2].astype(int).sum() < rgb[1, 1].astype(int).sum()
    # negative control: the old x8 gain maps both to the same white
    old = np.clip(np.abs(big.astype(int) - ref).max(axis=2) * 8, 0, 255)
    assert old[1, 1] == old[2, 2] == 255
    tiny = ref.copy()
    tiny[4, 5, 2] = 1  # one 8-bit step in one channel
    rgb, top = diff_image(ref, tiny)
    assert top == 1 and rgb[4, 5].max() >= 200 and rgb.reshape(-1, 3).astype(int).sum(
        axis=1).tolist().count(0) == 18 * 32 - 1
    # negative control: under x8 the same change is 8 of 255, all but black
    assert np.abs(tiny.astype(int) - ref).max() * 8 < 16
    # through the report: each difference image comes with its legend, scaled to its max
    changed = _image()
    changed[0, 0] = 255
    out = write_results(tmp_path / "b", {
        "a@wgpu": {"passes": {"p": 1.0}, "image": _image()},
        "b@wgpu": {"passes": {"p": 1.0}, "image": changed}})
    assert warm_cli("bench", "report", str(out), safe_path=True).returncode == 0
    from PIL import Image

    legend = Image.open(out / "images" / "b_wgpu.diff_legend.png")
    assert legend.width > 2 * legend.height  # a horizontal colour bar
    md = (out / "report.md").read_text()
    assert "![legend](images/b_wgpu.diff_legend.png)" in md and "x 8" not in md


def test_stacked_chart_error_bars_are_the_pass_cis(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.axes import Axes

    calls = []
    original = Axes.errorbar

    def spy(self, x, y, *args, **kwargs):
        calls.append((self.get_title(), list(x), np.asarray(kwargs["xerr"], float)))
        return original(self, x, y, *args, **kwargs)

    monkeypatch.setattr(Axes, "errorbar", spy)
    out = write_results(tmp_path / "b", {"d@wgpu": {"passes": {"g": 10.0, "l": 2.0},
                                                    "noise": 0.1},
                                         "f@wgpu": {"passes": {"g": 5.0}, "noise": 0.1}})
    write_report(out)
    v = summarize_results([json.loads(x) for x in
                           (out / "results.jsonl").read_text().splitlines()])[0]
    gpu = [c for c in calls if c[0].startswith("GPU")]
    assert len(gpu) == 2  # one per stacked pass
    assert len(gpu[0][1]) == 2 and len(gpu[1][1]) == 1  # f has no 'l': no bar for it
    left = 0.0
    for (_, x, err), p in zip(gpu, v.passes, strict=True):
        s = p["gpu_ms"]
        left += s["median"]
        assert x[0] == pytest.approx(left)  # at the segment's end
        assert err[:, 0] == pytest.approx([s["median"] - s["ci_lo"], s["ci_hi"] - s["median"]])
        assert err.min() > 0  # negative control of a bar that draws nothing


def _rewrite(folder: Path, change) -> None:
    """Apply ``change(record)`` to every record of ``folder/results.jsonl``."""
    lines = [json.loads(x) for x in (folder / "results.jsonl").read_text().splitlines()]
    for rec in lines:
        change(rec)
    (folder / "results.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def _slower(rec: dict, factor: float) -> None:
    for p in rec["passes"]:
        p["gpu_ms"] = [x * factor for x in p["gpu_ms"]]
    rec["frame"]["gpu_ms"] = [x * factor for x in rec["frame"]["gpu_ms"]]


def _row(md: str, prefix: str) -> list[str]:
    line = next(x for x in md.splitlines() if x.startswith(prefix))
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_per_device_tables_side_by_side(tmp_path):
    two = write_results(tmp_path / "two", {
        "d@wgpu": {"passes": {"g": 10.0}, "device": "GPU A", "image": _image()},
        "e@wgpu": {"passes": {"g": 5.0}, "device": "GPU B", "image": _image()}})

    def first_d_on_b(rec: dict) -> None:  # d@wgpu's first run ran on B, twice as slow
        if rec["variant"] == "d@wgpu" and rec["repeat"] == 0:
            rec["device"] = "GPU B"
            _slower(rec, 2.0)

    _rewrite(two, first_d_on_b)
    assert warm_cli("bench", "report", str(two), safe_path=True).returncode == 0
    md = (two / "report.md").read_text()
    assert "## Per device" in md
    # devices in first-run order: B (d's first run), then A
    head = next(x for x in md.splitlines() if x.startswith("| variant | pass | GPU B"))
    assert [c.strip() for c in head.strip("|").split("|")][2:] == [
        "GPU B: GPU ms", "GPU B: 95% CI", "GPU A: GPU ms", "GPU A: 95% CI"]
    d = next(x for x in md.splitlines() if x.startswith("| d@wgpu | frame |")).split("|")
    e = next(x for x in md.splitlines() if x.startswith("| e@wgpu | frame |")).split("|")
    assert float(d[3]) == pytest.approx(20.0, rel=0.05) and float(d[5]) == pytest.approx(
        10.0, rel=0.05)
    assert float(e[3]) == pytest.approx(5.0, rel=0.05) and e[5].strip() == "-"  # not on A
    # the frame table: one row per (variant, device), each with that device's statistics;
    # nothing is pooled over devices any more
    frame = md.split("## Frame time per variant")[1].split("\n## ")[0]
    on_b, on_a = _row(frame, "| d@wgpu [GPU B] |"), _row(frame, "| d@wgpu [GPU A] |")
    assert on_b[1:3] == ["GPU B", "wgpu"] and on_a[1:3] == ["GPU A", "wgpu"]
    assert float(on_b[3]) == pytest.approx(20.0, rel=0.05)
    assert float(on_a[3]) == pytest.approx(10.0, rel=0.05)
    assert _row(frame, "| e@wgpu |")[1] == "GPU B"  # one device: no suffix
    assert "| d@wgpu |" not in frame and "mixed" not in md
    # per-pass tables and charts' rows too
    assert "### d@wgpu [GPU B]" in md and "### d@wgpu [GPU A]" in md and "### e@wgpu" in md
    # results.csv: the same split rows, each with its own median
    rows = list(csv.DictReader((two / "results.csv").open()))
    frame_gpu = {(r["variant"], r["device"]): float(r["median"]) for r in rows
                 if r["pass"] == "frame" and r["metric"] == "gpu_ms"}
    assert set(frame_gpu) == {("d@wgpu [GPU B]", "GPU B"), ("d@wgpu [GPU A]", "GPU A"),
                              ("e@wgpu", "GPU B")}
    assert frame_gpu["d@wgpu [GPU B]", "GPU B"] == pytest.approx(20.0, rel=0.05)
    assert frame_gpu["d@wgpu [GPU A]", "GPU A"] == pytest.approx(10.0, rel=0.05)
    # vs reference (d@wgpu, split): e is compared with d's run on B, its own device
    images = md.split("## Images")[1]
    assert _row(images, "| d@wgpu [GPU B] |")[-1] == "reference"
    assert _row(images, "| d@wgpu [GPU A] |")[-1] == "reference"
    vs = _row(images, "| e@wgpu |")[-1]  # pooled d (median 10 ms) would give -50 %
    # d ran once on B: one run measures no run-to-run noise, so the change has no mark
    assert vs.endswith("% (1 run: no mark)"), vs
    assert float(vs.split("%")[0]) == pytest.approx(-75.0, abs=1.0), vs
    # negative control: one device, no per-device section, no device suffix on any label
    one = write_results(tmp_path / "one", {"d@wgpu": {"passes": {"g": 10.0}},
                                           "e@wgpu": {"passes": {"g": 5.0}}})
    assert warm_cli("bench", "report", str(one), safe_path=True).returncode == 0
    md = (one / "report.md").read_text()
    assert "## Per device" not in md and "[synthetic]" not in md
    assert _row(md.split("## Frame time per variant")[1], "| d@wgpu |")[1] == "synthetic"
    assert "### d@wgpu\n" in md
    assert {r["variant"] for r in csv.DictReader((one / "results.csv").open())} == {
        "d@wgpu", "e@wgpu"}


def test_vs_reference_on_the_same_device(tmp_path):
    # B is twice as slow as A for everything; n is 10 % slower than r on each device. Each
    # device's row is compared with the reference on that device: +10 % *, never the
    # +120 % of n on B against r on A, nor a pooled n.s. over both devices.
    out = write_results(tmp_path / "b", {
        "r@wgpu": {"passes": {"g": 10.0}, "spread": 0.01, "image": _image()},
        "n@wgpu": {"passes": {"g": 11.0}, "spread": 0.01, "image": _image()},
        "s@wgpu": {"passes": {"g": 10.5}, "spread": 0.4, "image": _image()},
        "o@wgpu": {"passes": {"g": 12.0}, "spread": 0.01, "image": _image()}}, repeats=4)

    def place(rec: dict) -> None:
        if rec["variant"] == "o@wgpu":  # only ever ran on C, where r never ran
            rec["device"] = "GPU C"
        elif rec["repeat"] % 2:
            rec["device"] = "GPU B"
            _slower(rec, 2.0)
        else:
            rec["device"] = "GPU A"

    _rewrite(out, place)
    done = warm_cli("bench", "report", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (out / "report.md").read_text()
    images = md.split("## Images")[1].split("\n## ")[0]
    assert "compared with the reference's runs on the same device" in images
    assert _row(images, "| r@wgpu [GPU A] |")[-1] == "reference"
    assert _row(images, "| r@wgpu [GPU B] |")[-1] == "reference"
    assert _row(images, "| n@wgpu [GPU A] |")[-1] == "+10.0% *"
    assert _row(images, "| n@wgpu [GPU B] |")[-1] == "+10.0% *"
    # negative control of the mark: +5 % inside a wide spread is n.s. on each device
    assert _row(images, "| s@wgpu [GPU A] |")[-1] == "+5.0% (n.s.)"
    assert _row(images, "| s@wgpu [GPU B] |")[-1] == "+5.0% (n.s.)"
    # no reference run on C: the change is shown without a mark
    o = _row(images, "| o@wgpu |")[-1]
    assert o.endswith("(reference not run on GPU C: no mark)") and "*" not in o
    assert "n.s." not in o
    # the split rows' difference images are files of their own
    diffs = sorted(p.name for p in (out / "images").glob("n_wgpu*.diff.png"))
    assert len(diffs) == 2, diffs
    # --reference names the variant as run, not one of its rows
    done = warm_cli("bench", "report", str(out), "--reference", "n@wgpu", safe_path=True)
    assert done.returncode == 0, done.stderr
    images = (out / "report.md").read_text().split("## Images")[1].split("\n## ")[0]
    assert _row(images, "| r@wgpu [GPU B] |")[-1] == "-9.1% *"
    assert _row(images, "| n@wgpu [GPU A] |")[-1] == "reference"


def test_compare_writes_md_and_html_with_image_diffs(tmp_path):
    base = {"p": 10.0, "q": 2.0}
    old = write_results(tmp_path / "old", {"d@wgpu": {"passes": base, "image": _image()}})
    changed = _image()
    changed[5, 5] = 90
    new = write_results(tmp_path / "new", {"d@wgpu": {"passes": {"p": 10.0, "q": 2.6},
                                                      "image": changed}})
    out = tmp_path / "cmp"
    done = warm_cli("bench", "compare", str(old), str(new), "--out", str(out), safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (out / "compare.md").read_text()
    q = next(x for x in md.splitlines() if x.startswith("| d@wgpu | q | gpu_ms |"))
    p = next(x for x in md.splitlines() if x.startswith("| d@wgpu | p | gpu_ms |"))
    assert "% * | regression |" in q
    assert "(n.s.) | same |" in p  # same means: no mark
    assert "## Images" in md
    psnr = md.split("## Images")[1].strip().splitlines()[-1].split("|")[-2].strip()
    assert psnr.endswith("dB") and "∞" not in psnr  # one pixel differs
    assert relative_refs((out / "compare.html").read_text()) == []
    assert (out / "images" / "0_diff.png").is_file()
    # bad input: one line, exit 2, nothing written to --out
    bad = tmp_path / "bad"
    done = warm_cli("bench", "compare", str(old), str(tmp_path / "missing"), "--out", str(bad),
                    safe_path=True)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "missing" in done.stderr and "Traceback" not in done.stderr
    assert not bad.exists()
