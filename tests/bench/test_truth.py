"""``rfw bench --reference pathtrace[:COMPONENT][:SPP]``: the measures against the truth
(each with a case it must catch), the fronts and their dominance, and the whole bench at CI
size as a user runs it: references rendered once and reused from the cache, errors with CIs
beside GPU ms, the fronts drawn, the dominated configurations named, the columns in
results.csv and truth.csv, and the known orderings (more rt_ao rays, a larger shadow map)
coming out of the report."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from rfw.bench.truth import (
    Point,
    _resamples,
    _tiles,
    dominance,
    errors,
    family_of,
    front,
    mean_ci,
    parse,
    quantile_ci,
)
from rfw.errors import RfwError

from ..conftest import ray_method, rfw_cli

ROOT = Path(__file__).resolve().parents[2]


def test_the_reference_grammar_and_its_refusals():
    assert parse("deferred@vk") is None and parse("0") is None  # a variant, as before
    spec = parse("pathtrace")
    assert (spec.spp, spec.component, spec.reference_sets()) == (256, "full", [])
    spec = parse("pathtrace:ao=0.5:96")
    assert spec.spp == 96 and spec.reference_sets() == ["pt.mode=ao", "pt.ao_radius=0.5"]
    assert spec.per_frame * spec.frames == 96 and spec.per_frame <= 64
    assert parse("pathtrace:direct_centre:1").reference_sets()[-1] == "pt.jitter=false"
    for bad in ("pathtrace:0", "pathtrace:glow", "pathtrace:full=2", "pathtrace:ao=-1",
                "pathtrace:99999999"):
        with pytest.raises(RfwError, match="--reference"):
            parse(bad)


def test_a_bad_reference_is_refused_before_any_run(tmp_path):
    done = rfw_cli("bench", "rt_shadows@vk", "--reference", "pathtrace:ao=x", "--out",
                   tmp_path / "out", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert "pathtrace[:COMPONENT][:SPP]" in done.stderr
    assert not (tmp_path / "out").exists()
    ray = rfw_cli("bench", "rt_shadows@vk", "--reference", "pathtrace", "--executor", "ray",
                  "--out", tmp_path / "out", cwd=tmp_path)
    assert ray.returncode == 2 and "--executor local only" in ray.stderr, ray.stderr
    assert len(ray.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def noisy(shape=(64, 96), seed=1):
    rng = np.random.default_rng(seed)
    ref = np.ones((*shape, 4), np.float32)
    ref[..., :3] = rng.uniform(0.2, 2.0, (*shape, 3))
    return ref, rng


def test_errors_are_zero_for_the_truth_itself_and_grow_with_a_known_offset():
    ref, _rng = noisy()
    same = errors(ref, ref.copy(), None, None)
    assert same["rel_mse"]["value"] == 0.0 and same["rmse"]["value"] == 0.0
    assert same["hdr_flip"]["value"] < 1e-6
    brighter = ref.copy()
    brighter[..., :3] *= 1.1
    got = errors(ref, brighter, None, None)
    y = ref[..., :3]
    expected = float(np.mean((0.1 * y) ** 2 / (y * y + 0.01)))
    assert got["rel_mse"]["value"] == pytest.approx(expected, rel=1e-5)
    assert got["rel_mse"]["ci_lo"] <= got["rel_mse"]["value"] <= got["rel_mse"]["ci_hi"]
    assert got["hdr_flip"]["value"] > 0.01 and got["hdr_flip_p99"]["value"] \
        >= got["hdr_flip"]["value"]
    much = ref.copy()
    much[..., :3] *= 1.5  # more wrong is more error, on every measure
    worse = errors(ref, much, None, None)
    assert all(worse[m]["value"] > got[m]["value"]
               for m in ("rel_mse", "rmse", "hdr_flip", "hdr_flip_p99"))


def test_components_leave_out_what_they_do_not_judge():
    ref, _ = noisy()
    ref[:, :10, 3] = 0.0  # sky: rt_ao and SSAO leave it open, the AO truth has nothing there
    test = ref.copy()
    test[:, :10, :] = 7.0
    assert errors(ref, test, None, None, component="ao=1")["rmse"]["value"] == 0.0
    full = errors(ref, test, None, None)
    assert full["rmse"]["value"] > 1.0  # control: the full image counts the sky
    test[:, 20:, 0] += 0.2  # ao reads the first channel only
    assert errors(ref, test, None, None, component="ao=1")["rmse"]["value"] == \
        pytest.approx(0.2 * np.sqrt(76 / 86), rel=1e-4)


def test_tile_bootstrap_intervals_cover_the_mean_of_the_process():
    # 200 images of iid noise around 1: the 95% CI of the tile bootstrap holds the true
    # mean in about 95% of them; an interval of half the width would hold it far less
    tiles = _tiles(48, 48)
    counts = _resamples(int(tiles.max()) + 1, boots=400)
    rng = np.random.default_rng(3)
    hits = narrow = 0
    for _ in range(200):
        v = rng.exponential(1.0, 48 * 48)
        c = mean_ci(v, tiles, counts)
        hits += c["ci_lo"] <= 1.0 <= c["ci_hi"]
        half = (c["ci_hi"] - c["ci_lo"]) / 4
        narrow += c["value"] - half <= 1.0 <= c["value"] + half
    assert 0.88 <= hits / 200 <= 0.99, hits
    assert narrow / 200 < 0.75, narrow
    q = quantile_ci(rng.uniform(0, 1, 48 * 48), tiles, counts, 0.99)
    assert q["ci_lo"] <= 0.99 <= q["ci_hi"] and q["ci_hi"] - q["ci_lo"] < 0.05


def test_dominance_names_what_is_slower_and_worse_and_marks_what_the_cis_separate():
    pts = [Point("cheap", "a", 1.0, 0.9, 1.1, 0.30, 0.28, 0.32),
           Point("good", "b", 3.0, 2.9, 3.1, 0.10, 0.09, 0.11),
           Point("bad", "a", 3.5, 3.4, 3.6, 0.35, 0.33, 0.37),  # slower and worse than both
           Point("close", "b", 1.05, 0.9, 1.2, 0.31, 0.27, 0.35)]  # within cheap's noise
    dom = dominance(pts)
    assert dict(dom["bad"]) == {"cheap": True, "good": True, "close": True}
    assert dom["close"] == [("cheap", False)]  # by the medians only: the CIs overlap
    assert dom["cheap"] == [] and dom["good"] == []
    assert [p.label for p in front(pts)] == ["cheap", "good"]
    # without a CI on the GPU ms (too few samples) only the error can separate them
    few = [Point(p.label, p.family, p.ms, p.ms_lo, p.ms_hi, 0.2, 0.1, 0.3, ms_ci=False)
           for p in pts]
    assert not any(sure for by in dominance(few).values() for _, sure in by)


def test_families_are_the_variant_groups_without_the_swept_settings():
    rec = {"config_path": "/x/rt_shadows.toml", "varied": ["ao=ssao", "ssao.samples=8"],
           "requested_backend": "vk"}
    assert family_of(rec) == "rt_shadows[ao=ssao]@vk"
    assert family_of({**rec, "varied": ["ssao.samples=8"]}) == "rt_shadows@vk"


# ---------------------------------------------------------------- the bench at CI size

SIZE = ["--size", "256x144", "--frames", "2", "--warmup", "1", "--repeat", "1",
        "--no-progress"]


def bench(tmp_path: Path, name: str, *args: str) -> tuple[Path, dict[str, dict]]:
    out = tmp_path / name
    done = rfw_cli("bench", *args, *SIZE, "--out", out, cwd=tmp_path,
                   env={"RFW_CACHE_TRUTH": str(tmp_path / "cache")}, timeout=400)
    assert done.returncode == 0, done.stderr[-2000:]
    with open(out / "truth.csv", encoding="utf-8") as f:
        rows = {r["variant"]: r for r in csv.DictReader(f)}
    return out, rows


@pytest.fixture(scope="module")
def ao_bench(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("truth_ao")
    return (tmp, *bench(tmp, "ao", "rt_shadows@vk", "--vary", f"ao=off,ssao,{ray_method()}",
                        "--vary", "ssao.samples=4,16", "--vary", "rt_ao.samples=1,16",
                        "--reference", "pathtrace:ao:64"))


def test_the_ao_front_ranks_rays_and_names_what_is_dominated(ao_bench):
    _tmp, out, rows = ao_bench
    err = {k: float(r["rmse"]) for k, r in rows.items()}
    one, many = (f"rt_shadows[ao={ray_method()},rt_ao.samples={n}]@vk" for n in (1, 16))
    off = "rt_shadows[ao=off]@vk"
    assert set(rows) == {off, one, many, "rt_shadows[ao=ssao,ssao.samples=4]@vk",
                         "rt_shadows[ao=ssao,ssao.samples=16]@vk"}  # inert choices merged
    # 16 rays beat 1 ray and no AO at all beyond the error CIs; SSAO beats no AO
    assert float(rows[many]["rmse_ci_hi"]) < float(rows[one]["rmse_ci_lo"])
    assert float(rows[many]["rmse_ci_hi"]) < float(rows[off]["rmse_ci_lo"])
    assert err["rt_shadows[ao=ssao,ssao.samples=16]@vk"] < err[off]
    for r in rows.values():  # every error with its CI, every variant with its GPU ms
        assert float(r["rmse_ci_lo"]) <= float(r["rmse"]) <= float(r["rmse_ci_hi"])
        assert float(r["gpu_ms"]) > 0
    assert rows[many]["on_front"] == "1"
    assert any(r["dominated_by"] for r in rows.values())
    report = (out / "report.md").read_text()
    assert "## Error against the truth" in report and "charts/front_rmse.png" in report
    assert (out / "charts" / "front_rmse.png").stat().st_size > 10_000
    named = [k for k, r in rows.items() if r["dominated_by"]]
    assert all(f"**{k}** by" in report for k in named)
    with open(out / "results.csv", encoding="utf-8") as f:
        truth_rows = [r for r in csv.DictReader(f) if r["pass"] == "truth"]
    assert {r["metric"] for r in truth_rows} >= {"rmse", "rel_mse", "hdr_flip"}
    assert len({r["variant"] for r in truth_rows}) == 5
    truth = json.loads((out / "truth.json").read_text())
    (ref,) = truth["references"].values()  # one view: one reference for all five
    assert ref["source"] == "rendered" and ref["spp"] == 64 and ref["noise"]["rel_mse"] > 0


def test_a_second_bench_of_the_same_view_reuses_the_reference(ao_bench):
    tmp, _, rows = ao_bench
    out, again = bench(tmp, "again", "rt_shadows@vk", "--vary", "ao=off",
                       "--reference", "pathtrace:ao:64")
    (ref,) = json.loads((out / "truth.json").read_text())["references"].values()
    assert ref["source"] == "cache"
    off = "rt_shadows[ao=off]@vk"
    assert float(again[off]["rmse"]) == pytest.approx(float(rows[off]["rmse"]), abs=1e-6)


def test_larger_shadow_maps_and_ray_traced_shadows_order_the_direct_light_front(tmp_path):
    # the spheres under the sun: the courtyard's point lights have no shadow map, and their
    # unshadowed light would be most of a shadow map's error there
    _, rows = bench(tmp_path, "shadows", "rt_shadows@vk", "--scene", "spheres", "--vary",
                    f"shadows=shadow_map,{ray_method()}", "--vary", "shadow.resolution=128,2048",
                    "--set", "ao=off", "--reference", "pathtrace:direct_centre:1")
    err = {k.partition("[")[2].partition("]")[0]: float(r["rmse"]) for k, r in rows.items()}
    small, large = err["shadows=shadow_map,shadow.resolution=128"], \
        err["shadows=shadow_map,shadow.resolution=2048"]
    assert small > 1.3 * large and large > 1.3 * err[f"shadows={ray_method()}"], err


def test_anti_aliasing_is_judged_on_the_displayed_image_along_a_camera_path(tmp_path):
    out, rows = bench(tmp_path, "aa", "deferred_ssao_shadows@vk", "--scene", "spheres",
                      "--vary", "aa=none,fxaa,taa", "--set", "camera.path=orbit",
                      "--set", "camera.path.turns=0.05", "--frames", "4",
                      "--reference", "pathtrace:direct:16")
    none, fxaa, taa = (rows[f"deferred_ssao_shadows[aa={a}]@vk"] for a in ("none", "fxaa", "taa"))
    # FXAA changes only the displayed image: its linear image is the same as none's (the
    # control), its displayed one is not, and the front is drawn on the displayed FLIP
    assert fxaa["hdr_flip"] == none["hdr_flip"] and fxaa["flip"] != none["flip"]
    assert taa["hdr_flip"] != none["hdr_flip"]
    assert "charts/front_flip.png" in (out / "report.md").read_text()
    truth = json.loads((out / "truth.json").read_text())
    (ref,) = truth["references"].values()  # the path's last frame, for all three
    assert any(c.startswith("camera.position=") for c in ref["view"]["camera"])


def test_a_report_asked_for_a_truth_its_bench_never_rendered_is_one_line(ao_bench):
    tmp, out, _ = ao_bench
    (tmp / "bare").mkdir()
    (tmp / "bare" / "results.jsonl").write_bytes((out / "results.jsonl").read_bytes())
    done = rfw_cli("bench", "report", tmp / "bare", "--reference", "pathtrace:ao:64", cwd=tmp)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "no references" in done.stderr
    assert not (tmp / "bare" / "report.md").exists()
    # control: the bench's own folder with its truth.json reports (here without the
    # references' folders, so the truth section says what is missing and computes nothing)
    import shutil

    copy = tmp / "copy"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("reference"))
    again = rfw_cli("bench", "report", copy, "--reference", "pathtrace:ao:64", cwd=tmp)
    assert again.returncode == 0, again.stderr
    report = (copy / "report.md").read_text()
    assert "## Error against the truth" in report and "reference missing" in report
