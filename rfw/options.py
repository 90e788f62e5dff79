"""How a run runs, read once at the edge and passed down: :class:`RunOptions`.

The CLI, the Python API (:func:`rfw.render.render`, :func:`rfw.api.run`,
:class:`rfw.api.Session`, the default device of ``rfw.raycast``) and the bench worker build
one ``RunOptions`` from their arguments and the environment (``RunOptions.from_env``: the
``RFW_*`` variables of :mod:`rfw.env`, each checked there), and hand it to the frame driver,
which hands it to the backends, their devices and executors. A config's own keys
(``frames``, ``frames_in_flight``) stand between the two: :meth:`RunOptions.in_flight`. Nothing
below the edge reads the environment for these: tests/core/test_architecture.py checks that
only :mod:`rfw.env` touches ``os.environ`` for rfw and only this module names a run option's
variable, tests/core/test_options.py which modules read :mod:`rfw.env` and which call
``from_env``.

Where files live (``RFW_CACHE*``), whether scenes may be fetched (``RFW_FETCH``), a window's
format (``RFW_VIEW_FORMAT``), the commit a report names (``RFW_COMMIT``) and where ray streams
live (``RFW_RAYCAST_MAPPED``) are not options of a run: they say where the process keeps
things, and their readers are listed in the test.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from . import env
from .env import ASYNC_QUEUES, MAX_FRAMES_IN_FLIGHT, MAX_SEED, UUID_PREFIX
from .errors import (
    RfwTypeError,
    RfwValueError,
    check_bool,
    check_number,
    did_you_mean,
    type_name,
)

# the bounds rfw.env checks the variables against are the options' own
DEFAULT_FRAMES_IN_FLIGHT = 2

# field -> the environment variable it falls back to (rfw.env reads and checks it)
ENVIRONMENT = {
    "default_in_flight": "RFW_FRAMES_IN_FLIGHT",
    "order_seed": "RFW_ORDER_SEED",
    "poison": "RFW_POISON",
    "bundles": "RFW_VK_BUNDLES",
    "frame_replay": "RFW_VK_FRAME_REPLAY",
    "frame_span": "RFW_VK_FRAME_SPAN",
    "async_queue": "RFW_VK_ASYNC_QUEUE",
    "gpu": "RFW_GPU",
}


@dataclass(frozen=True)
class RunOptions:
    """Everything about how frames run that is not the config's graph or scene.

    ``frames``: timed frames (None: the config's); ``warmup``: untimed frames before them;
    ``frames_in_flight``: frames on the GPU while the next records (None: the config's,
    else ``default_in_flight``; 1 waits for each); ``default_in_flight``: where neither the
    run nor the config says (``RFW_FRAMES_IN_FLIGHT``, below a config's key as
    docs/environment.md has it; 2); ``validation``: the API's validation layer on a device the run
    makes; ``alias``: transients share memory where the backend places it (vk);
    ``order_seed`` / ``poison``: schedule fuzzing (vk: a seeded legal reordering, poisoned
    transients); ``bundles`` / ``frame_replay``: vk's record-once caches (off: the
    baseline a benchmark measures them against); ``frame_span``: vk async compute on one
    queue family; ``async_queue``: ``family`` (a compute-only family) or ``graphics``;
    ``gpu``: the device index among the machine's GPUs, or ``uuid:<hex>`` (NVML's
    ``GPU-...`` is taken too): the device with that UUID (None: the first)."""

    frames: int | None = None
    warmup: int = 1
    frames_in_flight: int | None = None
    default_in_flight: int = DEFAULT_FRAMES_IN_FLIGHT
    validation: bool = False
    alias: bool = True
    order_seed: int | None = None
    poison: bool = False
    bundles: bool = True
    frame_replay: bool = True
    frame_span: bool = False
    async_queue: str = "family"
    gpu: int | str | None = None

    def __post_init__(self) -> None:
        where = "options"
        if isinstance(self.gpu, str):  # a UUID, kept as uuid:<32 lowercase hex digits>
            digits = env.uuid_hex(self.gpu) if self.gpu.startswith(
                (UUID_PREFIX, "GPU-")) else None
            if digits is None:
                raise RfwValueError(f"'gpu' must be a device index, uuid:<32 hex digits> or "
                                    f"GPU-<uuid>, not {self.gpu!r}", element=where)
            object.__setattr__(self, "gpu", UUID_PREFIX + digits)
        for name in ("frames", "frames_in_flight", "order_seed", "gpu"):
            value = getattr(self, name)
            if name == "gpu" and isinstance(value, str):
                continue
            if value is not None:
                hi = {"frames": None, "frames_in_flight": MAX_FRAMES_IN_FLIGHT,
                      "order_seed": MAX_SEED, "gpu": None}[name]
                lo = 0 if name in ("order_seed", "gpu") else 1
                check_number(value, name, kind=int, lo=lo, hi=hi, element=where)
        check_number(self.warmup, "warmup", kind=int, lo=0, element=where)
        check_number(self.default_in_flight, "default_in_flight", kind=int, lo=1,
                     hi=MAX_FRAMES_IN_FLIGHT, element=where)
        for name in ("validation", "alias", "poison", "bundles", "frame_replay",
                     "frame_span"):
            check_bool(getattr(self, name), name, element=where)
        if self.async_queue not in ASYNC_QUEUES:
            raise RfwValueError(f"'async_queue' must be one of {', '.join(ASYNC_QUEUES)}, "
                               f"not {self.async_queue!r}", element=where)

    @classmethod
    def from_env(cls, **given: Any) -> RunOptions:
        """Options from ``given`` (None: not given) with the environment's ``RFW_*``
        variables (:data:`ENVIRONMENT`) for the fields not given, then the defaults.
        Only the edge calls this: the CLI, the API's entry points, a bench worker."""
        names = {f.name for f in dataclasses.fields(cls)}
        for key in given:
            if key not in names:
                raise RfwTypeError(f"no run option '{key}'" + did_you_mean(key, names),
                                   element="options")
        values = {k: v for k, v in given.items() if v is not None}
        for name, var in ENVIRONMENT.items():
            if name not in values:
                read = env.get(var)
                if read is not None:
                    values[name] = read
        return cls(**values)

    def replace(self, **changes: Any) -> RunOptions:
        """A copy with ``changes`` (None: keep this one's value)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def in_flight(self, config_value: int | None = None) -> int:
        """Frames in flight: this run's, else the config's, else ``default_in_flight``."""
        for value in (self.frames_in_flight, config_value):
            if value is not None:
                return value
        return self.default_in_flight


DEFAULT = RunOptions()


def check_options(value: Any) -> RunOptions:
    """``value`` when it is RunOptions (None: the defaults); else a one-line type error."""
    if value is None:
        return DEFAULT
    if not isinstance(value, RunOptions):
        raise RfwTypeError(f"'options' must be rfw.RunOptions, not {type_name(value)}",
                           element="options")
    return value
