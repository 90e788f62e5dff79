"""The fault corpus of ``rfw bench`` and of the commands without an output folder (issue 21,
item 10): a bench interrupted after its first run (SIGINT, SIGTERM, Ctrl-C to the whole
process group), before it, or while it starts; another writer while a bench holds
``--out``; special files, a full disk and a read-only folder as ``--out``; bad input after
a good bench. The earlier bench (a real one) must survive byte for byte, the interrupted
one's runs are kept in ``OUT/partial-<time>/`` without a report, and no worker process may
be left. Helpers and their negative controls: faults_util.py, test_faults.py.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from .faults_util import (
    BENCH_QUICK,
    FLAT,
    LOCK,
    QUICK,
    assert_kept,
    assert_refused,
    caught,
    changes,
    env_for,
    finish,
    full_tmpfs,
    kill_tree,
    leftovers,
    make_special,
    one_line,
    read_only,
    rfw,
    seed,
    signal_at,
    snapshot,
    staged_records,
    start,
    stopped,
    wait_for,
    workers,
)

# two configs, two repeats: four runs; the second config is flat under another name
FLAT_B = Path(FLAT).read_text().replace('name = "flat"', 'name = "flat_b"', 1)
BENCH2 = ["bench", "flat", "flat_b.toml", "--repeat", "2", *BENCH_QUICK]


@pytest.fixture(scope="session")
def env(tmp_path_factory) -> dict[str, str]:
    # home and caches shared by the session's rfw processes: a warm shader cache
    return env_for(tmp_path_factory.mktemp("faults-home"))


@pytest.fixture(scope="session")
def good_bench(tmp_path_factory, env) -> Path:
    """A real complete bench: runs/, results.jsonl, results.csv, report.md, report.html,
    images/, charts/."""
    out = tmp_path_factory.mktemp("faults-good-bench") / "bench"
    done = rfw(["bench", "flat", "--repeat", "1", *BENCH_QUICK, "--out", str(out)],
               out.parent, env)
    assert done.returncode == 0, done.stderr
    assert {"runs", "results.jsonl", "report.md", "report.html"} <= set(os.listdir(out))
    return out


def _root(tmp: Path) -> Path:
    (tmp / "flat_b.toml").write_text(FLAT_B)
    return tmp


def _outside_partial(out: Path) -> dict[str, tuple]:
    return {k: v for k, v in snapshot(out).items() if not k.startswith("partial-")}


def _waiting_for_a_worker(proc, out: Path) -> None:
    # a worker started and the bench waiting for it, not inside Popen: a signal while Popen
    # starts a worker is a race of its own (CPython does not end a child whose Popen() was
    # interrupted; the report of this corpus says more), left out here
    wait_for(proc, lambda: any("rfw.bench.worker" in w for w in workers(str(out))),
             "a worker")
    time.sleep(0.5)


# -- interrupted after the first run --------------------------------------------------------

SCENARIOS = {"INT": (signal.SIGINT, False, True), "TERM": (signal.SIGTERM, False, True),
             # a terminal's Ctrl-C reaches the workers too; here without an earlier bench
             "ctrl-c-group-new": (signal.SIGINT, True, False)}


@pytest.fixture(scope="module", params=SCENARIOS, ids=SCENARIOS)
def interrupted(request, tmp_path_factory, env, good_bench):
    sig, group, prev = SCENARIOS[request.param]
    root = _root(tmp_path_factory.mktemp(f"bench-{request.param}"))
    out = root / "out"
    before = seed(good_bench, out) if prev else {}
    proc = start([*BENCH2, "--out", str(out)], root, env, session=group)
    try:
        wait_for(proc, lambda: staged_records(out) >= 1, "the first run's record")
        _waiting_for_a_worker(proc, out)
        if group:
            os.killpg(proc.pid, sig)
        else:
            os.kill(proc.pid, sig)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    left = workers(str(out))
    partials = sorted(out.glob("partial-*"))
    kept = changes(before, _outside_partial(out))
    partial = snapshot(partials[0]) if len(partials) == 1 else {}
    report = rfw(["bench", "report", str(partials[0])], root, env) if partials else None
    return {"sig": sig, "prev": prev, "rc": rc, "err": err, "out": out, "before": before,
            "workers": left, "partials": partials, "kept": kept, "partial": partial,
            "report": report}


def test_bench_interrupted_one_line(interrupted):
    err = interrupted["err"]
    assert interrupted["rc"] == 128 + interrupted["sig"], err[-2000:]
    assert not one_line(err, "rfw: interrupted after 1 of 4 runs (kept in "), err[-2000:]
    assert f"{interrupted['partials'][0]}; earlier results untouched)" in err


def test_bench_interrupted_keeps_earlier_bench(interrupted):
    out = interrupted["out"]
    assert leftovers(out) == []
    assert len(interrupted["partials"]) == 1, os.listdir(out)
    if interrupted["prev"]:
        assert interrupted["kept"] == [], interrupted["kept"][:8]
    else:  # nothing but the partial folder
        assert os.listdir(out) == [interrupted["partials"][0].name]


def test_bench_interrupted_partial_folder(interrupted):
    names = set(interrupted["partial"])
    assert {"PARTIAL.txt", "results.jsonl", "runs/flat_wgpu/r0/record.json"} <= names, names
    assert not names & {"report.md", "report.html", "results.csv"}, names  # no whole report
    partial = interrupted["partials"][0]
    assert (partial / "PARTIAL.txt").read_text().startswith(
        "rfw bench interrupted after 1 of 4 runs")
    lines = (partial / "results.jsonl").read_text().splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["variant"] == "flat@wgpu"
    assert not json.loads(lines[0]).get("error")


def test_bench_interrupted_leaves_no_worker(interrupted):
    assert interrupted["workers"] == []


def test_bench_report_of_partial(interrupted):
    # what 'rfw bench report' does on the kept runs: a report of the one finished run
    done = interrupted["report"]
    assert done.returncode == 0, done.stderr
    assert (interrupted["partials"][0] / "report.md").is_file()
    if interrupted["prev"]:  # and the earlier bench is still untouched
        assert changes(interrupted["before"], _outside_partial(interrupted["out"])) == []


# -- interrupted before any run finished, another writer meanwhile -------------------------


@pytest.fixture(scope="module")
def before_first(tmp_path_factory, env, good_bench):
    root = _root(tmp_path_factory.mktemp("bench-before-first"))
    out = root / "out"
    before = seed(good_bench, out)
    proc = start([*BENCH2, "--out", str(out)], root, env)
    try:
        _waiting_for_a_worker(proc, out)
        with stopped(proc):
            assert staged_records(out) == 0
            second = rfw(["run", *QUICK, "--out", str(out)], root, env)
            os.kill(proc.pid, signal.SIGINT)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    return {"pid": proc.pid, "rc": rc, "err": err, "out": out, "before": before,
            "second": second, "workers": workers(str(out))}


def test_run_refused_while_bench_holds_out(before_first):
    assert_refused(before_first["second"], "--out", "in use by another rfw",
                   f"pid {before_first['pid']}: rfw bench")


def test_bench_interrupted_before_first_run(before_first):
    assert before_first["rc"] == 130, before_first["err"][-2000:]
    assert before_first["err"].strip() == \
        "rfw: interrupted after 0 of 4 runs; earlier results untouched"
    assert_kept(before_first["out"], before_first["before"])  # and no partial folder


def test_bench_interrupted_before_first_run_no_worker(before_first):
    assert before_first["workers"] == []


@pytest.mark.parametrize("moment", ["imports", "checks"])
def test_bench_signal_while_starting(tmp_path, env, good_bench, moment):
    root = _root(tmp_path)
    out = root / "out"
    before = seed(good_bench, out)
    proc = start([*BENCH2, "--out", str(out)], root, env)
    try:
        signal_at(proc, out, moment, signal.SIGINT)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    assert rc == 130, err[-2000:]
    assert not one_line(err, "rfw: interrupted"), one_line(err, "rfw: interrupted")
    assert_kept(out, before)


# -- commands without an output folder ------------------------------------------------------

OTHERS = {
    "plan-INT": (["graph", "plan", FLAT], signal.SIGINT),
    "plan-TERM": (["graph", "plan", FLAT], signal.SIGTERM),
    "plan-html-INT": (["graph", "plan", FLAT, "--html", "p.html"], signal.SIGINT),
    "scenes-list-INT": (["scenes", "list"], signal.SIGINT),
    "scenes-list-TERM": (["scenes", "list"], signal.SIGTERM),
    "dot-INT": (["graph", "dot", FLAT, "-o", "g.dot"], signal.SIGINT),
}


@pytest.mark.parametrize("argv,sig", OTHERS.values(), ids=OTHERS)
def test_other_command_interrupted(tmp_path, env, argv, sig):
    before = snapshot(tmp_path)
    proc = start(argv, tmp_path, env)
    try:
        # held still as soon as its handlers are in: the command cannot finish first
        wait_for(proc, lambda: signal.SIGTERM in caught(proc.pid), "rfw's signal handlers",
                 pause=0)
        with stopped(proc):
            os.kill(proc.pid, sig)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    assert rc == 128 + sig, f"exit {rc}: {err[-2000:]}"
    assert not one_line(err, "rfw: interrupted"), one_line(err, "rfw: interrupted")
    assert changes(before, snapshot(tmp_path)) == []  # no page, no DOT file, half or whole


# -- special files, a full disk, a read-only folder ---------------------------------------


@pytest.mark.parametrize("name,kind", [("report.md", "fifo"), ("results.jsonl", "fifo"),
                                       ("report.html", "socket")])
def test_bench_special_output(tmp_path, env, good_bench, name, kind):
    out = tmp_path / "out"
    seed(good_bench, out)
    (out / name).unlink()
    close = make_special(out / name, kind)
    try:
        before = snapshot(out)
        done = rfw(["bench", "flat", "--repeat", "1", *BENCH_QUICK, "--out", str(out)],
                   tmp_path, env)
        assert_refused(done, name, "not a regular file")
        assert_kept(out, before)
    finally:
        close()


def test_bench_disk_full(tmp_path, env, good_bench):
    def fill(root: Path) -> None:
        seed(good_bench, root / "out")

    with full_tmpfs(tmp_path / "mnt", fill, size_k=1024) as mnt:
        out = mnt / "out"
        before = snapshot(out)
        done = rfw(["bench", "flat", "--repeat", "1", *BENCH_QUICK, "--out", str(out)],
                   tmp_path, env)
        assert_refused(done, LOCK, "No space left on device")
        assert_kept(out, before)


def test_bench_read_only_out(tmp_path, env, good_bench):
    out = tmp_path / "out"
    seed(good_bench, out)
    with read_only(out):
        before = snapshot(out)
        done = rfw(["bench", "flat", "--repeat", "1", *BENCH_QUICK, "--out", str(out)],
                   tmp_path, env)
        assert_refused(done, "--out", "Read-only file system")
        assert_kept(out, before)


# -- bad input after a good bench, and a good one that replaces it --------------------------

B = ["flat", *BENCH_QUICK]
BAD_BENCH = [
    ("repeat-0", [*B, "--repeat", "0"], "--repeat"),
    ("config-unknown", ["nosuch_config", *BENCH_QUICK], "nosuch_config"),
    ("set-unknown", [*B, "--set", "nosuch=1"], "nosuch"),
    ("vary-unknown", [*B, "--vary", "flat.nosuch=1,2"], "nosuch"),
    ("reference-unknown", [*B, "--reference", "nosuch"], "--reference"),
    ("peers-unknown", [*B, "--peers", "nosuch"], "--peers"),
    ("scene-unknown", ["flat", *BENCH_QUICK[2:], "--scene", "nosuch_scene"], "nosuch_scene"),
    ("size-0x0", [*B, "--size", "0x0"], "--size"),
    ("frames-0", [*B, "--frames", "0"], "--frames"),
    ("yfov-900", [*B, "--set", "camera.yfov=900"], "camera.yfov"),
]


@pytest.mark.parametrize("argv,needle", [b[1:] for b in BAD_BENCH],
                         ids=[b[0] for b in BAD_BENCH])
def test_bad_input_after_good_bench(tmp_path, env, good_bench, argv, needle):
    out = tmp_path / "out"
    before = seed(good_bench, out)
    done = rfw(["bench", *argv, "--out", str(out)], tmp_path, env)
    assert_refused(done, needle)
    assert_kept(out, before)


def test_good_bench_replaces_the_earlier_one(tmp_path, env, good_bench):
    root = _root(tmp_path)
    out = root / "out"
    before = seed(good_bench, out)
    (out / "notes.txt").write_text("the user's own notes\n")
    done = rfw(["bench", "flat_b.toml", "--repeat", "1", *BENCH_QUICK, "--out", str(out)],
               root, env)
    assert done.returncode == 0, done.stderr
    assert leftovers(out) == []
    assert os.listdir(out / "runs") == ["flat_b_wgpu"]  # the earlier variant's runs are gone
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    assert [r["variant"] for r in records] == ["flat_b@wgpu"]
    after = snapshot(out)
    assert after["report.md"] != before["report.md"]
    assert "flat_b" in (out / "report.md").read_text()
    assert (out / "notes.txt").read_text() == "the user's own notes\n"
