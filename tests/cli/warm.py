"""``python -m rfw.cli ARGS`` forked from a warm zygote (tests/cli/warm_zygote.py) instead of
started: the same process a fresh start would become, less its start (Python, numpy, wgpu's
header parse, rfw's imports: about 0.4 s of CPU a run on lavapipe's machines).

For the tests that run rfw many times and judge only what ``main()`` does (exit code,
stdout, stderr, the files): ``warm_cli`` takes ``conftest.rfw_cli``'s arguments, less
what it passes to subprocess.run. A run whose environment differs from this process's in anything read before
``main()`` (anything but HOME, XDG_CACHE_HOME, RFW_*, PYTHONPATH and
PYTHONDONTWRITEBYTECODE) is started fresh through ``rfw_cli``, as is every run where the
zygote cannot start.
"""

from __future__ import annotations

import json
import locale
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

from ..conftest import ROOT, rfw_cli

ZYGOTE = Path(__file__).with_name("warm_zygote.py")
# what a child sets per run; everything else must be this process's
PER_RUN = ("HOME", "XDG_CACHE_HOME", "PYTHONPATH", "PYTHONDONTWRITEBYTECODE",
           "PYTEST_CURRENT_TEST")  # pytest's, per test: nothing reads it



class Zygote:
    """The zygote process and its answers, read line by line without Python's buffering
    (a buffered line would be invisible to ``select``)."""

    def __init__(self) -> None:
        # this tree first, as conftest.tree_env has it: the children run this tree's rfw
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
        self.env = dict(os.environ)  # what it started with
        self.proc = subprocess.Popen([sys.executable, "-s", str(ZYGOTE)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, env=env, cwd=ROOT, bufsize=0)
        self.buf = b""

    def send(self, request: dict) -> None:
        self.proc.stdin.write(json.dumps(request).encode() + b"\n")

    def answer(self, deadline: float | None = None) -> dict | None:
        """The next JSON line, or None when ``deadline`` passed or the zygote ended."""
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buf:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and (left <= 0 or not select.select([fd], [], [], left)[0]):
                return None
            chunk = os.read(fd, 4096)
            if not chunk:
                return None
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return json.loads(line)

    def alive(self) -> bool:
        return self.proc.poll() is None


_zygote: Zygote | None = None


def _start() -> Zygote | None:
    z = Zygote()
    if z.answer(time.monotonic() + 120) != "ready":
        z.proc.kill()
        z.proc.wait()
        return None
    return z


def _zygote_proc() -> Zygote | None:
    global _zygote
    if _zygote is None or not _zygote.alive():
        _zygote = _start()
    return _zygote


def same_start(environ: Mapping[str, str], zygote: Mapping[str, str]) -> bool:
    """Whether a process with ``environ`` starts as one with the zygote's environment
    ``zygote`` does (see the module)."""
    def started(env: Mapping[str, str]) -> dict[str, str]:
        return {k: v for k, v in env.items() if k not in PER_RUN and not k.startswith("RFW_")}

    return started(environ) == started(zygote)


def _text(data: bytes, errors: str) -> str:
    # as subprocess.run(text=True) decodes: the locale's encoding, universal newlines
    text = data.decode(locale.getpreferredencoding(False), errors=errors)
    return text.replace("\r\n", "\n").replace("\r", "\n")


def warm_cli(*args: object, cwd: Path | str | None = None,
             env: Mapping[str, str | None] | None = None,
             environ: Mapping[str, str] | None = None, tree: bool = False,
             safe_path: bool = False, timeout: float = 300,
             errors: str = "strict") -> subprocess.CompletedProcess:
    """``rfw_cli`` with these arguments (their meaning is its), forked. The children run this
    tree's rfw, ``tree`` or not."""
    argv = [str(a) for a in args]
    merged = {**(os.environ if environ is None else environ), **(env or {})}
    full = {k: v for k, v in merged.items() if v is not None}
    cwd = os.getcwd() if cwd is None else cwd
    z = _zygote_proc()
    z = z if z is not None and same_start(full, z.env) else None
    if z is None:
        return rfw_cli(*argv, cwd=cwd, environ=full, tree=tree, safe_path=safe_path,
                       timeout=timeout, errors=errors)
    with tempfile.TemporaryDirectory(prefix="rfw-warm-") as tmp:
        out, err = Path(tmp) / "stdout", Path(tmp) / "stderr"
        z.send({"argv": argv, "cwd": str(cwd), "env": full, "stdout": str(out),
                "stderr": str(err), "safe_path": safe_path})
        deadline = time.monotonic() + timeout
        forked = z.answer(deadline)
        assert forked is not None, "the rfw zygote ended"
        done = z.answer(deadline)
        if done is None:
            os.kill(forked["pid"], signal.SIGKILL)
            z.answer()  # the zygote's answer for the killed child
            raise subprocess.TimeoutExpired(["rfw", *argv], timeout)
        code = done["status"]
        return subprocess.CompletedProcess(
            [sys.executable, "-m", "rfw.cli", *argv], code,
            _text(out.read_bytes(), errors), _text(err.read_bytes(), errors))
