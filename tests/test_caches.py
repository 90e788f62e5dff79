"""Caches heal: a damaged entry is found, rebuilt with one warning line, and later runs work.

Through the real CLI, as a user meets a damaged cache. The SPIR-V cache has its own tests
(tests/vkext/test_spirv.py); fetched scenes are in tests/scene/test_fetch.py."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from .cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[1]
RUN = ["run", str(ROOT / "configs" / "meshlet.toml"), "--backend", "vk", "--size", "64x36",
       "--frames", "1"]


def rfw(args: list[str], cwd: Path, cache: Path) -> subprocess.CompletedProcess:
    return warm_cli(*args, cwd=cwd, env={"RFW_CACHE_MESHLETS": str(cache)})


def warnings_of(done: subprocess.CompletedProcess) -> list[str]:
    return [ln for ln in done.stderr.splitlines() if ln.startswith("rfw: warning:")]


def image(out: Path) -> np.ndarray:
    with Image.open(out / "tonemap.ldr.png") as im:
        return np.asarray(im)


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """One clean run: its image, and every meshlet cache entry it wrote."""
    tmp = tmp_path_factory.mktemp("meshlet_cache")
    cache = tmp / "cache"
    done = rfw([*RUN, "--out", str(tmp / "out")], tmp, cache)
    if done.returncode != 0 and ("VK_EXT_mesh_shader" in done.stderr
                                 or "no Vulkan" in done.stderr):
        pytest.skip(done.stderr.strip().splitlines()[-1])
    assert done.returncode == 0, done.stderr
    assert warnings_of(done) == []
    entries = {p: p.read_bytes() for p in sorted(cache.iterdir())}
    assert entries
    return tmp, cache, image(tmp / "out"), entries


def damage_truncate(data: bytes) -> bytes:
    return data[: len(data) // 3]


def damage_flip(data: bytes) -> bytes:
    i = len(data) // 2
    return data[:i] + bytes([data[i] ^ 0x55]) + data[i + 1:]


def damage_garbage(data: bytes) -> bytes:
    return b"\x00" * len(data)


@pytest.mark.parametrize("damage", [damage_truncate, damage_flip, damage_garbage])
def test_damaged_meshlet_entry_is_rebuilt_with_one_warning(first_run, tmp_path, damage):
    _, cache, expected, entries = first_run
    victim = max(entries, key=lambda p: len(entries[p]))  # the largest mesh's entry
    victim.write_bytes(damage(entries[victim]))
    assert victim.read_bytes() != entries[victim]
    done = rfw([*RUN, "--out", str(tmp_path / "out")], tmp_path, cache)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert warnings_of(done) == [f"rfw: warning: {victim}: corrupt cache entry, rebuilt"]
    np.testing.assert_array_equal(image(tmp_path / "out"), expected)
    assert {p: p.read_bytes() for p in sorted(cache.iterdir())} == entries  # healed
    # the next run hits the healed entry, quietly (and is a negative control of the above)
    again = rfw([*RUN, "--out", str(tmp_path / "again")], tmp_path, cache)
    assert again.returncode == 0 and warnings_of(again) == [], again.stderr
    np.testing.assert_array_equal(image(tmp_path / "again"), expected)


def test_unwritable_meshlet_cache_still_renders(first_run, tmp_path):
    _, _, expected, _ = first_run
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the cache folder would be")
    done = rfw([*RUN, "--out", str(tmp_path / "out")], tmp_path, blocker / "meshlets")
    assert done.returncode == 0, done.stderr
    lines = warnings_of(done)
    assert len(lines) == 1 and "cannot write the meshlet cache" in lines[0], done.stderr
    np.testing.assert_array_equal(image(tmp_path / "out"), expected)
