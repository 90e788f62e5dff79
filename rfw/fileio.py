"""Files written whole or not at all."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO


def atomic_write(path: str | Path, write: Callable[[BinaryIO], object]) -> None:
    """Write ``path`` through ``write(file)`` into a temporary file beside it, then rename:
    readers and failures never see half a file. The file gets the permissions ``open()``
    would give it (mkstemp's are 0600); an OSError names ``path``, not the temporary file."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as e:
        raise OSError(e.errno, e.strerror, str(path)) from None
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise OSError(e.errno, e.strerror, str(path)) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def inside(root: str | Path, name: str | Path) -> Path:
    """``root / name``, refused unless it resolves (symlinks included) inside ``root``: a
    name that comes from a config or a graph can never write elsewhere."""
    from .errors import RfwError

    base = Path(root).resolve()
    path = (base / name).resolve()
    if path != base and base not in path.parents:
        raise RfwError(f"'{name}' would be written outside the output folder {base}",
                       file=str(root))
    return path
