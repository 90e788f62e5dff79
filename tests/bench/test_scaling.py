"""benchmarks/bench_scaling.py: its scenes are what it says they are, its sweep measures every
pass at every point, and one failing point is reported without ending the sweep."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_scaling as bs  # noqa: E402


def outward(mesh) -> np.ndarray:
    """Per non-degenerate triangle: does its counter-clockwise normal point away from the
    sphere's centre?"""
    tri = mesh.positions[mesh.indices.reshape(-1, 3)].astype(np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    big = np.linalg.norm(n, axis=1) > 1e-9  # the poles' rows are degenerate
    return (np.einsum("ij,ij->i", n, tri.mean(axis=1)) > 0)[big]


@pytest.mark.parametrize("n", [2, 4, 16])
def test_sphere_has_4n2_outward_triangles_on_the_unit_sphere(n):
    mesh = bs.sphere(n)
    assert mesh.triangle_count == 4 * n * n
    assert int(mesh.indices.max()) < len(mesh.positions)
    assert np.allclose(np.linalg.norm(mesh.positions, axis=1), 1.0, atol=1e-6)
    assert np.array_equal(mesh.normals, mesh.positions)
    face = outward(mesh)
    assert face.size >= 4 * n * n - 4 * n and face.all()
    # negative control: the opposite winding is caught
    flipped = bs.sphere(n)
    flipped.indices = flipped.indices.reshape(-1, 3)[:, ::-1].reshape(-1).copy()
    assert not outward(flipped).any()


def test_grid_scene_copies_one_mesh_with_or_without_textures():
    on, off = bs.grid_scene(10, 4, True), bs.grid_scene(10, 4, False)
    for scene in (on, off):
        assert len(scene.meshes) == 1 and len(scene.instances) == 10
        assert scene.triangle_count == 10 * 64
        places = {tuple(i.transform[:3, 3]) for i in scene.instances}
        assert len(places) == 10  # no two copies in one place
    assert len(on.textures) == 3 and on.materials[0].base_color_texture == 0
    assert off.textures == [] and off.materials[0].base_color_texture is None


def test_points_vary_one_axis_at_a_time_around_the_base():
    grid = bs.GRIDS["full"]
    pts = bs.points(grid, list(bs.AXES))
    sizes = [len(grid["size"]), len(grid["instances"]), len(grid["n"]), 2]
    assert len(pts) == sum(sizes) - (len(sizes) - 1)  # the base point once
    base = [p for p in pts if len(p["axes"]) == len(bs.AXES)]
    assert len(base) == 1
    for axis in bs.AXES:
        mine = [p for p in pts if axis in p["axes"]]
        for p in mine:  # only this axis differs from the base
            differs = [k for k in bs.AXES if p[k] != grid["base"][k]]
            assert differs in ([], [axis])
    assert {p["size"] for p in pts} >= {(640, 360), (3840, 2160)}
    assert {p["instances"] for p in pts} >= {1, 100_000}


def test_budget_guess_scales_with_cost():
    done = [{**bs.GRIDS["reduced"]["base"], "process_s": 2.0}]
    big = {**done[0], "instances": 1000}
    assert bs._guess_s(done, done[0]) == 2.0
    assert bs.cost(big) > 4 * bs.cost(done[0])  # ten times the triangles
    assert bs._guess_s(done, big) == pytest.approx(2.0 * bs.cost(big) / bs.cost(done[0]))
    assert bs._guess_s([*done, {**big, "process_s": 3.0}], big) == 3.0  # the nearest
    assert bs._guess_s([], big) == 0.0


def test_a_tiny_sweep_end_to_end(tmp_path):
    """Two points (textures on and off) through the script as users run it."""
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_scaling.py"),
                           "--grid", "reduced", "--axes", "textures", "--frames", "2",
                           "--warmup", "0", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    data = json.loads((tmp_path / "scaling.json").read_text())
    assert data["grid_name"] == "reduced" and data["env"]["rfw_commit"]
    assert [p["textures"] for p in data["points"]] == [True, False]
    for p in data["points"]:
        assert p["triangles"] == p["instances"] * 4 * p["n"] ** 2
        for name in bs.SERIES:  # lavapipe has timestamps: every pass timed every frame
            gpu = p["passes"][name]["gpu_ms"]
            assert len(gpu) == 2 and all(v > 0 for v in gpu), (name, gpu)
        # the raw floors drew the surface rfw's floor pass drew: same pixels, same depth
        check = p["raw_depth_check"]
        assert check["coverage_floor"] > 0.01
        for mode in ("instanced", "draws"):
            assert check[f"coverage_{mode}"] == check["coverage_floor"]
            assert check[f"max_depth_diff_{mode}"] <= 1e-6
    text = (tmp_path / "scaling.md").read_text()
    assert "## textures" in text and "| on | 25,600 |" in text and "| off | 25,600 |" in text
    assert (tmp_path / "scaling_textures.png").stat().st_size > 1000
    assert (tmp_path / "scaling.toml").is_file()
    if shutil.which("nvidia-smi") is None:  # lavapipe: no GPU clocks to report
        assert f"GPU clocks: {bs.NO_CLOCKS}." in text
    else:  # a GPU machine reports them (the H200 run once failed on this line)
        assert "GPU clocks: " in text and "MHz" in text.split("GPU clocks: ")[1].split("\n")[0]


def test_clocks_line_where_nvidia_smi_answered():
    g = {"index": 0, "name": "H200", "sm_mhz": 1980, "mem_mhz": 3201, "max_sm_mhz": 1980}
    recs = [{"gpu_clocks": [g]}, {"gpu_clocks": [{**g, "sm_mhz": 1755}]}, {"error": "x"}]
    assert bs._clocks(recs).startswith("SM 1755-1980 MHz after the points' frames (max 1980")
    assert bs._clocks([{"gpu_clocks": None}]) == bs.NO_CLOCKS


def test_a_failing_point_is_an_error_record(tmp_path):
    spec = {"point": {**bs.GRIDS["reduced"]["base"], "size": [64, 36], "axes": ["size"]},
            "config": str(tmp_path / "missing.toml"), "backend": "vk", "frames": 1,
            "warmup": 0}
    rec = bs.run_worker(spec, 300)
    assert rec["error"].startswith("GraphError") or "missing.toml" in rec["error"], rec
    # positive control: the same spec with the graph there measures
    (tmp_path / "missing.toml").write_text(bs.GRAPH)
    rec = bs.run_worker(spec, 300)
    assert "error" not in rec, rec.get("error")
    assert rec["passes"]["gbuffer"]["gpu_ms_median"] is not None


def test_raw_floor_depth_moves_with_the_camera():
    """Negative control of the depth check above: a camera nudged by 1 % of the grid's size
    changes the raw floor's pixels."""
    import raw_floor

    scene = bs.grid_scene(4, 4, False)
    cam = scene.default_camera()
    vp = cam.projection(64 / 36) @ cam.view()
    nudge = np.eye(4, dtype=np.float32)
    nudge[0, 3] = 0.05
    transforms = np.stack([i.transform for i in scene.instances])
    a: dict = {}
    b: dict = {}
    raw_floor.measure(scene.meshes[0], transforms, vp, (64, 36), frames=1, warmup=0,
                      modes=("instanced",), depth_out=a)
    raw_floor.measure(scene.meshes[0], transforms, vp @ nudge, (64, 36), frames=1, warmup=0,
                      modes=("instanced",), depth_out=b)
    # the floor covers 11 % of the pixels, and the nudge moves the depth of all of them
    # (measured: 264 of the 2304 pixels; 11 change coverage)
    assert (a["instanced"] < 1).mean() > 0.01
    assert changed_share(a["instanced"], b["instanced"], over=1e-6) > 0.05
