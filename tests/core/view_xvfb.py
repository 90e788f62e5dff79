"""Running ``rfw view`` under Xvfb in tests (tests/core/test_view_*.py)."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

needs_xvfb = pytest.mark.skipif(shutil.which("xvfb-run") is None,
                                reason="needs xvfb-run (scripts/setup-system.sh installs it)")


def xvfb() -> list[str]:
    # -a searches from a per-worker number: two pytest-xdist workers do not race for :99
    return ["xvfb-run", "-a", "-n", str(100 + os.getpid() % 800), "-s", "-screen 0 640x480x24"]


def under_xvfb(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    """``cmd`` under its own Xvfb; started again if another process took the display
    between xvfb-run's look for a free one and its server's start (nothing of rfw ran)."""
    for _ in range(3):
        done = subprocess.run([*xvfb(), *cmd], capture_output=True, text=True, timeout=180,
                              check=False, **kw)
        if "Xvfb failed to start" not in done.stderr:
            break
    return done
