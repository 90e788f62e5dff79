"""The API corpus (issue 21, item 6): every public callable of ``import rfw`` given bad
arguments raises an ``rfw.RfwError`` naming the argument, a TypeError where the type is
wrong (``rfw.RfwTypeError``) and a ValueError otherwise, from rfw's own code (the last
traceback frame is in rfw or vkext, not pathlib, difflib or numpy), and files that existed
before survive. Each group runs in a subprocess of its own (``corpus_harness.py``); the
valid calls of ``corpus.py`` (kind None) are the negative controls."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from .corpus import CASES

ROOT = Path(__file__).resolve().parents[2]
OWN = (str(ROOT / "rfw") + "/", str(ROOT / "vkext") + "/")
_runs: dict[str, dict] = {}


@pytest.fixture(scope="module")
def group_run(tmp_path_factory):
    def run(group: str) -> dict:
        if group not in _runs:
            tmp = tmp_path_factory.mktemp(group)
            done = subprocess.run([sys.executable, "-m", "tests.api.corpus_harness", group,
                                   str(tmp)], cwd=ROOT, capture_output=True, text=True,
                                  timeout=600, check=False)
            assert done.returncode == 0, done.stderr
            _runs[group] = json.loads(done.stdout.splitlines()[-1])
        return _runs[group]

    return run


@pytest.mark.parametrize(("group", "cid", "code", "kind", "needle"), CASES,
                         ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_api_case(group_run, group, cid, code, kind, needle):
    run = group_run(group)
    if "skip" in run:
        pytest.skip(run["skip"])
    got = run["cases"][cid]
    assert run["changed"] == []  # the config and shader the cases name are untouched
    if kind is None:  # the valid call works
        assert not got["raised"], got
        return
    assert got["raised"], f"{code} was accepted"
    assert got["rfw"], got  # an RfwError: the line rfw run would print
    assert got["value_error"]  # every RfwError is a ValueError...
    assert got["type_error"] == got["rfw_type"] == (kind == "type"), got  # ...some TypeErrors
    assert needle in got["message"], got["message"]
    assert "\n" not in got["message"]
    assert got["last_file"].startswith(OWN), got["last_file"]  # raised by rfw, not deep inside


def test_a_refused_save_leaves_the_saved_result(group_run):
    run = group_run("result")
    assert run["before"] and set(run["before"]) == {"flat.color.png", "timings.json"}
    assert run["after"] == run["before"]


def test_the_corpus_covers_every_public_callable():
    # every public name of import rfw that can be called with arguments has cases
    import rfw

    called = {name for *_, code, _, _ in CASES for name in dir(rfw)
              if f"rfw.{name}(" in code or f"rfw.{name}." in code}
    called |= {"Result"} if any(c[0] == "result" for c in CASES) else set()
    exceptions = {"RfwError", "RfwTypeError", "RfwValueError", "SettingsError"}
    no_args = {"available"}  # takes none
    base_only = {"Pass", "RenderPass", "Settings", "PassEntry"}  # checked through subclasses
    assert set(rfw.__all__) - exceptions - no_args - base_only <= called, \
        set(rfw.__all__) - called
    assert len(CASES) >= 60 and sum(c[3] is None for c in CASES) >= 10
