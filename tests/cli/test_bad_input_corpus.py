"""The bad-input corpus (issue 11, item 9): every case runs the real CLI in a subprocess
(forked from a warm one, tests/cli/warm.py: what ``main()`` does is what is judged).

Each bad input must give exit code 2 and exactly one non-empty stderr line, starting
``rfw: error:`` and naming the file and the element (pass, slot, key, line); no traceback;
nothing written outside ``--out`` (the whole scratch folder is compared before and after,
the caches, ~/.config and the NVIDIA driver's ~/.nv aside); and the earlier results kept
(issue 21): ``--out`` is seeded with an old ``tonemap.ldr.png`` and ``timings.json``, and
after the failed run ``--out`` holds exactly those files, byte for byte, and nothing else.
Inputs valid by design (mirrored and zero-scale nodes, damaged caches) must render, exit 0.

The cases live in tests/cli/corpus_cases.py. (The glTF mutation property test of item 9 is
tests/scene/test_gltf_fuzz.py.) Set ``RFW_CORPUS_REPORT=FILE`` to append one JSON
line per case (id, area, exit code, problems) for a summary.

Before the issue-11 fixes (the tree at 1b23660, 2026-12-01): about 230 of the 280 bad cases
broke the contract and 109 printed a Python traceback (65 broke only the stale-output check);
6 of the 11 accepted cases then failed, 5 of them with a traceback. After (257bd80, the same
afternoon): 3 bad cases failed, 1 with a traceback; every accepted case passed.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import pytest

from .corpus_cases import ACCEPTED, Accepted, Case, all_cases
from .warm import warm_cli

CASES = all_cases()
OLD_PNG = b"\x89PNG\r\n\x1a\n an image from an earlier run"
OLD_TIMINGS = b'{"from": "an earlier run"}\n'
TIMEOUT = 120


def _env(root: Path, cwd: Path, extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("RFW_")}
    env.update(HOME=str(root / "home"), XDG_CACHE_HOME=str(root / "cache"),
               RFW_CACHE=str(root / "cache" / "rfw-scenes"), PYTHONDONTWRITEBYTECODE="1")
    for k, v in extra.items():
        v = v if v.startswith("/") else str(cwd / v)  # relative to the working folder
        env[k] = os.pathsep.join(p for p in (v, env.get(k, "")) if p) if k == "PYTHONPATH" \
            else v
    return env


def _prepare(root: Path, files: dict[str, bytes]) -> Path:
    cwd = root / "work"
    for d in (cwd, root / "home", root / "cache"):
        d.mkdir(parents=True, exist_ok=True)
    for rel, data in files.items():
        (cwd / rel).parent.mkdir(parents=True, exist_ok=True)
        (cwd / rel).write_bytes(data)
    return cwd


def _run(argv: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    return warm_cli(*argv, cwd=cwd, environ=env, timeout=TIMEOUT, errors="replace")


def snapshot(root: Path, skip: list[Path]) -> dict[str, str]:
    """Every path under ``root`` (not under ``skip``) with its content hash or link target."""
    found: dict[str, str] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        dirnames[:] = [d for d in dirnames if here / d not in skip]
        for name in dirnames + filenames:
            p = here / name
            if p in skip:
                continue
            rel = str(p.relative_to(root))
            if p.is_symlink():
                found[rel] = "link:" + os.readlink(p)
            elif p.is_file():
                found[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
            else:
                found[rel] = "dir"
    return found


def _changes(before: dict[str, str], after: dict[str, str]) -> list[str]:
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))


def error_problems(case: Case, done: subprocess.CompletedProcess) -> list[str]:
    """What is wrong with a failed run's exit code and stderr (empty: nothing)."""
    problems = []
    if "Traceback" in done.stderr or "Traceback" in done.stdout:
        problems.append("traceback")
    if done.returncode != 2:
        problems.append(f"exit code {done.returncode}, not 2")
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    if len(lines) != 1:
        problems.append(f"{len(lines)} stderr lines, not 1")
    errors = [line for line in lines if line.startswith("rfw: error:")]
    if not errors:
        problems.append("no 'rfw: error:' line")
    else:
        missing = [n for n in case.needles if n not in errors[0]]
        if missing:
            problems.append(f"the line does not name {missing}")
    return problems


def kept_problems(before: dict[str, str], after: dict[str, str]) -> list[str]:
    """What a failed run changed in ``--out`` (snapshots of it before and after)."""
    changed = _changes(before, after)
    return [f"--out changed: {changed[:5]}"] if changed else []


def _report(case_id: str, area: str, rc: int, problems: list[str], stderr: str) -> None:
    path = os.environ.get("RFW_CORPUS_REPORT")
    if path:
        last = stderr.strip().splitlines()[-1:] or [""]
        with open(path, "a", encoding="utf-8") as f:
            f.write(json.dumps({"id": case_id, "area": area, "rc": rc, "problems": problems,
                                "last_line": last[0][:300]}) + "\n")


def check_case(case: Case, root: Path) -> list[str]:
    cwd = _prepare(root, case.files)
    if case.setup is not None:
        case.setup(cwd)
    out = case.out
    seeded = out == "out"
    if seeded:
        (cwd / out).mkdir(exist_ok=True)
        (cwd / out / "tonemap.ldr.png").write_bytes(OLD_PNG)
        (cwd / out / "timings.json").write_bytes(OLD_TIMINGS)
    # caches, and the per-user config folder third-party libraries create (matplotlib's)
    # ~/.nv: the NVIDIA driver's own shader cache (ComputeCache), written by the driver
    skip = [root / "cache", root / "home" / ".cache", root / "home" / ".config",
            root / "home" / ".nv"]
    if out:  # an empty --out is the working folder itself: nothing is skipped then
        skip.append(cwd / out)
    before = snapshot(root, skip)
    kept = snapshot(cwd / out, []) if seeded else {}
    try:
        done = _run(case.command(), cwd, _env(root, cwd, case.env))
    except subprocess.TimeoutExpired:
        _report(case.id, case.area, -1, ["timed out"], "")
        return [f"timed out after {TIMEOUT} s"]
    problems = error_problems(case, done)
    outside = _changes(before, snapshot(root, skip))
    if outside:
        problems.append(f"wrote outside --out: {outside[:5]}")
    if seeded:
        problems += kept_problems(kept, snapshot(cwd / out, []))
    _report(case.id, case.area, done.returncode, problems, done.stderr)
    if problems:
        problems.append(f"stderr: {done.stderr.strip()[-1500:]!r}")
    return problems


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_clean_line(case: Case, tmp_path: Path) -> None:
    problems = check_case(case, tmp_path)
    assert not problems, f"{case.id} ({' '.join(case.command())}): " + "; ".join(problems)


@pytest.mark.parametrize("case", ACCEPTED, ids=[c.id for c in ACCEPTED])
def test_valid_input_renders(case: Accepted, tmp_path: Path) -> None:
    cwd = _prepare(tmp_path, case.files)
    env = _env(tmp_path, cwd, case.env)
    if case.warm:
        first = _run([*case.warm, "--size", "32x18", "--frames", "1", "--out", "warm"], cwd, env)
        assert first.returncode == 0, first.stderr
    if case.damage is not None:
        case.damage(tmp_path)
    done = _run(case.command(), cwd, env)
    problems = []
    if done.returncode != 0:
        problems.append(f"exit code {done.returncode}")
    if "Traceback" in done.stderr:
        problems.append("traceback")
    if case.argv[0] == "run" and not (cwd / "out" / "timings.json").is_file():
        problems.append("no timings.json")
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    warnings = [line for line in lines if line.startswith("rfw: warning:")]
    if case.warning and len(warnings) != 1:
        problems.append(f"{len(warnings)} 'rfw: warning:' lines, not 1 (the damaged cache "
                        "entry is neither reported nor rebuilt quietly once)")
    _report(case.id, "accepted", done.returncode, problems, done.stderr)
    assert not problems, "; ".join(problems) + f"; stderr: {done.stderr.strip()[-1500:]!r}"


# ---------------------------------------------------------------------------------------------
# negative controls: the checks above must reject what they are meant to reject


def _fake(rc: int, stderr: str) -> subprocess.CompletedProcess:
    return subprocess.CompletedProcess([], rc, "", stderr)


CONTROL = Case("control", ("run", "c.toml"), needles=("c.toml", "tonemap"))
GOOD_LINE = "rfw: error: c.toml: pass 'tonemap': bad\n"


def test_a_clean_line_passes_the_check() -> None:
    assert error_problems(CONTROL, _fake(2, GOOD_LINE)) == []


@pytest.mark.parametrize("rc, stderr, why", [
    (1, GOOD_LINE, "exit code 1"),
    (0, GOOD_LINE, "exit code 0"),
    (2, GOOD_LINE + "rfw: error: again\n", "2 stderr lines"),
    (2, "Traceback (most recent call last):\n" + GOOD_LINE, "traceback"),
    (2, "usage: rfw run\nrfw run: error: argument --frames\n", "no 'rfw: error:' line"),
    (2, "rfw: error: c.toml: bad\n", "does not name ['tonemap']"),
    (2, "", "0 stderr lines"),
], ids=["exit-1", "exit-0", "two-lines", "traceback", "argparse-usage", "element-missing",
        "silent"])
def test_the_check_rejects_a_bad_error(rc: int, stderr: str, why: str) -> None:
    assert any(why in p for p in error_problems(CONTROL, _fake(rc, stderr)))


def test_the_snapshot_sees_a_write_outside(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    before = snapshot(tmp_path, [tmp_path / "out"])
    (tmp_path / "out" / "fine.png").write_bytes(b"x")
    assert _changes(before, snapshot(tmp_path, [tmp_path / "out"])) == []
    (tmp_path / "x.png").write_bytes(b"x")
    os.symlink("/nowhere", tmp_path / "link")
    assert _changes(before, snapshot(tmp_path, [tmp_path / "out"])) == ["link", "x.png"]


def test_the_kept_check_sees_any_change_in_out(tmp_path: Path) -> None:
    (tmp_path / "tonemap.ldr.png").write_bytes(OLD_PNG)
    (tmp_path / "timings.json").write_bytes(OLD_TIMINGS)
    before = snapshot(tmp_path, [])
    assert kept_problems(before, snapshot(tmp_path, [])) == []
    (tmp_path / "timings.json").unlink()
    assert kept_problems(before, snapshot(tmp_path, []))
    (tmp_path / "timings.json").write_bytes(OLD_TIMINGS)
    (tmp_path / "RUN-FAILED.txt").write_bytes(b"")  # an added mark is a change too
    assert kept_problems(before, snapshot(tmp_path, []))
    (tmp_path / "RUN-FAILED.txt").unlink()
    (tmp_path / "tonemap.ldr.png").write_bytes(OLD_PNG + b"x")
    assert kept_problems(before, snapshot(tmp_path, []))


def test_the_corpus_is_large_and_ids_are_unique() -> None:
    ids = [c.id for c in CASES] + [c.id for c in ACCEPTED]
    assert len(CASES) >= 100
    assert len(ids) == len(set(ids))
    assert all(c.needles for c in CASES), [c.id for c in CASES if not c.needles]

