"""What the examples share (they run as scripts: ``python examples/NAME.py``, which puts
this folder on the path)."""

from __future__ import annotations

import os
from pathlib import Path


def out_problem(folder: Path) -> str | None:
    """Why ``folder`` cannot hold the output (one line), or None: it is a writable folder or
    can be made one. Checked before rendering, so a bad --out costs no render."""
    folder = Path(os.path.abspath(folder))
    for p in (folder, *folder.parents):  # the nearest part that exists decides
        if p.exists():
            if not p.is_dir():
                return f"{p}: --out: not a folder"
            if not os.access(p, os.W_OK | os.X_OK):
                return f"{p}: --out: cannot write here"
            return None
    return None
