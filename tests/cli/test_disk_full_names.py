"""A full disk names the output as the user gave it (``OUT/frames/...``), not the staging
folder rfw writes into meanwhile (``OUT/.rfw-staging-PID/...``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from .faults_util import QUICK, assert_kept, assert_refused, env_for, full_tmpfs, rfw, snapshot


@pytest.mark.parametrize("free,name", [(1, "frames/flat.color.0000.png"),
                                       (2, "flat.color.png")])
def test_disk_full_names_the_output(tmp_path, free, name):
    env = env_for(tmp_path / "home")
    good = tmp_path / "good"
    assert rfw(["run", *QUICK, "--out", str(good)], tmp_path, env).returncode == 0

    def fill(root: Path) -> None:
        shutil.copytree(good, root / "out", copy_function=shutil.copy2)

    with full_tmpfs(tmp_path / "mnt", fill, free_pages=free) as mnt:
        out = mnt / "out"
        before = snapshot(out)
        done = rfw(["run", *QUICK, "--save-every", "1", "--out", str(out)], tmp_path, env)
        line = assert_refused(done, f"{out}/{name}: No space left on device")
        assert ".rfw-staging" not in line, line
        assert_kept(out, before)
