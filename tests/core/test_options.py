"""Run options (rfw.options.RunOptions): read once at the edge, from the command line, then
the environment, with a config's keys between the two, and passed down to the backends;
nothing below the edge reads the environment for them (checked in the sources here), the
CLI sets no variable to reach vkext, and what the options say reaches the vk executor."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

import rfw.render
from rfw import cli
from rfw.config import apply_overrides, build, load_config
from rfw.errors import RfwError
from rfw.options import DEFAULT, ENVIRONMENT, RunOptions, check_options

from ..conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[2]
FLAT = ROOT / "configs" / "flat.toml"


@pytest.fixture
def clean_env(monkeypatch):
    """No run option in the environment (the suite may run under some)."""
    for var in ENVIRONMENT.values():
        monkeypatch.delenv(var, raising=False)
    return monkeypatch


def _args(*argv: str):
    return cli.parser().parse_args(["run", str(FLAT), *argv])


# ---------------------------------------------------------------------------------------------
# precedence: the command line, then the environment, then the defaults; a config's keys
# between the run's and the environment's


def test_the_command_line_wins_over_the_environment(clean_env):
    clean_env.setenv("RFW_ORDER_SEED", "9")
    clean_env.setenv("RFW_POISON", "1")
    clean_env.setenv("RFW_VK_BUNDLES", "0")
    given = cli.run_options(_args("--order-seed", "5", "--no-alias", "--validate"),
                            frames=3)
    assert (given.order_seed, given.alias, given.validation, given.frames) == (5, False, True, 3)
    assert given.poison and not given.bundles  # not on the command line: the environment's
    # without the flags the environment decides; without either, the defaults
    env_only = cli.run_options(_args())
    assert (env_only.order_seed, env_only.poison, env_only.alias) == (9, True, True)
    for var in ("RFW_ORDER_SEED", "RFW_POISON", "RFW_VK_BUNDLES"):
        clean_env.delenv(var)
    assert cli.run_options(_args()) == DEFAULT


def test_every_environment_variable_reaches_its_field(clean_env):
    values = {"RFW_FRAMES_IN_FLIGHT": ("3", 3), "RFW_ORDER_SEED": ("7", 7),
              "RFW_POISON": ("yes", True), "RFW_VK_BUNDLES": ("off", False),
              "RFW_VK_FRAME_REPLAY": ("0", False), "RFW_VK_FRAME_SPAN": ("1", True),
              "RFW_VK_ASYNC_QUEUE": ("graphics", "graphics"), "RFW_GPU": ("0", 0)}
    assert set(values) == set(ENVIRONMENT.values())
    for var, (raw, _) in values.items():
        clean_env.setenv(var, raw)
    options = RunOptions.from_env()
    for field, var in ENVIRONMENT.items():
        assert getattr(options, field) == values[var][1], field
        assert getattr(DEFAULT, field) != values[var][1], field  # each one changed something


def test_a_config_key_stands_between_the_run_and_the_environment(clean_env):
    keyed = apply_overrides(load_config(FLAT), ["frames_in_flight=3"])
    plain = load_config(FLAT)
    assert plain.frames_in_flight is None
    clean_env.setenv("RFW_FRAMES_IN_FLIGHT", "1")
    options = RunOptions.from_env()
    assert options.in_flight(keyed.frames_in_flight) == 3  # the config's key wins ...
    assert options.in_flight(plain.frames_in_flight) == 1  # ... else the environment's
    ran = RunOptions.from_env(frames_in_flight=2)
    assert ran.in_flight(keyed.frames_in_flight) == 2  # the run's wins over both
    clean_env.delenv("RFW_FRAMES_IN_FLIGHT")
    assert RunOptions.from_env().in_flight(plain.frames_in_flight) == 2  # the default
    # frames: the run's, else the config's (rfw.render: options.frames or cfg.frames)
    assert cli.run_options(_args("--frames", "4"), frames=4).frames == 4
    assert cli.run_options(_args()).frames is None


def test_render_keywords_fold_into_the_options(clean_env, monkeypatch):
    seen = []
    real = rfw.render.start

    def start(*args, options, **kw):
        seen.append(options)
        return real(*args, options=options, **kw)

    monkeypatch.setattr(rfw.render, "start", start)
    cfg = apply_overrides(load_config(FLAT), ["size=16x8"])
    clean_env.setenv("RFW_FRAMES_IN_FLIGHT", "3")
    rfw.render.render(cfg, scene=tiny_scene(), frames=2, warmup=0)  # the environment's
    rfw.render.render(cfg, scene=tiny_scene(), frames_in_flight=1,
                      options=RunOptions(frames=1, warmup=2))  # given: no environment
    first, second = seen
    assert (first.frames, first.warmup, first.frames_in_flight) == (2, 0, 3)
    assert (second.frames, second.warmup, second.frames_in_flight) == (1, 2, 1)


# ---------------------------------------------------------------------------------------------
# bad values: one line naming what was wrong


@pytest.mark.parametrize(("make", "says"), [
    (lambda: RunOptions(frames=0), "'frames' must be at least 1, not 0"),
    (lambda: RunOptions(frames_in_flight=9), "'frames_in_flight' must be between 1 and 8"),
    (lambda: RunOptions(order_seed=-1), "'order_seed' must be between 0 and 4294967295"),
    (lambda: RunOptions(poison="yes"), "'poison'"),
    (lambda: RunOptions(gpu=1.0), "'gpu' must be an integer"),
    (lambda: RunOptions(async_queue="fast"), "'async_queue' must be one of family, graphics"),
    (lambda: RunOptions.from_env(framez=2), "no run option 'framez' (did you mean 'frames'"),
    (lambda: check_options({"frames": 2}), "'options' must be rfw.RunOptions, not dict"),
])
def test_a_bad_value_is_one_line(make, says):
    with pytest.raises(RfwError) as e:
        make()
    assert says in str(e.value) and "\n" not in str(e.value)


def test_a_bad_variable_is_one_line_naming_it(clean_env):
    for var, raw in (("RFW_POISON", "maybe"), ("RFW_ORDER_SEED", "-3"),
                     ("RFW_VK_ASYNC_QUEUE", "fast"), ("RFW_FRAMES_IN_FLIGHT", "9")):
        clean_env.setenv(var, raw)
        with pytest.raises(RfwError) as e:
            RunOptions.from_env()
        assert str(e.value).startswith(f"{var}: expected") and "\n" not in str(e.value)
        clean_env.delenv(var)
    assert RunOptions.from_env() == DEFAULT  # control: with them gone, nothing is refused


# ---------------------------------------------------------------------------------------------
# the command line reaches vkext through the options, not the environment


@pytest.fixture(scope="module")
def vk_device():
    vkext = pytest.importorskip("vkext")
    try:
        device = vkext.VkDevice(validation=True, label="rfw-tests-options")
    except vkext.VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")
    yield device
    device.destroy()
    device.check_validation()


def test_poison_and_order_seed_leave_the_environment_alone(clean_env, monkeypatch, tmp_path,
                                                           capsys):
    pytest.importorskip("vkext")
    from vkext import poison

    before = dict(os.environ)
    during = []
    real = rfw.render.render

    def render(*args, **kw):
        during.append((dict(os.environ), kw["options"]))
        return real(*args, **kw)

    monkeypatch.setattr(rfw.render, "render", render)
    fills = poison.STATS["fills"]
    rc = cli.main(["run", str(FLAT), "--backend", "vk", "--size", "16x8", "--frames", "1",
                   "--poison", "--order-seed", "3", "--out", str(tmp_path / "out")])
    assert rc == 0, capsys.readouterr().err
    assert dict(os.environ) == before
    (env, options), = during
    assert env == before  # not even while the run runs
    assert (options.poison, options.order_seed) == (True, 3)
    assert poison.STATS["fills"] > fills  # and they reached the vk executor


def test_an_executor_without_bundles_runs_without_bundles(vk_device):
    from rfw.frame import open_frame

    built = build(apply_overrides(load_config(FLAT), ["size=16x8"]))
    images, caches = {}, {}
    for name, options in (("default", DEFAULT), ("off", RunOptions(bundles=False))):
        frame = open_frame(built, "vk", devices=(vk_device,), scene=tiny_scene(),
                           options=options)
        try:
            ex = frame.executors["vk"]
            caches[name] = (ex.bundles, ex.sets)
            frame.run(2)
            images[name] = frame.read("flat.color")
        finally:
            frame.destroy()
    assert caches["off"] == (None, None)
    assert all(c is not None for c in caches["default"])  # negative control: the default has them
    assert (images["off"] == images["default"]).all()


# ---------------------------------------------------------------------------------------------
# nothing below the edge reads the environment for a run option

# modules that read rfw.env: what they read is no run option (docs/environment.md); that
# os.environ is read in rfw.env only, and no run option's variable is named outside
# rfw.options, is tests/core/test_architecture.py's
ENV_READERS = {
    "rfw/options.py": "RunOptions.from_env: every run option",
    "rfw/cli.py": "check_all before any command",
    "rfw/scene/names.py": "RFW_FETCH", "rfw/scene/fetch/cache.py": "RFW_CACHE",
    "rfw/spirv.py": "RFW_CACHE_SPIRV", "rfw/meshlets.py": "RFW_CACHE_MESHLETS",
    "rfw/bench/truth.py": "RFW_CACHE_TRUTH",
    "rfw/view.py": "RFW_VIEW_FORMAT", "rfw/bench/runner.py": "RFW_COMMIT",
    "vkext/raycast/placement.py": "RFW_RAYCAST_MAPPED", "vkext/external.py": "RFW_CUDA",
    # RFW_FAKE_GPUS, a test aid read by the device enumerations only
    "vkext/device.py": "RFW_FAKE_GPUS", "rfw/backends/wgpu/device.py": "RFW_FAKE_GPUS",
    "rfw/bench/gpus.py": "uuid_hex (no variable): a GPU-<uuid> as RFW_GPU takes it",
}
# the edges: where a run starts and its options are built
EDGES = {
    "rfw/cli.py", "rfw/render.py", "rfw/api.py", "rfw/bench/worker.py",
    "rfw/bench/reference.py",  # a bench reference's own process
    "rfw/bench/runner.py",  # refuses a bad variable once, before its workers start
    "rfw/raycasting.py",  # rfw.raycast's own device
}
IMPORTS_ENV = re.compile(r"from (?:rfw|\.+) import env\b|from (?:rfw|\.*)\.?env import"
                         r"|import rfw\.env")


def _modules() -> dict[str, str]:
    return {str(p.relative_to(ROOT)): p.read_text() for folder in ("rfw", "vkext", "passes")
            for p in sorted((ROOT / folder).rglob("*.py"))}


def test_only_the_edges_build_options_and_only_the_listed_modules_read_rfw_env():
    modules = _modules()
    assert len(modules) > 100
    env_readers = {m for m, text in modules.items() if IMPORTS_ENV.search(text)}
    assert env_readers == set(ENV_READERS), env_readers ^ set(ENV_READERS)
    builders = {m for m, text in modules.items() if "from_env(" in text} - {"rfw/options.py"}
    assert builders == EDGES, builders ^ EDGES


def test_the_source_check_catches_a_reader():
    # negative control: the pattern finds what it is meant to find
    assert IMPORTS_ENV.search("    from rfw import env\n")
    assert IMPORTS_ENV.search("from ..env import get\n")
    assert IMPORTS_ENV.search("from . import env\n")
    assert not IMPORTS_ENV.search("from .envelope import x\n")
