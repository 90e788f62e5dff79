"""Report rough edges a user review found (report review 2), through the CLI: images from
different cameras are not compared, difference images state their scale (``--diff-scale
shared`` puts them on one), and a Ray report points to a per-device table only where there
is one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from rfw.bench.images import colorize

from ..cli.warm import warm_cli
from .test_paper_report import _image, _rewrite, _row, relative_refs, write_results
from .test_review_fixes import ray_results

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--size", "32x18", "--frames", "2", "--warmup", "1", "--repeat", "1", "--no-progress"]


def _orbit(turns: float = 1.0, frames: int = 20) -> dict:
    """A record's ``camera_path`` of an orbit (20 frames, as synthetic records have): each
    frame's camera as the worker writes it."""
    out = []
    for k in range(frames):
        t = k / frames
        a = 2 * np.pi * turns * t
        out.append({"t": t, "position": [6 * float(np.cos(a)), 3.0, 6 * float(np.sin(a))],
                    "target": [0.0, 1.0, 0.0], "yfov": 45.0, "write_ms": 0.01})
    return {"kind": "orbit", "frames": out}


def _images_section(md: str) -> str:
    return md.split("## Images")[1].split("\n## ")[0]


def _other(value: int, where=(slice(2, 5), slice(3, 9))) -> np.ndarray:
    img = _image()
    img[where] = value
    return img


# ---------------------------------------------------------------------------------------------
# 1. images from different cameras


def test_a_camera_path_against_a_static_reference_is_not_compared(tmp_path):
    out = write_results(tmp_path / "b", {
        "ref@wgpu": {"passes": {"p": 1.0}, "image": _image()},
        "same@wgpu": {"passes": {"p": 1.0}, "image": _other(90)},
        "orbit@wgpu": {"passes": {"p": 1.0}, "image": _other(20)},
        "yfov@wgpu": {"passes": {"p": 1.0}, "image": _other(30)},
        "scene@wgpu": {"passes": {"p": 1.0}, "image": _other(40)}})

    def cameras(rec: dict) -> None:
        if rec["variant"] == "orbit@wgpu":
            rec["settings"] = ["camera.path=orbit"]
            rec["camera_path"] = _orbit()
        elif rec["variant"] == "yfov@wgpu":
            rec["settings"] = ["camera.yfov=30"]
        elif rec["variant"] == "scene@wgpu":
            rec["scene"] = "sponza"

    _rewrite(out, cameras)
    done = warm_cli("bench", "report", str(out), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (out / "report.md").read_text()
    images = _images_section(md)
    assert "**Different cameras:**" in images
    orbit = _row(images, "| orbit@wgpu |")
    assert orbit[2] == ("different cameras: not compared (reference: static camera; this: "
                        "orbit path, last frame, t=0.95)"), orbit
    assert orbit[4:6] == ["not compared", "not compared"] or orbit[3:5] == [
        "not compared", "not compared"], orbit
    assert "dB" not in " ".join(orbit) and not list((out / "images").glob("orbit_wgpu.*"))
    yfov = _row(images, "| yfov@wgpu |")
    assert yfov[2] == ("different cameras: not compared (reference: static camera; this: "
                       "static camera (yfov=30))"), yfov
    scene = _row(images, "| scene@wgpu |")
    assert scene[2].startswith("different scenes: not compared"), scene
    # negative control: the same static camera is compared as before, with its scale
    same = _row(images, "| same@wgpu |")
    assert "![diff](images/same_wgpu.diff.png)" in same[2]
    assert "scale 0-10/255 (this image's max)" in same[2]
    assert any(c.endswith(" dB") for c in same) and "not compared" not in same
    assert (out / "images" / "same_wgpu.diff.png").is_file()
    page = (out / "report.html").read_text()
    assert "different cameras: not compared" in page and relative_refs(page) == []
    # a path against the same path: compared (the same last frame); another path is not
    done = warm_cli("bench", "report", str(out), "--reference", "orbit@wgpu", cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    assert _row(images, "| orbit@wgpu |")[-1] == "reference"
    assert "∞ (identical)" in _row(images, "| orbit@wgpu |")
    ref = _row(images, "| ref@wgpu |")[2]
    assert ref == ("different cameras: not compared (reference: orbit path, last frame, "
                   "t=0.95; this: static camera)"), ref

    def half_turn(rec: dict) -> None:
        if rec["variant"] == "same@wgpu":
            rec["camera_path"] = _orbit(turns=0.5)
        elif rec["variant"] == "yfov@wgpu":  # the same orbit: the same last frame
            rec["camera_path"] = _orbit()

    _rewrite(out, half_turn)
    done = warm_cli("bench", "report", str(out), "--reference", "orbit@wgpu", cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    assert _row(images, "| same@wgpu |")[2].startswith("different cameras: not compared")
    assert "![diff](images/yfov_wgpu.diff.png)" in _row(images, "| yfov@wgpu |")[2]


def test_static_cameras_compare_as_the_config_reads_them(tmp_path):
    # camera.yfov=45 and =45.0 are one camera (the config's parsing says so); 46 is another
    out = write_results(tmp_path / "b", {
        "a@wgpu": {"passes": {"p": 1.0}, "image": _image()},
        "b@wgpu": {"passes": {"p": 1.0}, "image": _other(90)},
        "c@wgpu": {"passes": {"p": 1.0}, "image": _other(80)}})
    yfov = {"a@wgpu": "45", "b@wgpu": "45.0", "c@wgpu": "46"}

    def settings(rec: dict) -> None:
        rec["config_path"] = str(ROOT / "configs" / "flat.toml")
        rec["settings"] = [f"camera.yfov={yfov[rec['variant']]}", "flat.ambient=0.2"]

    _rewrite(out, settings)
    done = warm_cli("bench", "report", str(out), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    assert "![diff](images/b_wgpu.diff.png)" in _row(images, "| b@wgpu |")[2]
    assert _row(images, "| c@wgpu |")[2] == (
        "different cameras: not compared (reference: static camera (yfov=45); this: static "
        "camera (yfov=46))")


def test_bench_vary_camera_path_through_the_cli(tmp_path):
    # the review's case, run for real: --vary camera.path=orbit,off; the static view is not
    # diffed against the orbit's last frame
    done = warm_cli("bench", "flat", "--vary", "camera.path=orbit,off", "--out", "b", "--diff-scale",
                    "shared", *TINY, cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "b"
    recs = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert [bool(r.get("camera_path")) for r in recs] == [True, False]
    images = _images_section((out / "report.md").read_text())
    off = _row(images, "| flat[camera.path=off]@wgpu |")
    assert off[2] == ("different cameras: not compared (reference: orbit path, last frame, "
                      "t=0.5; this: static camera)"), off
    assert not any(c.endswith("dB") for c in off)
    # negative control: the orbit (the reference) against itself is compared, on the
    # shared scale --diff-scale asked for
    orbit = _row(images, "| flat[camera.path=orbit]@wgpu |")
    assert "∞ (identical)" in orbit and "(shared; this image's max 0)" in orbit[2]
    # the same results with the static view as reference: the orbit is the one not compared
    done = warm_cli("bench", "report", "b", "--reference", "1", cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    assert _row(images, "| flat[camera.path=orbit]@wgpu |")[2].startswith(
        "different cameras: not compared (reference: static camera; this: orbit path")
    assert "no difference (max 0/255)" in _row(images, "| flat[camera.path=off]@wgpu |")[2]


def test_compare_does_not_diff_images_of_different_cameras(tmp_path):
    old = write_results(tmp_path / "old", {"d@wgpu": {"passes": {"p": 1.0}, "image": _image()},
                                           "e@wgpu": {"passes": {"p": 1.0}, "image": _image()}})
    new = write_results(tmp_path / "new", {
        "d@wgpu": {"passes": {"p": 1.0}, "image": _other(20)},
        "e@wgpu": {"passes": {"p": 1.0}, "image": _other(95)}})

    def orbit(rec: dict) -> None:
        if rec["variant"] == "d@wgpu":
            rec["settings"] = ["camera.path=orbit"]
            rec["camera_path"] = _orbit()

    _rewrite(new, orbit)
    # the settings differ: refused without --allow-mismatch, as before
    done = warm_cli("bench", "compare", str(old), str(new), "--out", "cmp", cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 2 and "settings" in done.stderr
    done = warm_cli("bench", "compare", str(old), str(new), "--out", "cmp", "--allow-mismatch",
                    cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (tmp_path / "cmp" / "compare.md").read_text()
    images = md.split("## Images")[1]
    assert "**Different cameras:**" in images
    d = _row(images, "| d@wgpu |")
    assert d[3:] == ["different cameras: not compared (OLD: static camera; NEW: orbit path, "
                     "last frame, t=0.95)", "not compared"], d
    assert not (tmp_path / "cmp" / "images" / "0_diff.png").exists()
    # negative control: the variant with the same camera is diffed, its scale stated
    e = _row(images, "| e@wgpu |")
    assert "![diff](images/1_diff.png)" in e[3] and "scale 0-5/255 (this image's max)" in e[3]
    assert e[4].endswith(" dB")
    assert relative_refs((tmp_path / "cmp" / "compare.html").read_text()) == []


# ---------------------------------------------------------------------------------------------
# 2. difference images on their own scales, or on one


def _max_pixel(path: Path, where=(3, 4)) -> tuple[int, ...]:
    return tuple(int(x) for x in np.asarray(Image.open(path).convert("RGB"))[where])


def test_each_difference_states_its_scale_and_shared_puts_them_on_one(tmp_path):
    # exposure 1.05 against 3: a 4-step and a 78-step change
    out = write_results(tmp_path / "b", {
        "ref@wgpu": {"passes": {"p": 1.0}, "image": _image()},
        "e105@wgpu": {"passes": {"p": 1.0}, "image": _other(104)},
        "e3@wgpu": {"passes": {"p": 1.0}, "image": _other(178)}})
    done = warm_cli("bench", "report", str(out), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    small, large = _row(images, "| e105@wgpu |")[2], _row(images, "| e3@wgpu |")[2]
    assert "scale 0-4/255 (this image's max)" in small, small
    assert "scale 0-78/255 (this image's max)" in large, large
    assert "each image has its own scale, stated below it" in images
    top = tuple(int(x) for x in colorize(np.array([[1.0]]))[0, 0])
    # own scales: both maxima take the map's top colour (what the review misread)
    assert _max_pixel(out / "images" / "e105_wgpu.diff.png") == top
    assert _max_pixel(out / "images" / "e3_wgpu.diff.png") == top
    own_legend = np.asarray(Image.open(out / "images" / "e105_wgpu.diff_legend.png"))
    done = warm_cli("bench", "report", str(out), "--diff-scale", "shared", cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 0, done.stderr
    images = _images_section((out / "report.md").read_text())
    small, large = _row(images, "| e105@wgpu |")[2], _row(images, "| e3@wgpu |")[2]
    assert "scale 0-78/255 (shared; this image's max 4)" in small, small
    assert "scale 0-78/255 (shared; this image's max 78)" in large, large
    assert "largest difference of all the report's images (`--diff-scale shared`" in images
    # one scale: the 4-step change is dark, the 78-step one the top colour
    assert _max_pixel(out / "images" / "e105_wgpu.diff.png") == tuple(
        int(x) for x in colorize(np.array([[4 / 78]]))[0, 0])
    assert _max_pixel(out / "images" / "e3_wgpu.diff.png") == top
    shared_legend = np.asarray(Image.open(out / "images" / "e105_wgpu.diff_legend.png"))
    assert own_legend.shape != shared_legend.shape or (own_legend != shared_legend).any()
    # compare takes the flag too
    new = write_results(tmp_path / "new", {
        "ref@wgpu": {"passes": {"p": 1.0}, "image": _other(104)},
        "e3@wgpu": {"passes": {"p": 1.0}, "image": _image()}})
    done = warm_cli("bench", "compare", str(out), str(new), "--out", "cmp", "--diff-scale", "shared",
                    cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    images = (tmp_path / "cmp" / "compare.md").read_text().split("## Images")[1]
    assert "scale 0-78/255 (shared; this image's max 4)" in _row(images, "| ref@wgpu |")[3]
    assert "scale 0-78/255 (shared; this image's max 78)" in _row(images, "| e3@wgpu |")[3]
    # a value that is not a scale: one line, exit 2
    done = warm_cli("bench", "report", str(out), "--diff-scale", "max", cwd=tmp_path, safe_path=True)
    assert done.returncode == 2 and "--diff-scale" in done.stderr
    assert "Traceback" not in done.stderr


# ---------------------------------------------------------------------------------------------
# 3. a Ray report's pointer to the per-device table


def test_ray_report_points_to_the_per_device_table_only_where_it_exists(tmp_path):
    two = ray_results(tmp_path / "two", executor="ray")  # new@wgpu ran on hosts a and b
    done = warm_cli("bench", "report", str(two), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (two / "report.md").read_text()
    how = md.split("## How this was measured")[1]
    assert "## Per device" in md
    assert 'compare the 2 devices in the per-device table ("Per device")' in how
    # negative control: every run on host a, one device: no table, and no pointer to one
    one = ray_results(tmp_path / "one", executor="ray")

    def host_a(rec: dict) -> None:
        rec["ray"]["host"] = "a"

    _rewrite(one, host_a)
    done = warm_cli("bench", "report", str(one), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (one / "report.md").read_text()
    how = md.split("## How this was measured")[1]
    assert "## Per device" not in md and "per-device table (" not in md
    assert ("all runs measured one device (synthetic @ a GPU 0), so there is no per-device "
            "table") in how
