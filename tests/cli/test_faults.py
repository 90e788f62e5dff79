"""The fault corpus of ``rfw run`` (issue 21, item 10): rfw as a scripted subprocess under
signals at several moments, two writers on one folder, special files as outputs, a full
file system, a read-only ``--out`` and bad input after a good run. Each case starts from
the real output of an earlier good run and asserts that it survives byte for byte
(content, inode and mtime of every file; special files by kind, never opened) with no
staging folder or lock info left, or, for a run that succeeds, that it replaces exactly
what it should.

Moments are seen, not guessed: "imports" is rfw's own imports under way (its TOML
extension module mapped, main() not yet started), "checks" is main()'s signal handlers
installed (SIGTERM in /proc/PID/status SigCgt) before the lock is taken, "staging" the
staging folder there, "frames" two frame images saved into it. The process is held with
SIGSTOP while the moment is checked and the signal sent, so the signal lands there.
The bench's faults are in test_faults_bench.py; the judges' negative controls are the
test_control_* cases at the end of this file.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .corpus_cases import PLUGIN_ENV, WGSL, plugin_files
from .faults_util import (
    FLAT,
    LOCK,
    LONG,
    MOMENTS,
    QUICK,
    assert_kept,
    assert_refused,
    caught,
    changes,
    env_for,
    file_size_limit,
    finish,
    full_tmpfs,
    kill_tree,
    leftovers,
    make_special,
    mapped,
    one_line,
    read_only,
    rfw,
    seed,
    signal_at,
    snapshot,
    staged_frames,
    staging_dirs,
    start,
    stopped,
    wait_for,
    workers,
)


@pytest.fixture(scope="session")
def env(tmp_path_factory) -> dict[str, str]:
    # home and caches shared by the session's rfw processes: a warm shader cache
    return env_for(tmp_path_factory.mktemp("faults-home"))


@pytest.fixture(scope="session")
def good(tmp_path_factory, env) -> Path:
    """A real good run's output: flat.color.png, timings.json (3 frames) and frames/ with
    flat.color.0000-0002.png."""
    out = tmp_path_factory.mktemp("faults-good") / "out"
    done = rfw(["run", *QUICK[:-1], "3", "--save-every", "1", "--out", str(out)], out.parent,
               env)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (out / "frames").iterdir()) == \
        [f"flat.color.000{k}.png" for k in range(3)]
    return out


def _frames(timings: Path) -> int:
    return json.loads(timings.read_text())["frames"]


# -- 1. signals at several moments of rfw run ----------------------------------------------

SIGNALS = [signal.SIGINT, signal.SIGTERM]


@pytest.mark.parametrize("prev", ["previous", "none"])
@pytest.mark.parametrize("sig", SIGNALS, ids=["INT", "TERM"])
@pytest.mark.parametrize("moment", MOMENTS)
def test_run_signal(tmp_path, env, good, moment, sig, prev):
    out = tmp_path / "out"
    before = seed(good, out) if prev == "previous" else {}
    proc = start(["run", *LONG, "--out", str(out)], tmp_path, env)
    try:
        signal_at(proc, out, moment, sig)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    assert rc == 128 + sig, f"exit {rc}: {err[-2000:]}"
    assert not one_line(err, "rfw: interrupted"), one_line(err, "rfw: interrupted")
    if prev == "previous":
        assert_kept(out, before)
    else:  # the folder it created is gone again (or at least empty)
        assert not out.exists() or not any(out.iterdir()), sorted(os.listdir(out))


def test_run_second_signal_during_cleanup(tmp_path, env, good):
    # two Ctrl-C in a row: the second ends the process at once, the same one line
    out = tmp_path / "out"
    before = seed(good, out)
    proc = start(["run", *LONG, "--out", str(out)], tmp_path, env)
    try:
        wait_for(proc, lambda: staged_frames(out) >= 2, "two staged frames", pause=0.01)
        with stopped(proc):
            os.kill(proc.pid, signal.SIGINT)
        time.sleep(0.001)
        os.kill(proc.pid, signal.SIGINT)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    assert rc == 130, err[-2000:]
    assert not one_line(err, "rfw: interrupted"), one_line(err, "rfw: interrupted")
    # the second signal may cut the cleanup short: the earlier results are intact anyway
    changed = changes(before, snapshot(out))
    assert [c for c in changed if not c.startswith(".rfw-")] == [], changed


def test_run_ctrl_c_reaches_the_whole_group(tmp_path, env, good):
    # a terminal's Ctrl-C: SIGINT to every process of the foreground group
    out = tmp_path / "out"
    before = seed(good, out)
    proc = start(["run", *LONG, "--out", str(out)], tmp_path, env, session=True)
    try:
        wait_for(proc, lambda: staged_frames(out) >= 2, "two staged frames", pause=0.01)
        os.killpg(proc.pid, signal.SIGINT)
        rc, _, err = finish(proc)
    finally:
        kill_tree(proc)
    assert rc == 130, err[-2000:]
    assert not one_line(err, "rfw: interrupted"), one_line(err, "rfw: interrupted")
    assert_kept(out, before)


def test_run_sigkill_then_next_run_cleans_up(tmp_path, env, good):
    # SIGKILL cannot be handled: its staging folder and lock info stay, and the next run
    # (which holds the lock, so knows they are stale) removes them and succeeds
    out = tmp_path / "out"
    seed(good, out)
    proc = start(["run", *LONG, "--out", str(out)], tmp_path, env)
    try:
        wait_for(proc, lambda: staged_frames(out) >= 2, "two staged frames", pause=0.01)
        proc.kill()
        finish(proc)
    finally:
        kill_tree(proc)
    stale = staging_dirs(out)
    assert len(stale) == 1 and (out / LOCK).exists(), leftovers(out)
    assert f"pid {proc.pid}:" in (out / LOCK).read_text()
    assert (out / "timings.json").read_bytes() == (good / "timings.json").read_bytes()
    done = rfw(["run", *QUICK, "--out", str(out)], tmp_path, env)
    assert done.returncode == 0, done.stderr
    assert leftovers(out) == [], leftovers(out)
    assert _frames(out / "timings.json") == 1


# -- 3. two writers -------------------------------------------------------------------------

HOLDER = [FLAT, "--scene", "stress:1", "--size", "64x36", "--frames", "300",
          "--save-every", "100"]


@pytest.fixture(scope="module")
def two_writers(tmp_path_factory, env, good):
    """A run holding --out (stopped while it holds the lock), three more rfw run through
    three spellings of the folder and one rfw bench tried meanwhile, then the first let go."""
    root = tmp_path_factory.mktemp("two-writers")
    out = root / "out"
    seed(good, out)
    (root / "link").symlink_to(out)
    first = start(["run", *HOLDER, "--out", str(out)], root, env)
    tried = {}
    try:
        wait_for(first, lambda: f"pid {first.pid}:" in _read(out / LOCK), "the lock")
        with stopped(first):
            for name, where in (("same", str(out)), ("dot", f"{out}/./"),
                                ("link", "link")):
                tried[name] = rfw(["run", *QUICK, "--out", where], root, env)
            tried["bench"] = rfw(["bench", "flat", "--scene", "stress:1", "--size", "32x18",
                                  "--frames", "1", "--warmup", "0", "--repeat", "1",
                                  "--no-progress", "--out", str(out)], root, env)
            during = snapshot(out)
        rc, _, err = finish(first)
    finally:
        kill_tree(first)
    return {"pid": first.pid, "tried": tried, "rc": rc, "err": err, "out": out,
            "during": during}


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except OSError:
        return ""


@pytest.mark.parametrize("name", ["same", "dot", "link", "bench"])
def test_second_writer_refused(two_writers, name):
    line = assert_refused(two_writers["tried"][name], "--out", "in use by another rfw",
                          f"pid {two_writers['pid']}: rfw run")
    assert "wait for it or choose another folder" in line


def test_second_writers_wrote_nothing(two_writers):
    # meanwhile only the holder's own staging folder and lock info are in the folder
    extra = [k for k in two_writers["during"] if k.split("/")[0].startswith(".rfw-")]
    assert {k.split("/")[0] for k in extra} <= {LOCK, f".rfw-staging-{two_writers['pid']}"}


def test_refused_writers_keep_the_holders_lock_info(two_writers):
    # a refused writer must not remove what says who holds the folder
    assert LOCK in two_writers["during"], sorted(two_writers["during"])


def test_first_writer_finishes_right(two_writers):
    out = two_writers["out"]
    assert two_writers["rc"] == 0, two_writers["err"]
    assert leftovers(out) == []
    assert _frames(out / "timings.json") == 300
    assert json.loads((out / "timings.json").read_text())["size"] == [64, 36]
    from PIL import Image

    assert Image.open(out / "flat.color.png").size == (64, 36)
    assert sorted(p.name for p in (out / "frames").iterdir()) == \
        [f"flat.color.{k:04d}.png" for k in (0, 100, 200, 299)]


def test_two_writers_into_two_folders_both_work(tmp_path, env):
    # the control: the lock is per folder, two runs side by side are fine
    procs = [start(["run", *QUICK, "--out", str(tmp_path / f"o{k}")], tmp_path, env)
             for k in range(2)]
    try:
        results = [finish(p) for p in procs]
    finally:
        for p in procs:
            kill_tree(p)
    for k, (rc, _, err) in enumerate(results):
        assert rc == 0, err
        assert sorted(os.listdir(tmp_path / f"o{k}")) == ["flat.color.png", "timings.json"]


# -- 4. special files as outputs ------------------------------------------------------------

SPECIAL_RUN = [
    ("flat.color.png", "fifo"), ("flat.color.png", "socket"), ("flat.color.png", "chardev"),
    ("flat.color.png", "folder"), ("flat.color.png", "link-dev-full"),
    ("timings.json", "fifo"), ("timings.json", "socket"), ("timings.json", "folder"),
    ("flat.color.exr", "fifo"),
    ("frames/flat.color.0000.png", "fifo"),
]


@pytest.mark.parametrize("name,kind", SPECIAL_RUN, ids=[f"{n}-{k}" for n, k in SPECIAL_RUN])
def test_run_special_output(tmp_path, env, good, name, kind):
    out = tmp_path / "out"
    seed(good, out)
    path = out / name
    if path.exists():
        path.unlink()
    close = make_special(path, kind)
    try:
        before = snapshot(out)
        done = rfw(["run", *QUICK, "--save-every", "1", "--out", str(out)], tmp_path, env)
        why = "outside the output folder" if kind.startswith("link") else "not a regular file"
        assert_refused(done, name.rpartition("/")[2], why)
        assert_kept(out, before)  # still the FIFO, socket, device or folder it was
    finally:
        close()


def test_run_frames_is_a_file(tmp_path, env, good):
    out = tmp_path / "out"
    seed(good, out)
    shutil.rmtree(out / "frames")
    (out / "frames").write_bytes(b"a file of the user's, not a folder\n")
    before = snapshot(out)
    done = rfw(["run", *QUICK, "--save-every", "1", "--out", str(out)], tmp_path, env)
    assert_refused(done, "frames", "not a folder")
    assert_kept(out, before)


def test_run_out_is_a_fifo(tmp_path, env):
    os.mkfifo(tmp_path / "out")
    before = snapshot(tmp_path)
    done = rfw(["run", *QUICK, "--out", "out"], tmp_path, env)
    assert_refused(done, "out", "--out")
    assert changes(before, snapshot(tmp_path)) == []


RAPTOR = str(Path(__file__).resolve().parents[1] / "data" / "raptor" / "chapter4_graph.json")
SPECIAL_OTHER = [
    # (command before the path, element, the path's kind)
    (["graph", "plan", FLAT, "--html"], "--html", "dev-full"),
    (["graph", "plan", FLAT, "--html"], "--html", "dev-null"),
    (["graph", "plan", FLAT, "--html"], "--html", "fifo"),
    (["graph", "plan", FLAT, "--html"], "--html", "socket"),
    (["graph", "plan", FLAT, "--html"], "--html", "folder"),
    (["graph", "dot", RAPTOR, "-o"], "-o", "dev-full"),
    (["graph", "dot", RAPTOR, "-o"], "-o", "fifo"),
    (["graph", "dot", RAPTOR, "-o"], "-o", "socket"),
    (["graph", "dot", RAPTOR, "-o"], "-o", "folder"),
    (["graph", "dot", RAPTOR, "-o"], "-o", "svg-fifo"),  # g.dot's g.svg
    (["graph", "convert", RAPTOR, "-o"], "-o", "dev-full"),
    (["graph", "convert", RAPTOR, "-o"], "-o", "fifo"),
    (["graph", "convert", RAPTOR, "-o"], "-o", "socket"),
    (["graph", "convert", RAPTOR, "-o"], "-o", "folder"),
    (["view", FLAT, "--frames", "1", "--screenshot"], "--screenshot", "dev-full"),
    (["view", FLAT, "--frames", "1", "--screenshot"], "--screenshot", "fifo"),
    (["view", FLAT, "--frames", "1", "--screenshot"], "--screenshot", "socket"),
]


@pytest.mark.parametrize("argv,element,kind", SPECIAL_OTHER,
                         ids=[f"{a[0]}-{a[1] if a[0] == 'graph' else 'shot'}-{k}"
                              for a, _, k in SPECIAL_OTHER])
def test_other_special_output(tmp_path, env, argv, element, kind):
    close = lambda: None  # noqa: E731
    if kind in ("dev-full", "dev-null"):
        target = f"/dev/{kind[4:]}"
        dev = os.stat(target)
    elif kind == "svg-fifo":
        os.mkfifo(tmp_path / "g.svg")
        target = "g.dot"
    else:  # the suffix each command expects
        target = "x" + {"plan": ".html", "dot": ".dot", "convert": ".toml"}.get(argv[1], ".png")
        close = make_special(tmp_path / target, kind)
    try:
        before = snapshot(tmp_path)
        done = rfw([*argv, target], tmp_path, env)
        assert_refused(done, element, "not a regular file")
        assert changes(before, snapshot(tmp_path)) == []  # nothing written, still special
        if kind in ("dev-full", "dev-null"):
            now = os.stat(target)
            assert (now.st_mode, now.st_rdev, now.st_ino) == \
                (dev.st_mode, dev.st_rdev, dev.st_ino)
    finally:
        close()


# -- 5. a full file system ------------------------------------------------------------------

# pages of 4 KiB left: none (the lock info cannot be written), then room for it, for the
# lock and the first frame, for those and the image: each time the next file fails
FULL = [(0, ".rfw-lock"), (1, "flat.color.0000.png"), (2, "flat.color.png"),
        (3, "timings.json")]


@pytest.mark.parametrize("free,fails", FULL, ids=[f"free{f}" for f, _ in FULL])
def test_run_disk_full(tmp_path, env, good, free, fails):
    def fill(root: Path) -> None:
        shutil.copytree(good, root / "out", copy_function=shutil.copy2)

    with full_tmpfs(tmp_path / "mnt", fill, free_pages=free) as mnt:
        out = mnt / "out"
        before = snapshot(out)
        done = rfw(["run", *QUICK, "--save-every", "1", "--out", str(out)], tmp_path, env)
        assert_refused(done, fails, "No space left on device")
        assert_kept(out, before)


def test_disk_full_control(tmp_path):
    # the fault is real: not one more byte fits, and with a page free one page does
    with full_tmpfs(tmp_path / "a", lambda root: None) as mnt, \
            pytest.raises(OSError, match="No space left"):
        (mnt / "more").write_bytes(b"x")
    with full_tmpfs(tmp_path / "b", lambda root: None, free_pages=1) as mnt:
        (mnt / "more").write_bytes(b"x" * 4096)


# --html draws the DAG with graphviz dot (the GPU machine has none; CI installs it)
NEEDS_DOT = pytest.mark.skipif(shutil.which("dot") is None, reason="graphviz dot draws the DAG")


@pytest.mark.parametrize("argv,name", [
    pytest.param(["graph", "plan", FLAT, "--html", "old.html"], "old.html", marks=NEEDS_DOT),
    (["graph", "dot", RAPTOR, "-o", "old.dot"], "old.dot"),
    (["graph", "convert", RAPTOR, "-o", "old.toml"], "old.toml"),
], ids=["plan-html", "dot", "convert"])
def test_file_too_large_keeps_the_old_file(tmp_path, env, argv, name):
    # RLIMIT_FSIZE: a write past 1 KiB fails (EFBIG); the old file stays, no temporary left
    (tmp_path / name).write_bytes(b"an earlier, good file\n")
    before = snapshot(tmp_path)
    done = rfw(argv, tmp_path, env, preexec_fn=file_size_limit(1024))
    assert_refused(done, name, "File too large")
    assert changes(before, snapshot(tmp_path)) == []


def test_run_file_too_large_at_the_lock(tmp_path, env, good):
    out = tmp_path / "out"
    before = seed(good, out)
    done = rfw(["run", *QUICK, "--out", str(out)], tmp_path, env,
               preexec_fn=file_size_limit(16))
    assert_refused(done, ".rfw-lock", "File too large")
    assert_kept(out, before)


# -- 6. a read-only --out -------------------------------------------------------------------


def test_run_read_only_out(tmp_path, env, good):
    out = tmp_path / "out"
    seed(good, out)
    with read_only(out):
        before = snapshot(out)
        done = rfw(["run", *QUICK, "--out", str(out)], tmp_path, env)
        assert_refused(done, "--out", "Read-only file system")
        assert_kept(out, before)


def test_run_read_only_parent(tmp_path, env):
    (tmp_path / "ro").mkdir()
    with read_only(tmp_path / "ro"):
        done = rfw(["run", *QUICK, "--out", "ro/new"], tmp_path, env)
        assert_refused(done, "ro/new", "Read-only file system")
        assert not (tmp_path / "ro" / "new").exists()


@NEEDS_DOT
def test_plan_html_read_only(tmp_path, env):
    (tmp_path / "ro").mkdir()
    (tmp_path / "ro" / "plan.html").write_bytes(b"an earlier page\n")
    with read_only(tmp_path / "ro"):
        before = snapshot(tmp_path / "ro")
        done = rfw(["graph", "plan", FLAT, "--html", "ro/plan.html"], tmp_path, env)
        assert_refused(done, "ro/plan.html", "Read-only file system")
        assert changes(before, snapshot(tmp_path / "ro")) == []


def test_read_only_control(tmp_path):
    (tmp_path / "ro").mkdir()
    with read_only(tmp_path / "ro") as ro, pytest.raises(OSError, match="Read-only"):
        (ro / "x").write_bytes(b"x")
    (tmp_path / "ro" / "x").write_bytes(b"x")  # and writable again after


# -- 7. bad input after a good run ----------------------------------------------------------

Q = QUICK
BAD_CONFIG = 'name = "x"\nscene = "default"\nsize = [32, 18]\noutputs = ["flat.color"]\n' \
    '[[pass]]\nname = "nosuchpass"\n'
BAD = [
    ("yfov-900", [*Q, "--set", "camera.yfov=900"], "camera.yfov"),
    ("save-every-0", [*Q, "--save-every", "0"], "--save-every"),
    ("backend-nosuch", [*Q, "--backend", "nosuch"], "--backend"),
    ("backend-empty", [*Q, "--backend", ""], "--backend"),
    ("exr-no-float", [*Q, "--exr"], "--exr"),
    ("camera-gltf-9", [*Q, "--set", "camera.gltf=9"], "camera.gltf"),
    ("scene-unknown", [FLAT, "--size", "32x18", "--scene", "nosuch_scene"], "--scene"),
    ("scene-empty", [FLAT, "--size", "32x18", "--scene", ""], "--scene"),
    ("scene-broken", [FLAT, "--size", "32x18", "--scene", "broken.gltf"], "broken.gltf"),
    ("scene-missing", [FLAT, "--size", "32x18", "--scene", "missing.obj"], "missing.obj"),
    ("stress-0", [FLAT, "--size", "32x18", "--scene", "stress:0"], "stress:0"),
    ("unknown-pass", ["unknown.toml"], "nosuchpass"),
    ("missing-config", ["missing.toml"], "missing.toml"),
    ("toml-syntax", ["syntax.toml"], "syntax.toml"),
    ("size-0x5", [*Q, "--size", "0x5"], "--size"),
    ("frames-0", [*Q, "--frames", "0"], "--frames"),
    ("set-unknown", [*Q, "--set", "nosuch=1"], "nosuch"),
    ("setting-unknown", [*Q, "--set", "flat.nosuch=1"], "nosuch"),
    ("set-size-0", [*Q, "--set", "size=0x0"], "size"),
    ("position-1e39", [*Q, "--set", "camera.position=1e39,0,0"], "camera.position"),
    ("position-1e30", [*Q, "--set", "camera.position=1e30,0,0"], "camera.position"),
    ("validate-wgpu", [*Q, "--validate"], "--validate"),
    ("order-seed-wgpu", [*Q, "--order-seed", "3"], "--order-seed"),
    ("output-unknown", ["outputs.toml", *Q[1:]], "flat.nosuch"),
]


@pytest.mark.parametrize("argv,needle", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_after_good_run(tmp_path, env, good, argv, needle):
    (tmp_path / "unknown.toml").write_text(BAD_CONFIG)
    (tmp_path / "syntax.toml").write_text('name = "x\n')
    (tmp_path / "broken.gltf").write_bytes(b"not a glTF")
    (tmp_path / "outputs.toml").write_text(Path(FLAT).read_text().replace(
        'outputs = ["flat.color"]', 'outputs = ["flat.nosuch"]'))
    out = tmp_path / "out"
    before = seed(good, out)
    done = rfw(["run", *argv, "--out", str(out)], tmp_path, env)
    assert_refused(done, needle)
    assert_kept(out, before)


def test_out_is_a_file(tmp_path, env):
    (tmp_path / "out").write_bytes(b"a file of the user's\n")
    before = snapshot(tmp_path)
    done = rfw(["run", *QUICK, "--out", "out"], tmp_path, env)
    assert_refused(done, "out", "--out")
    done = rfw(["run", *QUICK, "--out", "out/sub"], tmp_path, env)
    assert_refused(done, "out/sub", "--out")
    assert changes(before, snapshot(tmp_path)) == []


def test_broken_shader_fails_after_the_lock(tmp_path, env, good):
    # found only while rendering (pipeline creation), after the staging folder exists
    for rel, data in plugin_files(WGSL.replace("let size", "let size =").encode()).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(data)
    out = tmp_path / "out"
    before = seed(good, out)
    run_env = {**env, "PYTHONPATH": os.pathsep.join([str(tmp_path / PLUGIN_ENV["PYTHONPATH"]),
                                                     env["PYTHONPATH"]])}
    done = rfw(["run", "c.toml", "--backend", "wgpu", "--out", str(out)], tmp_path, run_env)
    assert_refused(done, "corpus_copy.comp.wgsl")
    assert_kept(out, before)


# -- 8. a good second run replaces what it should -------------------------------------------


def test_second_run_replaces_results(tmp_path, env, good):
    out = tmp_path / "out"
    before = seed(good, out)
    (out / "notes.txt").write_text("the user's own notes\n")
    (out / "frames" / "mine.txt").write_text("the user's own file in frames/\n")
    notes = snapshot(out)
    done = rfw(["run", *QUICK, "--size", "48x27", "--out", str(out)], tmp_path, env)
    assert done.returncode == 0, done.stderr
    after = snapshot(out)
    assert leftovers(out) == []
    assert _frames(out / "timings.json") == 1
    from PIL import Image

    assert Image.open(out / "flat.color.png").size == (48, 27)
    assert after["flat.color.png"] != before["flat.color.png"]
    # the user's files stay; the earlier run's frame images go (they are not this run's)
    assert after["notes.txt"] == notes["notes.txt"]
    assert after["frames/mine.txt"] == notes["frames/mine.txt"]
    assert sorted(os.listdir(out / "frames")) == ["mine.txt"]


def test_save_every_replaces_frames(tmp_path, env, good):
    out = tmp_path / "out"
    seed(good, out)  # frames 0000-0002 of a 3-frame run
    (out / "frames" / "mine.txt").write_text("the user's own file in frames/\n")
    before = snapshot(out)
    done = rfw(["run", *QUICK[:-1], "2", "--save-every", "1", "--out", str(out)], tmp_path,
               env)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(out / "frames")) == \
        ["flat.color.0000.png", "flat.color.0001.png", "mine.txt"]
    after = snapshot(out)
    assert after["frames/mine.txt"] == before["frames/mine.txt"]
    assert after["frames/flat.color.0000.png"] != before["frames/flat.color.0000.png"]
    assert _frames(out / "timings.json") == 2
    assert leftovers(out) == []


def test_success_removes_superseded_marks(tmp_path, env, good):
    # an earlier version's RUN-FAILED.txt and the EXR of an output now written as PNG only
    out = tmp_path / "out"
    seed(good, out)
    (out / "RUN-FAILED.txt").write_text("an earlier version's failure mark\n")
    (out / "flat.color.exr").write_bytes(b"an old EXR")
    done = rfw(["run", *QUICK, "--out", str(out)], tmp_path, env)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(out)) == ["flat.color.png", "timings.json"]


def test_run_into_new_folder(tmp_path, env):
    done = rfw(["run", *QUICK, "--out", "a/b/out"], tmp_path, env)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(tmp_path / "a" / "b" / "out")) == \
        ["flat.color.png", "timings.json"]


# -- negative controls of the judges --------------------------------------------------------


@pytest.fixture
def folder(tmp_path) -> Path:
    root = tmp_path / "f"
    (root / "sub").mkdir(parents=True)
    (root / "a.txt").write_bytes(b"a")
    (root / "sub" / "b.txt").write_bytes(b"b")
    os.mkfifo(root / "pipe")
    return root


def _touch_same(p: Path) -> None:
    data = p.read_bytes()
    p.unlink()
    p.write_bytes(data)  # same bytes, a new file


def _fifo_to_file(p: Path) -> None:
    p.unlink()
    p.write_bytes(b"")


MUTATIONS = {
    "content": lambda r: (r / "a.txt").write_bytes(b"A"),
    "rewritten-same-bytes": lambda r: _touch_same(r / "a.txt"),
    "mtime": lambda r: os.utime(r / "a.txt", ns=(1, 1)),
    "added-file": lambda r: (r / "sub" / "c.txt").write_bytes(b""),
    "added-folder": lambda r: (r / "new").mkdir(),
    "removed": lambda r: (r / "sub" / "b.txt").unlink(),
    "fifo-replaced-by-file": lambda r: _fifo_to_file(r / "pipe"),
    "link-added": lambda r: (r / "l").symlink_to("a.txt"),
}


@pytest.mark.parametrize("mutate", MUTATIONS.values(), ids=MUTATIONS.keys())
def test_control_snapshot_sees_changes(folder, mutate):
    before = snapshot(folder)
    assert changes(before, snapshot(folder)) == []
    if mutate is MUTATIONS["rewritten-same-bytes"]:
        keep = (folder / "a.txt").open("rb")  # the old inode cannot be reused meanwhile
    mutate(folder)
    assert changes(before, snapshot(folder)) != []
    if mutate is MUTATIONS["rewritten-same-bytes"]:
        keep.close()
    with pytest.raises(AssertionError, match="--out changed"):
        assert_kept(folder, before)


def test_control_snapshot_of_removed_folder(folder):
    before = snapshot(folder)
    shutil.rmtree(folder)
    assert snapshot(folder) == {} and changes(before, {}) != []


@pytest.mark.parametrize("stderr", [
    "", "rfw: interrupted\nrfw: interrupted\n", "Traceback (most recent call last):\n",
    "KeyboardInterrupt\n", "rfw: error: x\n",
], ids=["empty", "two-lines", "traceback", "other-line", "wrong-start"])
def test_control_one_line(stderr):
    assert one_line(stderr, "rfw: interrupted") != []
    assert one_line("rfw: interrupted\n", "rfw: interrupted") == []


def test_control_leftovers(tmp_path):
    assert leftovers(tmp_path) == []
    (tmp_path / ".rfw-staging-12").mkdir()
    (tmp_path / LOCK).write_text("pid 12: rfw run\n")
    assert leftovers(tmp_path) == [LOCK, ".rfw-staging-12"]
    with pytest.raises(AssertionError, match="left in --out"):
        assert_kept(tmp_path, snapshot(tmp_path))


def test_control_workers(tmp_path):
    marker = str(tmp_path / "unique-marker")
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", marker])
    try:
        # a loaded machine may scan /proc before the child has exec'd into its command line
        deadline = time.monotonic() + 10
        while not workers(marker) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert workers(marker) != []
    finally:
        proc.kill()
        proc.wait()
    assert workers(marker) == []


def test_control_moments(tmp_path):
    # caught(): Python catches SIGINT only; SIGTERM once a handler is installed
    code = "import signal, sys, time; sys.stdout.write('a\\n'); sys.stdout.flush(); " \
        "time.sleep(0.5); signal.signal(signal.SIGTERM, lambda *a: None); " \
        "sys.stdout.write('b\\n'); sys.stdout.flush(); time.sleep(60)"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "a\n"
        assert signal.SIGINT in caught(proc.pid) and signal.SIGTERM not in caught(proc.pid)
        assert proc.stdout.readline() == "b\n"
        assert signal.SIGTERM in caught(proc.pid)
        assert mapped(proc.pid, "libc") and not mapped(proc.pid, "_rtoml")
    finally:
        proc.kill()
        proc.wait()


def test_control_assert_refused():
    ok = subprocess.CompletedProcess([], 2, "", "rfw: error: out: --out: in use\n")
    assert_refused(ok, "--out")
    for bad in (subprocess.CompletedProcess([], 0, "", "rfw: error: out: --out: x\n"),
                subprocess.CompletedProcess([], 2, "", "rfw: error: x\nmore\n"),
                subprocess.CompletedProcess([], 2, "", "rfw: error: no element\n")):
        with pytest.raises(AssertionError):
            assert_refused(bad, "--out")
