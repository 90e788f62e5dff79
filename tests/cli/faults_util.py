"""Shared helpers of the fault corpus (issue 21, item 10): rfw as a scripted subprocess,
signals sent at moments the test can see (never by guessing a delay), and the judges of
"the earlier results survived".

The judges each have a negative control in tests/cli/test_faults.py (test_control_*):
:func:`snapshot` / :func:`changes` (a folder byte for byte, special files by kind, never
opened), :func:`one_line` (one stderr line, no traceback), :func:`leftovers` (staging and
lock info), :func:`workers` (bench worker processes still running), and the fault makers
:func:`full_tmpfs` and :func:`read_only` (they must really refuse writes: on a machine
where they cannot be made the tests fail, they do not skip).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ..conftest import rfw_cli, tree_env
from .warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]
FLAT = str(ROOT / "configs" / "flat.toml")
# a config that renders in a fraction of a second once the device is up
QUICK = [FLAT, "--scene", "stress:1", "--size", "32x18", "--frames", "1"]
# long enough to be signalled in the middle: about 30 s of frames on lavapipe, 300 of
# them saved under the staging folder's frames/ (what "after a few frames" waits for)
LONG = [FLAT, "--scene", "stress:1", "--size", "256x144", "--frames", "3000",
        "--save-every", "10"]
BENCH_QUICK = ["--scene", "stress:1", "--size", "32x18", "--frames", "1", "--warmup", "0",
               "--no-progress"]
TIMEOUT = 180
STAGING, LOCK = ".rfw-staging-", ".rfw-lock"


def env_for(home: Path) -> dict[str, str]:
    """This tree's rfw with caches and home in ``home`` (shared by a session's tests, so the
    shader cache is warm after the first render) and no RFW_* setting of the caller's."""
    env = {k: v for k, v in tree_env().items() if not k.startswith("RFW_")}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / "cache"),
               RFW_CACHE=str(home / "cache" / "rfw-scenes"), PYTHONDONTWRITEBYTECODE="1")
    return env


def rfw(argv: list[str], cwd: Path, env: dict[str, str], *,
        preexec_fn: Callable[[], None] | None = None,
        timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """Run ``python -m rfw.cli ARGV`` to the end: forked from the warm zygote (tests/cli/warm.py)
    unless ``preexec_fn`` is to run in it first. (The signal cases start theirs fresh: see
    :func:`start`.)"""
    if preexec_fn is None:
        return warm_cli(*argv, cwd=cwd, environ=env, timeout=timeout, errors="replace")
    return rfw_cli(*argv, cwd=cwd, environ=env, timeout=timeout, errors="replace",
                   preexec_fn=preexec_fn)


def start(argv: list[str], cwd: Path, env: dict[str, str], *,
          session: bool = False) -> subprocess.Popen:
    """Start ``python -m rfw.cli ARGV``; ``session``: in a process group of its own (what
    a terminal's Ctrl-C reaches as a whole)."""
    return subprocess.Popen([sys.executable, "-m", "rfw.cli", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            errors="replace", start_new_session=session)


def finish(proc: subprocess.Popen, timeout: float = TIMEOUT) -> tuple[int, str, str]:
    """Wait for ``proc``; (exit code, stdout, stderr). A process that hangs is killed (with
    its group) and fails the test."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_tree(proc)
        out, err = proc.communicate()
        pytest.fail(f"rfw did not end within {timeout} s: {err[-2000:]}")
    return proc.returncode, out, err


def kill_tree(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc`` and, when it leads one, its process group (test cleanup only)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        if os.getpgid(proc.pid) == proc.pid:
            os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(ProcessLookupError):
        proc.kill()


def wait_for(proc: subprocess.Popen, ready: Callable[[], bool], what: str, *,
             timeout: float = TIMEOUT, pause: float = 0.02) -> None:
    """Poll until ``ready()``; fails (and kills ``proc``) if ``proc`` ends first or it takes
    longer than ``timeout``. ``pause`` 0: poll as fast as possible (short moments)."""
    end = time.monotonic() + timeout
    while not ready():
        if proc.poll() is not None:
            _, err = proc.communicate()
            pytest.fail(f"rfw ended (exit {proc.returncode}) before {what}: {err[-2000:]}")
        if time.monotonic() > end:
            kill_tree(proc)
            pytest.fail(f"no {what} within {timeout} s")
        if pause:
            time.sleep(pause)


@contextlib.contextmanager
def stopped(proc: subprocess.Popen) -> Iterator[None]:
    """``proc`` held still (SIGSTOP) in the block: the moment a test saw stays the moment
    its signal arrives; SIGCONT after."""
    os.kill(proc.pid, signal.SIGSTOP)
    try:
        yield
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGCONT)


# -- moments a test can see in /proc and in --out -------------------------------------------


def caught(pid: int) -> set[int]:
    """The signals ``pid`` has handlers for (SigCgt): SIGTERM among them once rfw.cli's
    main() has installed its handlers (Python itself only catches SIGINT)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("SigCgt:"):
            mask = int(line.split()[1], 16)
            return {n for n in range(1, 65) if mask >> (n - 1) & 1}
    return set()


def mapped(pid: int, needle: str) -> bool:
    """Whether a file whose path contains ``needle`` is mapped into ``pid`` (an extension
    module loaded: its imports are under way)."""
    try:
        return needle in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def staging_dirs(out: Path) -> list[Path]:
    return sorted(out.glob(STAGING + "*")) if out.is_dir() else []


def staged_frames(out: Path) -> int:
    return sum(len(list((s / "frames").glob("*.png"))) for s in staging_dirs(out)
               if (s / "frames").is_dir())


def staged_records(out: Path) -> int:
    """Whole lines in the staging folder's results.jsonl (a bench's finished runs)."""
    n = 0
    for s in staging_dirs(out):
        with contextlib.suppress(OSError):
            n += (s / "results.jsonl").read_bytes().count(b"\n")
    return n


def leftovers(out: Path) -> list[str]:
    """Staging folders and lock info left in ``out`` (a finished command leaves none)."""
    if not out.is_dir():
        return []
    return sorted(p.name for p in out.iterdir()
                  if p.name.startswith(STAGING) or p.name == LOCK)


def workers(marker: str) -> list[str]:
    """Processes (not this one) whose command line contains ``marker`` (a bench's unique
    --out path: its workers' --out is inside it)."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (proc / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if marker in cmd and state != "Z":  # a zombie is gone, only not reaped yet
            found.append(f"{proc.name}: {cmd.strip()}")
    return found


MOMENTS = ["imports", "checks", "staging", "frames"]


def signal_at(proc: subprocess.Popen, out: Path, moment: str, sig: int) -> None:
    """Send ``sig`` to ``proc`` at ``moment`` (held still meanwhile): "imports" (rfw's imports
    under way, main() not started), "checks" (main()'s handlers installed, no lock yet),
    "staging" (a staging folder in ``out``), "frames" (two frames staged there)."""
    pid = proc.pid
    if moment == "imports":
        wait_for(proc, lambda: mapped(pid, "_rtoml"), "rfw's imports", pause=0.002)
    elif moment == "checks":
        wait_for(proc, lambda: signal.SIGTERM in caught(pid), "rfw's signal handlers",
                 pause=0.002)
    elif moment == "staging":
        wait_for(proc, lambda: bool(staging_dirs(out)), "a staging folder")
    else:
        wait_for(proc, lambda: staged_frames(out) >= 2, "two staged frames", pause=0.01)
    with stopped(proc):
        if moment == "imports":  # the moment is what the test says it is: no lock yet
            assert not (out / LOCK).exists(), "the lock was taken already"
        if moment == "checks":
            assert not (out / LOCK).exists(), "the lock was taken already"
        os.kill(pid, sig)


# -- judges ---------------------------------------------------------------------------------


def snapshot(root: Path) -> dict[str, tuple]:
    """Every path under ``root`` (``root`` itself as '.'): regular files by sha256, size,
    inode and mtime (a rewrite with the same bytes is a change too), links by target,
    folders by kind, special files by kind and device number (never opened: a FIFO would
    block). An absent ``root`` is an empty snapshot."""
    found: dict[str, tuple] = {}
    if not os.path.lexists(root):
        return found
    paths = [root]
    for dirpath, dirnames, filenames in os.walk(root):
        paths += [Path(dirpath) / n for n in dirnames + filenames]
    for p in paths:
        st = os.lstat(p)
        rel = "." if p == root else str(p.relative_to(root))
        if stat.S_ISLNK(st.st_mode):
            found[rel] = ("link", os.readlink(p))
        elif stat.S_ISREG(st.st_mode):
            found[rel] = ("file", hashlib.sha256(p.read_bytes()).hexdigest(), st.st_size,
                          st.st_ino, st.st_mtime_ns)
        elif stat.S_ISDIR(st.st_mode):
            found[rel] = ("dir",)  # its mtime moves when staging comes and goes
        else:
            found[rel] = (stat.filemode(st.st_mode)[0], st.st_rdev, st.st_ino)
    return found


def changes(before: dict[str, tuple], after: dict[str, tuple]) -> list[str]:
    """The paths that differ between two snapshots."""
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))


def one_line(stderr: str, start: str) -> list[str]:
    """What is wrong with ``stderr`` (empty: nothing): it must be exactly one non-empty line,
    starting with ``start``, without a traceback."""
    problems = []
    if "Traceback" in stderr:
        problems.append("traceback")
    lines = [line for line in stderr.splitlines() if line.strip()]
    if len(lines) != 1:
        problems.append(f"{len(lines)} stderr lines, not 1: {lines[-3:]}")
    elif not lines[0].startswith(start):
        problems.append(f"the line does not start with {start!r}: {lines[0]!r}")
    return problems


def assert_refused(done: subprocess.CompletedProcess | tuple, *needles: str,
                   code: int = 2) -> str:
    """Exit ``code`` and one ``rfw: error:`` line naming every needle; returns the line."""
    rc, err = (done.returncode, done.stderr) if isinstance(done, subprocess.CompletedProcess) \
        else (done[0], done[2])
    assert rc == code, f"exit {rc}, not {code}: {err[-2000:]}"
    assert not one_line(err, "rfw: error:"), one_line(err, "rfw: error:")
    missing = [n for n in needles if n not in err]
    assert not missing, f"the line does not name {missing}: {err.strip()}"
    return err.strip()


def assert_kept(out: Path, before: dict[str, tuple]) -> None:
    """``out`` exactly as in ``before`` and no staging folder or lock info in it."""
    assert leftovers(out) == [], f"left in --out: {leftovers(out)}"
    changed = changes(before, snapshot(out))
    assert not changed, f"--out changed: {changed[:8]}"


def seed(template: Path, out: Path) -> dict[str, tuple]:
    """``out`` as a copy of an earlier good result; its snapshot."""
    shutil.copytree(template, out, copy_function=shutil.copy2)
    return snapshot(out)


# -- fault makers ---------------------------------------------------------------------------


def _sh(*cmd: str) -> None:
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode:  # no skip: this machine (root, as CI) must be able to make the fault
        pytest.fail(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()}")


@contextlib.contextmanager
def full_tmpfs(where: Path, fill: Callable[[Path], None], *, free_pages: int = 0,
               size_k: int = 256) -> Iterator[Path]:
    """A small tmpfs mounted at ``where`` (needs root, as on CI), ``fill(where)`` put in
    first, then the rest filled with 4 KiB files until the file system refuses, then
    ``free_pages`` of those removed again: a disk with exactly that much room left."""
    where.mkdir(parents=True, exist_ok=True)
    _sh("mount", "-t", "tmpfs", "-o", f"size={size_k}k,mode=0755", "rfw-faults", str(where))
    try:
        fill(where)
        fillers = []
        while True:
            path = where / f".filler-{len(fillers)}"
            try:
                path.write_bytes(b"x" * 4096)
            except OSError:
                path.unlink(missing_ok=True)
                break
            fillers.append(path)
        for path in fillers[:free_pages]:
            path.unlink()
        yield where
    finally:
        _sh("umount", "-l", str(where))


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[Path]:
    """``folder`` as a read-only bind mount of itself (as root, chmod stops no write)."""
    _sh("mount", "--bind", str(folder), str(folder))
    try:
        _sh("mount", "-o", "remount,bind,ro", str(folder))
        yield folder
    finally:
        _sh("umount", "-l", str(folder))


def file_size_limit(limit: int) -> Callable[[], None]:
    """A preexec_fn: files of the child cannot grow past ``limit`` bytes (EFBIG, not SIGXFSZ).
    Only for commands without a GPU device: lavapipe's device memory is a file mapping, and
    under the limit creating the device dies of SIGBUS in the driver (measured, wgpu
    request_device), before rfw can say anything."""
    import resource

    def limit_child() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return limit_child


def make_special(path: Path, kind: str) -> Callable[[], None]:
    """Make ``path`` a FIFO, a socket, a character device (a /dev/full of its own), a folder
    or a link to /dev/full; returns what closes it (a socket's listener)."""
    import socket

    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        return s.close
    elif kind == "chardev":
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 7))  # the numbers of /dev/full
    elif kind == "folder":
        path.mkdir()
    elif kind == "link-dev-full":
        path.symlink_to("/dev/full")
    else:
        raise ValueError(kind)
    return lambda: None
