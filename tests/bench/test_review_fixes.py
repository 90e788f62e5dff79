"""Fixes from a review of ``rfw bench``, through the CLI in a subprocess: peers refuse a
camera they would not render, a bad ``--ray-address`` is refused before anything is printed,
``compare`` refuses runs measured differently unless told, and the Ray executor's report
says how its runs ran and splits a variant measured on several devices into one row per device."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from ..cli.warm import warm_cli
from .synthetic import record

ROOT = Path(__file__).resolve().parents[2]


def one_error_line(done: subprocess.CompletedProcess, *expected: str,
                   quiet: bool = True) -> str:
    """Exit 2, nothing on stdout (unless not ``quiet``: a report printed before the error),
    one ``rfw: error:`` line holding every ``expected``."""
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stdout + done.stderr
    assert not quiet or done.stdout == "", done.stdout
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    assert "Traceback" not in done.stderr
    for e in expected:
        assert e in lines[0], lines[0]
    return lines[0]


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ---------------------------------------------------------------------------------------------
# 1. peers render their default camera: a camera setting with --peers is refused


@pytest.mark.parametrize("camera", [["--set", "camera.path=orbit", "--set", "camera.yfov=20"],
                                    ["--set", "camera.yfov=20"],
                                    ["--vary", "camera.yfov=20,40"]])
def test_peers_with_a_camera_setting_are_refused(tmp_path, camera):
    done = warm_cli("bench", str(ROOT / "configs" / "flat.toml"), "--size", "32x18", "--frames", "2",
                    "--repeat", "1", "--peers", "moderngl", *camera, "--out", "X", cwd=tmp_path,
                    safe_path=True)
    key = camera[1].partition("=")[0]
    one_error_line(done, "--peers:", key, "default camera")
    assert listing(tmp_path) == []


def test_peer_camera_check_is_only_for_camera_keys_with_peers(tmp_path):
    # negative controls: a later check (--reference) is reached, so the camera one let
    # these through: a non-camera key with peers, a camera key without peers
    flat = str(ROOT / "configs" / "flat.toml")
    for args, later in (
            (["--peers", "moderngl", "--set", "flat.ambient=0.5"], "--reference 'nosuch'"),
            (["--set", "camera.yfov=20"], "--reference 'nosuch'"),
            (["--peers", "moderngl", "--set", "cameraman=1"], "no pass or variant 'cameraman'")):
        done = warm_cli("bench", flat, "--size", "32x18", *args, "--reference", "nosuch", "--out",
                        "X", cwd=tmp_path, safe_path=True)
        line = one_error_line(done, later)
        assert "--peers" not in line
    assert listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# 4. --ray-address syntax: checked while parsing, before the "rfw bench: N variant(s)" header


@pytest.mark.parametrize("address, expected", [
    ("localhost", "expected auto, HOST:PORT or ray://HOST:PORT, not 'localhost'"),
    ("127.0.0.1:99999", "not '127.0.0.1:99999'"),
    ("ray://:10001", "not 'ray://:10001'"),
    ("http://127.0.0.1:8265", "(the dashboard's http address is not the cluster's)"),
    ("https://head:8265", "(the dashboard's http address is not the cluster's)"),
])
def test_bad_ray_address_syntax_is_one_line_before_any_output(tmp_path, address, expected):
    done = warm_cli("bench", str(ROOT / "configs" / "flat.toml"), "--executor", "ray",
                    "--ray-address", address, "--out", "X", cwd=tmp_path, safe_path=True)
    one_error_line(done, "--ray-address", expected)
    assert listing(tmp_path) == []


def test_good_ray_address_syntax_passes_the_parser(tmp_path):
    # negative control: a well-formed address gets past the syntax check to the connection
    # check (nothing listens on port 1), still before anything is printed
    done = warm_cli("bench", str(ROOT / "configs" / "flat.toml"), "--executor", "ray",
                    "--ray-address", "ray://127.0.0.1:1", "--out", "X", cwd=tmp_path, safe_path=True)
    line = one_error_line(done, "nothing answers at 127.0.0.1:1")
    assert "expected auto" not in line
    assert listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# 3. compare: runs measured differently are refused unless --allow-mismatch


def write(folder: Path, **plan) -> Path:
    """Three runs of one variant, measured with ``plan`` (size, frames, settings, ...)."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = []
    for r in range(3):
        rec = record("flat@wgpu", r, {"flat": 1.0}, seed=r)
        rec.update({"settings": [], **plan})
        lines.append(json.dumps(rec) + "\n")
    (folder / "results.jsonl").write_text("".join(lines))
    return folder


@pytest.mark.parametrize("old, new, expected", [
    ({"size": [32, 18]}, {"size": [64, 36]}, "size 32x18 vs 64x36"),
    ({"frames": 20}, {"frames": 10, "warmup": 3}, "frames 20 vs 10; warmup 1 vs 3"),
    ({"scene": "courtyard"}, {"scene": "dragon"}, "scene courtyard vs dragon"),
    ({"settings": ["flat.ambient=0.1"]}, {"settings": ["flat.ambient=0.2"]},
     "settings [flat.ambient=0.1] vs [flat.ambient=0.2]"),
    # a local run against Ray tasks (side by side, on a node 'vm'): both differ
    ({}, {"executor": "ray", "ray": {"host": "vm", "gpu_ids": []}},
     "executor local vs ray; device synthetic vs synthetic @ vm"),
    ({"device": "GPU A"}, {"device": "GPU B"}, "device GPU A vs GPU B"),
    # Ray on the same node both times, but the tasks got other GPUs
    ({"executor": "ray", "ray": {"host": "vm", "gpu_ids": [0]}},
     {"executor": "ray", "ray": {"host": "vm", "gpu_ids": [1]}},
     "device synthetic @ vm GPU 0 vs synthetic @ vm GPU 1"),
])
def test_compare_refuses_runs_measured_differently(tmp_path, old, new, expected):
    a, b = write(tmp_path / "old", **old), write(tmp_path / "new", **new)
    before = listing(tmp_path)
    for extra in ([], ["--fail-on-regression"], ["--out", str(tmp_path / "cmp")]):
        done = warm_cli("bench", "compare", str(a), str(b), *extra, cwd=tmp_path, safe_path=True)
        one_error_line(done, "bench compare: flat@wgpu: measured differently: ", expected,
                       "--allow-mismatch")
        assert listing(tmp_path) == before  # no compare.md/html
    # allowed: compared, and every report says so at its top
    done = warm_cli("bench", "compare", str(a), str(b), "--allow-mismatch", "--out",
                    str(tmp_path / "cmp"), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == f"MISMATCH: flat@wgpu: measured differently: " \
        f"{expected}"
    md = (tmp_path / "cmp" / "compare.md").read_text()
    head = md.split("## Per pass")[0]
    assert "Mismatch: OLD and NEW were not measured the same way" in head
    assert f"flat@wgpu: measured differently: {expected}" in head
    assert "Mismatch" in (tmp_path / "cmp" / "compare.html").read_text()


def test_compare_of_runs_measured_alike_has_no_mismatch(tmp_path):
    # negative control: the same plan (settings in another order) is no mismatch
    a = write(tmp_path / "old", settings=["a.x=1", "b.y=2"])
    b = write(tmp_path / "new", settings=["b.y=2", "a.x=1"])
    done = warm_cli("bench", "compare", str(a), str(b), "--out", str(tmp_path / "cmp"), cwd=tmp_path,
                    safe_path=True)
    assert done.returncode == 0, done.stderr
    assert "MISMATCH" not in done.stdout
    assert "Mismatch" not in (tmp_path / "cmp" / "compare.md").read_text()
    # the same executor and device: Ray both times on one node's GPU 0, then local both times
    where = {"executor": "ray", "ray": {"host": "vm", "gpu_ids": [0]}}
    for plan in (where, {"device": "GPU A"}):
        a, b = write(tmp_path / "o2", **plan), write(tmp_path / "n2", **plan)
        done = warm_cli("bench", "compare", str(a), str(b), "--fail-on-regression", cwd=tmp_path,
                        safe_path=True)
        assert done.returncode == 0, done.stderr
        assert "MISMATCH" not in done.stdout and "measured differently" not in done.stdout


# ---------------------------------------------------------------------------------------------
# 5. the Ray executor's report: concurrency stated, one row per (variant, device)


def ray_results(folder: Path, *, executor: str | None) -> Path:
    """ref@wgpu on one host; new@wgpu 50 % slower, its runs split over two hosts."""
    import numpy as np
    from PIL import Image

    lines = []
    for r in range(4):
        for label, ms, hosts in (("ref@wgpu", 10.0, ("a",)), ("new@wgpu", 15.0, ("a", "b"))):
            rec = record(label, r, {"p": ms}, seed=r + len(label))
            rel = f"runs/{rec['variant_id']}/r{r}/image.png"
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.full((18, 32, 3), 100, np.uint8)).save(folder / rel)
            rec["image"] = rel
            if executor == "ray":
                rec["executor"] = "ray"
                rec["ray"] = {"node": "n", "host": hosts[r % len(hosts)], "gpu_ids": ["0"]}
                rec["ray_cluster"] = {"gpus": 2, "cpus": 16, "submitted": 8}
            lines.append(json.dumps(rec) + "\n")
    (folder / "results.jsonl").write_text("".join(lines))
    return folder


def table_row(md: str, prefix: str) -> list[str]:
    line = next(x for x in md.splitlines() if x.startswith(prefix))
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_ray_report_states_concurrency_and_splits_devices(tmp_path):
    out = ray_results(tmp_path / "ray", executor="ray")
    done = warm_cli("bench", "report", str(out), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (out / "report.md").read_text()
    how = md.split("## How this was measured")[1]
    assert "Runs went through Ray (`--executor ray`), concurrently: all 8 runs" in how
    assert "one GPU each, so up to 2 ran at the same time (cluster resources: 2 GPU, " \
        "16 CPU; 2 host(s))" in how
    assert "one after another" not in how
    # the variant that ran on two hosts has one row per host; one host: one row, no suffix
    frame = md.split("## Frame time per variant")[1].split("\n## ")[0]
    a, b = "synthetic @ a GPU 0", "synthetic @ b GPU 0"
    assert table_row(frame, f"| new@wgpu [{a}] |")[1] == a
    assert table_row(frame, f"| new@wgpu [{b}] |")[1] == b
    assert table_row(frame, "| ref@wgpu |")[1] == a
    assert "| new@wgpu |" not in frame and "mixed" not in md
    assert "## Per device" in md
    # +50 % on host a against the reference on host a: marked; host b has no reference run
    images = md.split("## Images")[1].split("\n## ")[0]
    on_a = table_row(images, f"| new@wgpu [{a}] |")[-1]
    assert on_a.endswith("% *") and abs(float(on_a[:-3]) - 50.0) < 2.0, on_a
    vs = table_row(images, f"| new@wgpu [{b}] |")[-1]
    assert vs.endswith(f"% (reference not run on {b}: no mark)"), vs
    assert "*" not in vs and "n.s." not in vs


def test_local_report_keeps_its_claims_and_marks(tmp_path):
    # negative control: the same numbers from the local runner: one process after another,
    # one device, so no split rows (no device suffix), and the +50 % gets its mark
    out = ray_results(tmp_path / "local", executor=None)
    done = warm_cli("bench", "report", str(out), cwd=tmp_path, safe_path=True)
    assert done.returncode == 0, done.stderr
    md = (out / "report.md").read_text()
    how = md.split("## How this was measured")[1]
    assert "one after another on this machine" in how and "Ray" not in how
    assert "mixed" not in md and "[synthetic" not in md and "## Per device" not in md
    assert table_row(md.split("## Images")[1], "| new@wgpu |")[-1] == "+50.0% *"


def test_peers_with_a_config_camera_are_refused(tmp_path):
    text = (ROOT / "configs" / "flat.toml").read_text()
    (tmp_path / "cam.toml").write_text(text.replace(
        'outputs = ["flat.color"]', 'outputs = ["flat.color"]\ncamera = { yfov = 20.0 }'))
    (tmp_path / "plain.toml").write_text(text)
    before = listing(tmp_path)
    done = warm_cli("bench", "cam.toml", "--size", "32x18", "--peers", "moderngl", "--out", "X",
                    cwd=tmp_path, safe_path=True)
    one_error_line(done, f"{tmp_path / 'cam.toml'}: --peers: ", "[camera]")
    # negative controls: the camera table is accepted without peers, and the same config
    # without it is accepted with peers (both reach the later --reference check)
    for args in (["cam.toml"], ["plain.toml", "--peers", "moderngl"]):
        done = warm_cli("bench", *args, "--size", "32x18", "--reference", "nosuch", "--out", "X",
                        cwd=tmp_path, safe_path=True)
        line = one_error_line(done, "--reference 'nosuch'")
        assert "--peers" not in line
    assert listing(tmp_path) == before
