"""Output folders that keep their results: one writer at a time, new files staged.

A command that writes into an output folder (``rfw run --out``, ``rfw bench --out``) holds
an :class:`OutputFolder` while it works:

- it takes a lock (``flock`` on the folder itself), so a second rfw writing there is refused
  in one line naming the first one's process; ``.rfw-lock`` says who holds it;
- it writes everything into a hidden staging folder inside the output folder (same file
  system, so moving a file in is a rename), ``.rfw-staging-<pid>``;
- :meth:`OutputFolder.commit` moves the staged files into place, with SIGINT and SIGTERM
  held back until it is done, and ``timings.json`` (or whatever ``last`` names) last;
- anything else (an error, a signal) removes the staging folder: the files that were there
  before are left byte for byte as they were. A folder the command created is removed again
  if it holds nothing.

Staging happens inside the output folder, not beside it, so that nothing is ever written
outside ``--out``; a staging folder left by a killed process is removed by the next writer,
which holds the lock and so knows it is stale.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path

from .errors import RfwError
from .fileio import check_target, inside

LOCK_INFO = ".rfw-lock"
STAGING_PREFIX = ".rfw-staging-"


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block is done (then they act as usual)."""
    held = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    except (ValueError, OSError):  # not the main thread: nothing to hold
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class OutputFolder:
    """The output folder ``out`` of one command, locked, with a staging folder to write
    into (:attr:`staging`). Use as a context manager; call :meth:`commit` on success."""

    def __init__(self, out: str | Path, *, element: str = "--out") -> None:
        self.given = str(out)
        self.out = Path(out)
        self.element = element
        self.staging = self.out / f"{STAGING_PREFIX}{os.getpid()}"
        self.committed = False
        self._fd: int | None = None
        self._created = False

    # -- checks before anything is written --------------------------------------------------

    def target(self, name: str | Path) -> Path:
        """Where ``name`` goes in the output folder, refused unless it resolves inside it
        (symlinks included) and is a regular file or nothing."""
        return check_target(inside(self.out, name), element=self.element)

    def staged(self, name: str | Path) -> Path:
        """Where ``name`` is written meanwhile: inside the staging folder."""
        return inside(self.staging, name)

    # -- lock and staging -----------------------------------------------------------------

    def __enter__(self) -> OutputFolder:
        if self.out.exists() and not self.out.is_dir():
            raise RfwError("is not a folder", file=self.given, element=self.element)
        if not self.out.exists():
            try:
                self.out.mkdir(parents=True)
                self._created = True
            except FileExistsError:
                pass
            except OSError as e:
                raise RfwError(e.strerror or str(e), file=self.given,
                               element=self.element) from None
        self.out = self.out.resolve()  # what is written is named by its real path
        self.staging = self.out / self.staging.name
        try:
            self._lock()
            self._clear_stale()
            self.staging.mkdir()
        except BaseException:
            self._release()
            raise
        return self

    def _lock(self) -> None:
        import fcntl

        try:
            self._fd = os.open(self.out, os.O_RDONLY | os.O_DIRECTORY)
        except OSError as e:
            raise RfwError(e.strerror or str(e), file=self.given, element=self.element) \
                from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = self._holder()
            os.close(self._fd)  # not ours: the holder's .rfw-lock must stay
            self._fd = None
            raise RfwError(f"in use by another rfw ({holder}): wait for it or choose another "
                           "folder", file=self.given, element=self.element) from None
        except OSError as e:  # a file system without flock (some network mounts)
            if e.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                raise
        info = f"pid {os.getpid()}: rfw {' '.join(sys.argv[1:])}"[:500]
        path = self.out / LOCK_INFO
        try:
            path.unlink(missing_ok=True)  # a stale one (its process was killed), or a link
            path.write_text(info + "\n", encoding="utf-8", errors="replace")
        except OSError as e:
            raise RfwError(e.strerror or str(e), file=str(path), element=self.element) \
                from None

    def _holder(self) -> str:
        try:
            text = (self.out / LOCK_INFO).read_text(encoding="utf-8", errors="replace")
        except OSError:
            return "its process is not recorded"
        return " ".join(text.split())[:200] or "its process is not recorded"

    def _clear_stale(self) -> None:
        # the lock is ours: a staging folder here is a killed process's
        for old in self.out.glob(STAGING_PREFIX + "*"):
            if old.is_dir() and not old.is_symlink():
                shutil.rmtree(old, ignore_errors=True)

    def _release(self) -> None:
        if self._fd is None:
            self._remove_created()
            return
        with contextlib.suppress(OSError):
            (self.out / LOCK_INFO).unlink(missing_ok=True)
        self._remove_created()
        with contextlib.suppress(OSError):
            os.close(self._fd)  # closing the descriptor releases the flock
        self._fd = None

    def _remove_created(self) -> None:
        if self._created and not self.committed:
            with contextlib.suppress(OSError):
                self.out.rmdir()  # only if empty

    def __exit__(self, kind: object, error: object, tb: object) -> None:
        from .signals import Interrupted

        if isinstance(error, Interrupted) and self.committed and not error.note:
            # held back during the commit, the signal came after it: the results are whole
            error.note = f"(after its results were written to {self.given})"
        if isinstance(error, OSError) and error.filename:
            error.filename = self._shown(error.filename)  # ENOSPC names the output's path
        with signals_held():
            if self.staging.is_dir():
                shutil.rmtree(self.staging, ignore_errors=True)
            self._release()

    def _shown(self, filename: str | bytes | int) -> str | bytes | int:
        """``filename`` as the user knows it: a staged path named by where it was going."""
        if not isinstance(filename, str):
            return filename
        try:
            rel = Path(filename).resolve().relative_to(self.staging)
        except ValueError:
            return filename
        return str(Path(self.given) / rel)

    # -- commit -----------------------------------------------------------------------------

    def commit(self, *, last: Iterable[str] = (), remove: Iterable[Path] = (),
               merge: Iterable[str] = ()) -> list[Path]:
        """Move every staged entry into the output folder, replacing what is there under
        the same name; entries named in ``merge`` (folders) have their files moved into the
        folder of that name instead; entries in ``last`` go after all others. Then remove
        ``remove`` (paths of earlier results this run supersedes), except what was just
        moved there. Signals wait meanwhile.
        Returns the final paths of the moved entries."""
        last = list(last)
        merge = set(merge)
        names = sorted(p.name for p in self.staging.iterdir())
        order = [n for n in names if n not in last] + [n for n in last if n in names]
        moved = []
        with signals_held():
            for name in order:
                src, dst = self.staging / name, inside(self.out, name)
                if name in merge and src.is_dir():
                    dst.mkdir(exist_ok=True)
                    for f in sorted(src.iterdir()):
                        os.replace(f, inside(dst, f.name))
                        moved.append(dst / f.name)
                    continue
                if dst.is_dir() and not dst.is_symlink():
                    trash = self.staging / f".old-{name}"
                    os.replace(dst, trash)
                os.replace(src, dst)
                moved.append(dst)
            done = set(moved)
            for old in remove:
                if old not in done and (old.is_file() or old.is_symlink()):
                    old.unlink()
            self.committed = True
        return moved


def partial_name(out: Path) -> Path:
    """A fresh ``partial-<date>-<time>`` folder name inside ``out``."""
    import time

    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = out / f"partial-{stamp}"
    n = 1
    while path.exists():
        n += 1
        path = out / f"partial-{stamp}-{n}"
    return path
