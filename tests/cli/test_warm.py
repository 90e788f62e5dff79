"""The warm CLI the corpora run rfw through (tests/cli/warm.py) gives what a fresh process
gives: a traceback and exit 1 where rfw lets an exception out, nothing kept from one run to
the next, a timeout that kills the run only; and it starts fresh what would start unlike it.
(The whole bad-input corpus gave the same exit code, problems and last stderr line, case by
case, through either, when the warm one was made.)"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from ..conftest import rfw_cli
from .corpus_cases import PLUGIN_PY, WGSL, plugin_files
from .warm import same_start, warm_cli

BROKEN = PLUGIN_PY.replace("        ctx.dispatch(", "        1 / 0\n        ctx.dispatch(")


def _folder(tmp_path: Path) -> dict[str, str]:
    for rel, data in plugin_files(WGSL.encode(), None, BROKEN).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(data)
    # the plugin's site first, before what the environment puts on the path already (the
    # GPU machine's dependencies live on PYTHONPATH)
    path = [str(tmp_path / "site"), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(path)}


def test_a_traceback_is_a_fresh_processs_and_nothing_is_kept(tmp_path):
    env = _folder(tmp_path)
    argv = ("run", "c.toml", "--size", "32x18", "--frames", "1", "--out", "out")
    warm = warm_cli(*argv, cwd=tmp_path, environ=env)
    fresh = rfw_cli(*argv, cwd=tmp_path, environ=env, tree=True)
    for done in (warm, fresh):
        assert done.returncode == 1, done.stderr
        assert "Traceback" in done.stderr and "ZeroDivisionError" in done.stderr
    assert warm.stderr.splitlines()[-1] == fresh.stderr.splitlines()[-1]
    # the plugin registered its pass in the last child only: without it on the path the
    # next run does not know the pass
    env["PYTHONPATH"] = os.environ.get("PYTHONPATH", "")
    gone = warm_cli(*argv, cwd=tmp_path, environ=env)
    assert gone.returncode == 2 and "corpus_copy" in gone.stderr, gone.stderr


def test_a_timeout_kills_the_run_and_the_next_one_runs(tmp_path):
    with pytest.raises(subprocess.TimeoutExpired):
        warm_cli("run", "--size", "32x18", "--frames", "100000", "--out", "out",
                 cwd=tmp_path, environ=dict(os.environ), timeout=1)
    done = warm_cli("run", "--frames", "x", cwd=tmp_path, environ=dict(os.environ))
    assert done.returncode == 2 and "--frames" in done.stderr


def test_what_changes_a_start_starts_fresh():
    base = {"PATH": "/bin", "HOME": "/root", "PYTEST_CURRENT_TEST": "a"}
    assert same_start({**base, "HOME": "/elsewhere", "RFW_FRAMES_IN_FLIGHT": "2",
                       "PYTEST_CURRENT_TEST": "b", "PYTHONPATH": "site"}, base)
    assert not same_start({**base, "WGPU_DEBUG": "1"}, base)
    assert not same_start({"HOME": "/root"}, base)
