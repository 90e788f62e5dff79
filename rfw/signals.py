"""SIGINT and SIGTERM end every command the same way: cleanup runs, one line, 128 + signal.

:func:`installed` makes both signals raise :class:`Interrupted` in the main thread, so
``finally`` blocks and context managers (output folders: :mod:`rfw.outdir`, devices,
worker processes) clean up as they do for an error; ``rfw.cli.main`` then prints
``rfw: interrupted`` and exits 130 (SIGINT) or 143 (SIGTERM). A second signal while that
cleanup runs ends the process at once, with the same line and code.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Iterator
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(BaseException):
    """A signal asked the command to stop (a BaseException: ``except Exception`` in the
    code it interrupts does not swallow it). ``note`` is added to the one line told."""

    def __init__(self, signum: int, note: str = "") -> None:
        super().__init__(signum, note)
        self.signum = signum
        self.note = note

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def line(self) -> str:
        return "rfw: interrupted" + (f" {self.note}" if self.note else "")


# the signal _first raised for: an Interrupted raised while Python runs a __del__ or a
# weakref callback is printed and dropped, so loops call check() to raise it again
_pending: int | None = None


def _first(signum: int, frame: FrameType | None) -> None:
    global _pending
    _pending = signum
    for s in SIGNALS:  # from now on a signal ends the process as soon as it comes
        signal.signal(s, _again)
    raise Interrupted(signum)


def check() -> None:
    """Raise :class:`Interrupted` again if a signal came and its first raise was lost
    (swallowed by a ``__del__``, a callback or a broad ``except``). Call it in long loops."""
    if _pending is not None:
        raise Interrupted(_pending)


def _quiet_unraisable(hook):
    """A ``sys.unraisablehook`` that drops an :class:`Interrupted` Python could not raise
    (it came while a ``__del__`` or weakref callback ran; :func:`check` raises it again)
    instead of printing it with a traceback; everything else goes to ``hook``."""

    def unraisable(info) -> None:
        if isinstance(info.exc_value, Interrupted):
            return
        hook(info)

    return unraisable


_told = False  # the one line is on stderr: a later signal ends the process without another


def tell(line: str) -> None:
    """Write ``line`` (the interruption's one line) to stderr with the signals held back,
    so that one arriving meanwhile cannot add a second line (it ends the process silently
    once they are let through: :func:`_again`)."""
    global _told
    held = _hold()
    try:
        if not _told:
            sys.stderr.flush()
            os.write(2, (line + "\n").encode())
            _told = True
    finally:
        if held:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)


def _hold() -> bool:
    try:
        signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
        return True
    except (AttributeError, OSError, ValueError):  # no pthread_sigmask here
        return False


def _again(signum: int, frame: FrameType | None) -> None:
    if not _told:
        _hold()  # never let through again: the process ends here
        os.write(2, b"rfw: interrupted\n")
    os._exit(128 + signum)


def early() -> None:
    """When this process is the ``rfw`` command (the console script or ``python -m
    rfw.cli``), end it with the one line and 128 + signal should SIGINT or SIGTERM come
    while it imports, before ``rfw.cli.main`` installs the handlers that clean up."""
    argv = list(getattr(sys, "orig_argv", sys.argv))
    command = os.path.basename(sys.argv[0]) == "rfw" if sys.argv else False
    if not (command or argv[1:3] == ["-m", "rfw.cli"]):
        return
    try:
        for s in SIGNALS:
            signal.signal(s, _again)
    except ValueError:  # not the main thread
        pass


@contextlib.contextmanager
def installed() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` within the block (in the main thread;
    elsewhere nothing changes), the handlers before it are put back after it."""
    global _pending, _told
    try:
        old = {s: signal.signal(s, _first) for s in SIGNALS}
    except ValueError:  # not the main thread
        yield
        return
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_unraisable(hook)
    try:
        yield
    finally:
        _pending, _told = None, False
        sys.unraisablehook = hook
        for s, handler in old.items():
            signal.signal(s, handler)
