"""Every ``RFW_*`` environment variable rfw and vkext read, checked in one place.

Each variable has one reader in :data:`READERS`; code reads it with ``get(name)``, never
``os.environ``. A value that is not allowed is one line naming the variable and what it
takes (``RFW_FETCH: expected 0 or 1 (or true/false, yes/no, on/off), not 'maybe'``).
An empty value (or only spaces) counts as unset, for every variable: ``RFW_GPU=`` is the
same as no ``RFW_GPU``. ``check_all()`` reads every variable that is set, so a bad one is
refused before a command does anything, even one this command would not read.
docs/environment.md lists them all, with the cache folders.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .errors import RfwError

TRUE, FALSE = ("1", "true", "yes", "on"), ("0", "false", "no", "off")
MAX_FRAMES_IN_FLIGHT = 8  # frames submitted and not waited for (rfw.options)
MAX_SEED = 2**32 - 1  # vkext.poison's order seeds
ASYNC_QUEUES = ("family", "graphics")  # RunOptions.async_queue
_INTEGER = re.compile(r"[+-]?[0-9]+")  # ascii digits only: int() takes '٣' and '1_0'


def value(name: str) -> str | None:
    """``name``'s value without surrounding spaces; None when unset or empty."""
    raw = os.environ.get(name)
    if raw is None or not raw.strip():
        return None
    return raw.strip()


def _refuse(name: str, expected: str, raw: str) -> RfwError:
    shown = raw if len(raw) <= 60 else raw[:57] + "..."
    return RfwError(f"expected {expected}, not {shown!r}", element=name)


def flag(name: str, default: bool = False) -> bool:
    """An on/off switch: 1/0, true/false, yes/no or on/off (any case)."""
    raw = value(name)
    if raw is None:
        return default
    word = raw.lower()
    if word in TRUE or word in FALSE:
        return word in TRUE
    raise _refuse(name, "0 or 1 (or true/false, yes/no, on/off)", raw)


def choice(name: str, options: Sequence[str], default: str | None = None) -> str | None:
    """One of ``options``, spelled exactly."""
    raw = value(name)
    if raw is None:
        return default
    if raw not in options:
        listed = ", ".join(options[:-1]) + f" or {options[-1]}" if len(options) > 1 \
            else options[0]
        raise _refuse(name, listed, raw)
    return raw


def integer(name: str, lo: int, hi: int | None = None, default: int | None = None, *,
            what: str = "a whole number") -> int | None:
    """A whole number in [lo, hi] (ascii digits, an optional sign)."""
    raw = value(name)
    if raw is None:
        return default
    bounds = f"from {lo} to {hi}" if hi is not None else f"from {lo}"
    expected = f"{what} ({bounds})" if what != "a whole number" else f"{what} {bounds}"
    if not _INTEGER.fullmatch(raw):
        raise _refuse(name, expected, raw)
    number = int(raw)
    if number < lo or (hi is not None and number > hi):
        raise _refuse(name, expected, raw)
    return number


def folder(name: str) -> Path | None:
    """A folder (``~`` expanded; relative to the working folder): made on first use, so it
    need not exist, but something there that is not a folder is refused now."""
    raw = value(name)
    if raw is None:
        return None
    if "\0" in raw:
        raise _refuse(name, "a folder", raw)
    path = Path(raw).expanduser()
    if path.exists() and not path.is_dir():
        raise _refuse(name, "a folder (that path is a file)", raw)
    return path


def word(name: str, pattern: str, expected: str) -> str | None:
    """A word matching ``pattern`` (a regular expression, whole value)."""
    raw = value(name)
    if raw is None:
        return None
    if not re.fullmatch(pattern, raw):
        raise _refuse(name, expected, raw)
    return raw


UUID_PREFIX = "uuid:"  # RFW_GPU=uuid:<32 hex digits>: the device with that UUID
_UUID = re.compile(r"(?:uuid:)?(?:GPU-)?([0-9a-fA-F-]+)")
MAX_FAKE_GPUS = 64  # RFW_FAKE_GPUS, a test aid


def uuid_hex(text: str) -> str | None:
    """A device UUID as 32 lowercase hex digits, from ``uuid:<hex>``, NVML's
    ``GPU-xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxxxx`` or plain hex (dashes anywhere); None when
    ``text`` is none of them."""
    m = _UUID.fullmatch(text.strip())
    if m is None:
        return None
    digits = m.group(1).replace("-", "").lower()
    return digits if len(digits) == 32 else None


def gpu(name: str) -> int | str | None:
    """A device index (a whole number from 0) or ``uuid:<hex>`` / ``GPU-...`` (a device
    UUID, returned as ``uuid:`` and 32 lowercase hex digits)."""
    raw = value(name)
    if raw is None:
        return None
    if _INTEGER.fullmatch(raw):
        return integer(name, 0, what="a device index")
    digits = uuid_hex(raw) if raw.startswith((UUID_PREFIX, "GPU-")) else None
    if digits is None:
        raise _refuse(name, "a device index (from 0), uuid:<32 hex digits> or GPU-<uuid>",
                      raw)
    return UUID_PREFIX + digits


VIEW_FORMATS = ("bgra8unorm", "rgba8unorm", "bgra8unorm-srgb", "rgba8unorm-srgb")
RAYCAST_PLACEMENTS = ("0", "1", "rays", "hits", "host", "auto")

# name -> its reader: the meaning, the default and who reads each is in docs/environment.md
READERS: dict[str, Callable[[], Any]] = {
    "RFW_FETCH": lambda: flag("RFW_FETCH"),
    "RFW_CACHE": lambda: folder("RFW_CACHE"),
    "RFW_CACHE_SPIRV": lambda: folder("RFW_CACHE_SPIRV"),
    "RFW_CACHE_MESHLETS": lambda: folder("RFW_CACHE_MESHLETS"),
    "RFW_CACHE_TRUTH": lambda: folder("RFW_CACHE_TRUTH"),
    "RFW_GPU": lambda: gpu("RFW_GPU"),
    # a test aid: the device enumerations (vkext.device, rfw.backends.wgpu.device) list
    # their first device this many times, the vk copies with synthetic UUIDs
    "RFW_FAKE_GPUS": lambda: integer("RFW_FAKE_GPUS", 1, MAX_FAKE_GPUS, what="a device count"),
    "RFW_FRAMES_IN_FLIGHT": lambda: integer("RFW_FRAMES_IN_FLIGHT", 1, MAX_FRAMES_IN_FLIGHT),
    "RFW_ORDER_SEED": lambda: integer("RFW_ORDER_SEED", 0, MAX_SEED, what="a seed"),
    "RFW_POISON": lambda: flag("RFW_POISON"),
    "RFW_VIEW_FORMAT": lambda: choice("RFW_VIEW_FORMAT", VIEW_FORMATS),
    "RFW_COMMIT": lambda: word("RFW_COMMIT", r"[0-9A-Za-z][0-9A-Za-z._+/-]{0,99}",
                               "a commit (one word of letters, digits and ._+/-, at most 100)"),
    "RFW_VK_BUNDLES": lambda: flag("RFW_VK_BUNDLES", True),
    "RFW_VK_FRAME_REPLAY": lambda: flag("RFW_VK_FRAME_REPLAY", True),
    "RFW_VK_FRAME_SPAN": lambda: flag("RFW_VK_FRAME_SPAN"),
    "RFW_VK_ASYNC_QUEUE": lambda: choice("RFW_VK_ASYNC_QUEUE", ASYNC_QUEUES, "family"),
    "RFW_RAYCAST_MAPPED": lambda: choice("RFW_RAYCAST_MAPPED", RAYCAST_PLACEMENTS, "auto"),
    "RFW_CUDA": lambda: flag("RFW_CUDA", True),
}


def get(name: str) -> Any:
    """The value of variable ``name`` (one of :data:`READERS`), checked; its default when
    unset or empty."""
    return READERS[name]()


def check_all() -> None:
    """Read every variable that is set: a bad value is refused before anything runs."""
    for name, read in READERS.items():
        if name in os.environ:
            read()
