"""``rfw bench compare``: regressions beyond the noise are flagged, noise is not."""

from __future__ import annotations

from rfw.bench.compare import changes
from rfw.bench.runner import load_results
from rfw.cli import main

from .synthetic import results

BASE = {"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.0, "tonemap": 0.5}}


def test_regression_flagged_and_exit_code(tmp_path, capsys):
    old = results(tmp_path / "old", BASE, seed=1)
    slower = {"deferred@wgpu": {"gbuffer": 10.0, "lighting": 2.6, "tonemap": 0.5}}
    new = results(tmp_path / "new", slower, seed=2)
    found, notes = changes(load_results(old), load_results(new))
    verdicts = {(c.what, c.metric): c.verdict(0.05) for c in found}
    assert verdicts[("lighting", "gpu_ms")] == "regression"
    assert verdicts[("gbuffer", "gpu_ms")] == "same"
    assert verdicts[("tonemap", "gpu_ms")] == "same"
    assert not notes
    assert main(["bench", "compare", str(old), str(new)]) == 0  # report only by default
    assert main(["bench", "compare", str(old), str(new), "--fail-on-regression"]) == 1
    out = capsys.readouterr().out
    assert "deferred@wgpu lighting.gpu_ms" in out and "regression" in out


def test_noise_and_small_changes_not_flagged(tmp_path):
    old = results(tmp_path / "old", BASE, seed=1, noise=0.05)
    new = results(tmp_path / "new", BASE, seed=2, noise=0.05)  # same means, other noise
    assert main(["bench", "compare", str(old), str(new), "--fail-on-regression"]) == 0
    # a clear but small change: CIs apart, yet under a 10% threshold
    faster = {"deferred@wgpu": {"gbuffer": 9.7, "lighting": 2.0, "tonemap": 0.5}}
    tight_old = results(tmp_path / "a", BASE, seed=3, noise=0.001)
    tight_new = results(tmp_path / "b", faster, seed=4, noise=0.001)
    found, _ = changes(load_results(tight_old), load_results(tight_new))
    g = next(c for c in found if (c.what, c.metric) == ("gbuffer", "gpu_ms"))
    assert not g.overlap and g.verdict(0.10) == "same" and g.verdict(0.02) == "improvement"


def test_compare_notes_variants_in_one_set_only(tmp_path, capsys):
    old = results(tmp_path / "old", BASE)
    new = results(tmp_path / "new", {**BASE, "forward@wgpu": {"forward": 5.0}})
    assert main(["bench", "compare", str(old), str(new)]) == 0
    assert "forward@wgpu: only in NEW" in capsys.readouterr().out


def test_compare_missing_results_fails_naming_the_file(tmp_path, capsys):
    assert main(["bench", "compare", str(tmp_path / "nope"), str(tmp_path)]) == 2
    assert "nope" in capsys.readouterr().err
