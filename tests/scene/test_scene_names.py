"""Scenes by name through the CLI: ``--scene NAME`` takes a cached fetched scene, says how to
fetch one that is not cached, fetches on demand only when allowed, and answers an unknown
name with the close matches; ``rfw scenes list`` shows built-in and fetchable scenes."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from rfw.scene import stress
from rfw.scene.fetch import SCENES, scene_to_glb
from rfw.scene.fetch.cache import FORMAT

from ..cli.warm import warm_cli
from ..golden_util import changed_share

ROOT = Path(__file__).resolve().parents[2]
FLAT = ROOT / "configs" / "flat.toml"


def cli(*args: str, cache: Path, cwd: Path | None = None,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return warm_cli(*args, cwd=cwd, env={"RFW_FETCH": None, "RFW_CACHE": str(cache), **(env or {})})


def one_line(done: subprocess.CompletedProcess, *needles: str) -> str:
    assert done.returncode == 2, (done.stdout, done.stderr)
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    assert "Traceback" not in done.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def fake_entry(cache: Path, name: str = "boxtextured") -> Path:
    """A cache entry as a fetch leaves it (the pinned archive's hash, the GLB's size and
    hash), holding a small generated scene: no network needed."""
    spec = SCENES[name]
    scene = stress(3)
    glb = scene_to_glb(scene)
    cache.mkdir(parents=True, exist_ok=True)
    (cache / f"{name}.glb").write_bytes(glb)
    (cache / f"{name}.LICENSE.txt").write_text("test license\n")
    info = {"name": name, "format": FORMAT, "package": spec.source.package,
            "version": spec.source.version, "sha256": spec.source.sha256,
            "license": spec.license, "triangles": scene.triangle_count,
            "meshes": len(scene.meshes), "glb_bytes": len(glb),
            "glb_sha256": hashlib.sha256(glb).hexdigest()}
    (cache / f"{name}.json").write_text(json.dumps(info))
    return cache / f"{name}.glb"


def run(out: Path, cache: Path, *args: str, config: Path = FLAT,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return cli("run", str(config), "--size", "32x18", "--out", str(out), *args, cache=cache,
               env=env, cwd=out.parent)


def image(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA"))


def test_unknown_name_lists_close_matches(tmp_path):
    line = one_line(run(tmp_path / "o", tmp_path / "c", "--scene", "dragn"),
                    "'dragn'", "did you mean 'dragon'?", "rfw scenes list", "scene")
    assert "flat.toml" in line
    one_line(run(tmp_path / "o", tmp_path / "c", "--scene", "courtyrd"),
             "did you mean 'courtyard'?")
    # a name nothing resembles: no guess, still the way to the names
    line = one_line(run(tmp_path / "o", tmp_path / "c", "--scene", "qqqzzz"), "'qqqzzz'")
    assert "did you mean" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"] or not (tmp_path / "o").exists()


def test_name_not_cached_says_how_to_fetch(tmp_path):
    one_line(run(tmp_path / "o", tmp_path / "c", "--scene", "boxtextured"),
             "'boxtextured' is not fetched yet", "rfw scenes fetch boxtextured", "--fetch",
             "RFW_FETCH=1")
    assert not (tmp_path / "c").exists()  # nothing fetched, no cache folder made


def test_fetch_allowed_without_the_registry_client_is_one_line(tmp_path):
    # --fetch (and RFW_FETCH=1) try: with no client on PATH the fetch fails in one line
    empty = tmp_path / "bin"
    empty.mkdir()
    for args, env in ((["--fetch"], {}), ([], {"RFW_FETCH": "1"})):
        done = run(tmp_path / "o", tmp_path / "c", "--scene", "boxtextured", *args,
                   env={"PATH": str(empty), **env})
        one_line(done, "cannot fetch scene 'boxtextured'", "apt-get", "rfw scenes fetch")
    assert not (tmp_path / "c" / "boxtextured.glb").exists()


def test_cached_name_renders_its_glb(tmp_path):
    cache = tmp_path / "c"
    glb = fake_entry(cache)
    by_name = run(tmp_path / "name", cache, "--scene", "boxtextured")
    assert by_name.returncode == 0, by_name.stderr
    by_path = run(tmp_path / "path", cache, "--scene", str(glb))
    assert by_path.returncode == 0, by_path.stderr
    default = run(tmp_path / "default", cache)
    assert default.returncode == 0, default.stderr
    a, b, c = (image(tmp_path / d / "flat.color.png") for d in ("name", "path", "default"))
    assert np.array_equal(a, b)
    assert changed_share(a, c) > 0.25  # control: the courtyard is another picture (84 %)
    timings = json.loads((tmp_path / "name" / "timings.json").read_text())
    assert timings["triangles"] == 3 * 12
    # a config's scene may be a name too
    cfg = tmp_path / "named.toml"
    cfg.write_text(FLAT.read_text().replace('scene = "default"', 'scene = "boxtextured"'))
    assert run(tmp_path / "cfg", cache, config=cfg).returncode == 0
    assert np.array_equal(image(tmp_path / "cfg" / "flat.color.png"), a)
    # control: a damaged GLB is not taken for the scene
    data = bytearray(glb.read_bytes())
    data[-1] ^= 0xFF
    glb.write_bytes(bytes(data))
    one_line(run(tmp_path / "bad", cache, "--scene", "boxtextured"), "not fetched yet")


def test_scenes_list(tmp_path):
    cache = tmp_path / "c"
    fake_entry(cache)
    done = cli("scenes", "list", cache=cache)
    assert done.returncode == 0, done.stderr
    rows = {ln.split()[0]: ln for ln in done.stdout.splitlines()[1:-1]}
    assert list(rows) == ["default", "courtyard", "cornell", "spheres", "stress", *SCENES]
    assert "built-in" in rows["courtyard"]
    box = rows["boxtextured"].split()
    assert box[1:4] == ["fetch", "(debian)", "yes"] and "36 tris" in rows["boxtextured"]
    # a small file in kB, not "0.0 MB"
    size = (cache / "boxtextured.glb").stat().st_size
    assert size < 1e6 and f"{size / 1e3:.1f} kB, 36 tris" in rows["boxtextured"]
    assert "CC-BY-4.0" in rows["boxtextured"]
    assert rows["dragon"].split()[3] == "no" and "non-commercial" in rows["dragon"]
    assert done.stdout.splitlines()[-1].startswith(f"cache: {cache}")
    other = cli("scenes", "list", "--cache", str(tmp_path / "other"), cache=cache)
    assert "boxtextured" in other.stdout
    row = next(ln for ln in other.stdout.splitlines() if ln.startswith("boxtextured"))
    assert row.split()[3] == "no"  # control: another cache has nothing


def test_view_takes_names_too(tmp_path):
    # refused before any window opens: one line, as rfw run says it
    done = cli("view", str(FLAT), "--scene", "dragn", "--frames", "1", cache=tmp_path / "c")
    one_line(done, "--scene", "did you mean 'dragon'?")
    done = cli("view", str(FLAT), "--scene", "boxtextured", "--frames", "1",
               cache=tmp_path / "c")
    one_line(done, "'boxtextured' is not fetched yet", "rfw scenes fetch boxtextured")


def test_a_config_and_the_python_api_take_scene_names(tmp_path):
    cache = tmp_path / "c"
    fake_entry(cache)
    by_flag = tmp_path / "flag"
    assert run(by_flag, cache, "--scene", "boxtextured").returncode == 0
    # scene = "boxtextured" in a config (beside it: no file of that name)
    config = tmp_path / "named.toml"
    assert 'scene = "default"' in FLAT.read_text()
    config.write_text(FLAT.read_text().replace('scene = "default"', 'scene = "boxtextured"'))
    by_config = tmp_path / "config"
    done = run(by_config, cache, config=config)
    assert done.returncode == 0, done.stderr
    # rfw.run(..., scene=NAME), and a misspelt name as one RfwError with the close match
    code = ("import sys, rfw\n"
            f"r = rfw.run({str(FLAT)!r}, scene='boxtextured', size=(32, 18))\n"
            f"r.save({str(tmp_path / 'api')!r})\n"
            "try:\n"
            f"    rfw.run({str(FLAT)!r}, scene='boxtexturd', size=(32, 18))\n"
            "except rfw.RfwError as e:\n"
            "    print('refused:', e)\n")
    api = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=False, env={**os.environ, "RFW_CACHE": str(cache)})
    assert api.returncode == 0, api.stderr
    assert "refused:" in api.stdout and "did you mean 'boxtextured'?" in api.stdout
    expected = image(by_flag / "flat.color.png")
    assert np.array_equal(image(by_config / "flat.color.png"), expected)
    assert np.array_equal(image(tmp_path / "api" / "flat.color.png"), expected)
    # negative control: the default scene's image is another
    default = tmp_path / "default"
    assert run(default, cache).returncode == 0
    assert changed_share(image(default / "flat.color.png"), expected) > 0.25  # 84 %


def test_bench_and_view_say_how_to_fetch_and_take_fetch(tmp_path):
    # not cached: the hint names --fetch, which both commands take
    line = one_line(cli("bench", "flat", "--scene", "boxtextured", "--frames", "1",
                        "--repeat", "1", "--out", str(tmp_path / "b"), cache=tmp_path / "c"),
                    "'boxtextured'", "--fetch")
    assert "not fetched yet" in line
    for command in ("bench", "view"):
        done = cli(command, "--help", cache=tmp_path / "c")
        assert "--fetch" in done.stdout
    # cached, bench runs the named scene (--fetch then has nothing to fetch)
    fake_entry(tmp_path / "c")
    done = cli("bench", "flat", "--scene", "boxtextured", "--fetch", "--size", "32x18",
               "--frames", "1", "--warmup", "0", "--repeat", "1", "--no-progress", "--out",
               str(tmp_path / "b"), cache=tmp_path / "c", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "b" / "RUN-FAILED.txt").exists()
