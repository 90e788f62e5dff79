"""Entry-point groups (``rfw.passes``, ``rfw.backends``): what installed distributions declare.

rfw's own built-ins are declared in its pyproject.toml like anyone else's. A source tree
run without installing it (``PYTHONPATH=.`` on a machine with no network) has no metadata
for rfw, so there the groups are read from the pyproject.toml beside the package instead.
"""

from __future__ import annotations

import importlib.metadata
from functools import cache
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def entry_points(group: str) -> list[importlib.metadata.EntryPoint]:
    """The group's entry points, installed ones first; rfw's own from its pyproject.toml
    when rfw runs from a tree that was never installed."""
    found = list(importlib.metadata.entry_points(group=group))
    if not _installed():
        names = {ep.name for ep in found}
        found += [ep for ep in _source_tree(group) if ep.name not in names]
    return found


@cache
def _installed() -> bool:
    try:
        importlib.metadata.distribution("rfw")
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


@cache
def _source_tree(group: str) -> tuple[importlib.metadata.EntryPoint, ...]:
    import tomllib

    if not PYPROJECT.is_file():
        return ()
    with PYPROJECT.open("rb") as f:
        table = tomllib.load(f).get("project", {}).get("entry-points", {}).get(group, {})
    return tuple(importlib.metadata.EntryPoint(name, value, group)
                 for name, value in table.items())
