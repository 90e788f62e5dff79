"""A signal whose first Interrupted is swallowed (raised inside a ``__del__``, where Python
prints it and goes on) still ends the command at the next frame: rfw.signals.check."""

from __future__ import annotations

import subprocess
import sys

import pytest

# a __del__ sends the signal to its own process, so the handler raises inside __del__
PROGRAM = r"""
import os, signal, sys, time
from rfw import signals
from rfw.signals import Interrupted

class Sender:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)

try:
    with signals.installed():
        Sender()  # dropped at once: its __del__ runs, the Interrupted is swallowed
        print("went on", flush=True)
        if sys.argv[1] == "check":
            signals.check()
        print("not stopped", flush=True)
except Interrupted as e:
    print(e.line(), file=sys.stderr)
    sys.exit(e.exit_code)
"""


def _run(mode: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", PROGRAM, mode], capture_output=True,
                          text=True, timeout=60)


def test_check_raises_the_swallowed_signal():
    p = _run("check")
    assert p.returncode == 143, (p.returncode, p.stderr)
    assert p.stdout.splitlines() == ["went on"]
    # the swallowed raise is not printed ("Exception ignored in ...", a traceback): one line
    assert p.stderr.splitlines() == ["rfw: interrupted"], p.stderr


def test_without_check_the_signal_is_lost():
    # the negative control: this is the loss check() is for
    p = _run("none")
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines() == ["went on", "not stopped"]
    assert p.stderr == ""


def test_other_exceptions_in_a_del_are_still_printed():
    # only Interrupted is kept quiet: a __del__ that fails otherwise is reported as ever
    code = ("from rfw import signals\nclass Bad:\n    def __del__(self):\n"
            "        raise ValueError('broken del')\nwith signals.installed():\n    Bad()\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0 and "Exception ignored" in p.stderr \
        and "ValueError: broken del" in p.stderr, p.stderr


@pytest.mark.parametrize("signum", [2, 15])
def test_a_new_block_starts_clean(signum):
    # a signal raised and handled in one installed() block is not raised again later
    code = ("import os, signal, time\nfrom rfw import signals\nfrom rfw.signals import "
            "Interrupted\ntry:\n    with signals.installed():\n        os.kill(os.getpid(), "
            f"{signum})\n        time.sleep(1)\nexcept Interrupted:\n    pass\n"
            "with signals.installed():\n    signals.check()\nprint('clean')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0 and p.stdout.strip() == "clean", p.stderr


@pytest.mark.parametrize("committed", [True, False])
def test_a_signal_after_the_commit_says_the_results_are_written(tmp_path, committed):
    from rfw.outdir import OutputFolder
    from rfw.signals import Interrupted

    out = tmp_path / "out"
    with pytest.raises(Interrupted) as caught, OutputFolder(out) as folder:
        (folder.staging / "a.txt").write_text("new")
        if committed:
            folder.commit()
        raise Interrupted(15)
    assert (out / "a.txt").exists() == committed
    line = caught.value.line()
    assert line == (f"rfw: interrupted (after its results were written to {out})"
                    if committed else "rfw: interrupted")


# the second Ctrl-C arrives while the first one's line is being written (os.write sends it
# to its own process first): with signals.tell the line is written once and the second
# signal ends the process silently, with the same code; the control writes it as rfw used
# to, with print, and the second signal's handler adds a second line
TWICE = r"""
import os, signal, sys, time
from rfw import signals
from rfw.signals import Interrupted

write = os.write
def write_after_a_signal(fd, data):
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)
    return write(fd, data)

with signals.installed():  # as rfw.cli.main: the line is told inside the block
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)
    except Interrupted as e:
        os.write = write_after_a_signal
        if sys.argv[1] == "tell":
            signals.tell(e.line())
        else:
            print(e.line(), file=sys.stderr, flush=True)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        code = e.exit_code
sys.exit(code)
"""


@pytest.mark.parametrize("mode, lines", [("tell", 1), ("print", 2)])
def test_a_second_signal_while_the_line_is_written_adds_none(mode, lines):
    got = subprocess.run([sys.executable, "-c", TWICE, mode], capture_output=True, text=True,
                         timeout=60)
    assert got.returncode == 130, got.stderr
    assert got.stderr.splitlines() == ["rfw: interrupted"] * lines, got.stderr
