"""Backends are plug-ins: what a backend offers the one frame driver (``rfw.render.render``),
and the ``rfw.backends`` entry-point group that names them.

rfw's own ``wgpu`` and ``vk`` register there like a third-party backend would::

    [project.entry-points."rfw.backends"]
    my_api = "my_package.backend:MyBackend"

The entry point names a class (or any callable) that takes no arguments and returns an
object with the :class:`Backend` members; :class:`BackendBase` gives the optional ones.
rfw itself never imports a backend's package: it loads it from the group when a run asks
for it by name (``rfw run --backend NAME``, a pass pinned with ``backend = "NAME"``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol

from .errors import RfwError, did_you_mean
from .options import DEFAULT, ENVIRONMENT, UUID_PREFIX, RunOptions
from .plugins import entry_points

if TYPE_CHECKING:
    import numpy as np

    from .backends.base import FrameExecutor
    from .graph import CompiledGraph
    from .graph.graph import Graph
    from .passes import Pass

ENTRY_POINT_GROUP = "rfw.backends"
BUILTIN = ("wgpu", "vk")  # the order mixed frames list their sides in (others follow, sorted)


class Backend(Protocol):
    """What the frame driver asks of a backend, in the order a run asks it."""

    name: str  # as registered: "wgpu", "vk"
    auto_variants: bool  # auto variants resolve for this device's caps (else: their last option)
    host_writes_depth: bool  # a bridge can upload a depth image (else it arrives as r32float)

    def make_device(self, *, label: str | None = None, options: RunOptions = DEFAULT) -> Any:
        """A new device as ``options`` ask: ``validation`` (the API's validation layer, where
        it has one), ``gpu`` (which of the machine's devices), ``async_queue``."""

    def owns(self, device: Any) -> bool:
        """Whether ``device`` is one of this backend's (a run may be handed any backend's)."""

    def describe(self, device: Any) -> dict[str, Any]:
        """timings.json's ``device``, ``driver``, ``api`` and ``backend``; optionally
        ``uuid`` (32 hex digits, or None with ``uuid_note`` saying why), which a bench run
        records (docs/multi-gpu.md)."""

    def caps(self, device: Any) -> frozenset[str]:
        """The capabilities the device gives passes (``Pass.requires`` names them)."""

    def timestamps(self, device: Any) -> bool:
        """Whether per-pass GPU times come from timestamp queries on this device."""

    def fit(self, graph: Graph, device: Any, *, readback: bool = True,
            options: RunOptions = DEFAULT) -> tuple[CompiledGraph, Any]:
        """Compile ``graph`` for the device and check the plan fits it (image limits, exact
        memory sizes; ``options.alias``: transients share memory, ``options.order_seed``);
        returns the plan and what ``executor`` needs of the fitting."""

    def check(self, plan: CompiledGraph, passes: dict[str, Pass]) -> None:
        """Refuse passes the backend cannot run, before anything is uploaded."""

    def scene(self, device: Any, scene: Any, camera: Any, size: tuple[int, int]) -> Any:
        """The scene uploaded, its viewport set to ``size``; has ``default_light`` and
        ``destroy()``."""

    def executor(self, device: Any, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: Any, *, readback: tuple[str, ...],
                 fitted: Any, options: RunOptions = DEFAULT) -> FrameExecutor:
        """The executor of ``plan`` (``begin_frame``/``record``/``flush``/``end_frame``,
        ``read``, ``timings``, ``destroy``), running as ``options`` say (frames in flight,
        aliasing, the backend's own switches)."""

    def read_bridge(self, executor: Any, bridge: str, resource: str) -> np.ndarray:
        """A resource read back to the host at bridge pass ``bridge`` (its source side)."""

    def write_bridge(self, executor: Any, bridge: str, resource: str, data: Any) -> None:
        """A bridge's host copy written into ``resource`` (its destination side)."""

    def collect(self, executor: Any) -> dict[str, Any]:
        """timings.json fields read from the executor before it is destroyed."""

    def report(self, executor: Any, device: Any, *, validation: bool) -> dict[str, Any]:
        """timings.json fields known once executor and (owned) device are destroyed."""

    def destroy_device(self, device: Any) -> None:
        """Release a device ``make_device`` made."""


class BackendBase:
    """Defaults for a backend's optional members; subclass it and fill in the rest."""

    name = ""
    auto_variants = False
    host_writes_depth = True

    def owns(self, device: Any) -> bool:
        return False

    def timestamps(self, device: Any) -> bool:
        return False

    def check(self, plan: CompiledGraph, passes: dict[str, Pass]) -> None:
        return None

    def collect(self, executor: Any) -> dict[str, Any]:
        return {}

    def report(self, executor: Any, device: Any, *, validation: bool) -> dict[str, Any]:
        return {}

    def destroy_device(self, device: Any) -> None:
        return None

    def list_devices(self) -> list[dict[str, Any]]:
        """The machine's devices in the driver's order (``index``, ``name``, ``kind``,
        ``uuid``), where the backend can list them without opening one; else []."""
        return []


MEMBERS = ("name", "auto_variants", "host_writes_depth", "make_device", "owns", "describe",
           "caps", "timestamps", "fit", "check", "scene", "executor", "read_bridge",
           "write_bridge", "collect", "report", "destroy_device")

_loaded: dict[str, Backend] = {}


GPU_ENV = ENVIRONMENT["gpu"]  # which GPU of the machine a backend opens (RunOptions.gpu)


def fake_uuid(index: int) -> str:
    """The synthetic UUID of device ``index`` under ``RFW_FAKE_GPUS`` (a test aid): 32 hex
    digits no real device has."""
    return "fa4e" * 6 + f"{index:08x}"


def pick_gpu(devices: list[tuple[str, Any]], choice: int | str, found: str, *,
             uuid_of: Callable[[Any], str | None] | None = None) -> Any:
    """The device ``choice`` (the run option ``gpu``) names among ``devices`` ((kind,
    device) in the driver's order; kind ``gpu`` or ``cpu``): an index counts among the GPUs,
    or among the CPU devices where there is no GPU; ``uuid:<hex>`` is the device whose
    ``uuid_of`` (32 lowercase hex digits) it is, of either kind."""
    if isinstance(choice, str):
        want = choice.removeprefix(UUID_PREFIX)
        if uuid_of is None:
            raise RfwError(f"asks for device {choice}, and these devices report no UUID: "
                           f"{found}", element=GPU_ENV)
        match = [d for _, d in devices if uuid_of(d) == want]
        if not match:
            have = ", ".join(str(uuid_of(d)) for _, d in devices) or "none"
            raise RfwError(f"no device has UUID {want} (this machine's have {have})",
                           element=GPU_ENV)
        return match[0]
    kind = "gpu" if any(k == "gpu" for k, _ in devices) else "cpu"
    pool = [d for k, d in devices if k == kind]
    if choice >= len(pool):
        raise RfwError(f"asks for device {choice}, and this machine has {len(pool)} "
                       f"{kind.upper()} device(s): {found}", element=GPU_ENV)
    return pool[choice]


def installed() -> list[str]:
    """The names registered in the ``rfw.backends`` group, built-ins first."""
    return order({ep.name for ep in entry_points(ENTRY_POINT_GROUP)})


def order(names: Iterable[str]) -> list[str]:
    """Built-ins in their order, then the others sorted."""
    names = set(names)
    return [n for n in BUILTIN if n in names] + sorted(names - set(BUILTIN))


def get_backend(name: str, *, file: str | None = None,
                element: str | None = "--backend") -> Backend:
    """The backend registered as ``name``, loaded on first use; an unknown or empty name is
    one line naming the installed ones."""
    if name in _loaded:
        return _loaded[name]
    eps = {ep.name: ep for ep in entry_points(ENTRY_POINT_GROUP)}
    if isinstance(name, str) and not name.strip():  # --backend '': not "the default"
        raise RfwError(f"names no backend; installed: {', '.join(order(eps)) or 'none'}",
                       file=file, element=element)
    ep = eps.get(name) if isinstance(name, str) else None
    if ep is None:
        raise RfwError(f"unknown backend {name!r}" + did_you_mean(str(name), eps)
                       + f"; installed: {', '.join(order(eps)) or 'none'}", file=file,
                       element=element)
    try:
        backend = ep.load()()
    except RfwError:
        raise
    except Exception as e:  # a broken plugin is one line, not a traceback
        raise RfwError(f"cannot load backend '{name}' ({ep.value}) from the "
                       f"'{ENTRY_POINT_GROUP}' entry points: {type(e).__name__}: {e}",
                       file=file, element=element) from e
    missing = [m for m in MEMBERS if not hasattr(backend, m)]
    if missing or backend.name != name:
        why = f"lacks {', '.join(missing)}" if missing else f"calls itself '{backend.name}'"
        raise RfwError(f"backend '{name}' ({ep.value}) {why}", file=file, element=element)
    _loaded[name] = backend
    return backend


def reload() -> None:
    """Forget loaded backends (after installing one)."""
    _loaded.clear()


class Devices:
    """The devices of one run, one per backend: a given device serves the backend that owns
    it, the others are made on first use (as ``options`` ask: validation, GPU, queues) and
    destroyed by ``close``."""

    def __init__(self, given: Iterable[Any] = (), *, options: RunOptions = DEFAULT):
        self.given = [d for d in given if d is not None]
        self.options = options
        self.devices: dict[str, Any] = {}
        self.made: list[tuple[Backend, Any]] = []

    def get(self, backend: Backend) -> Any:
        if backend.name not in self.devices:
            device = next((d for d in self.given if backend.owns(d)), None)
            if device is None:
                device = backend.make_device(options=self.options)
                self.made.append((backend, device))
            self.devices[backend.name] = device
        return self.devices[backend.name]

    def close(self) -> None:
        """Destroy the devices made here, newest first (validation's leak reports arrive
        now, so a run counts messages after this)."""
        while self.made:
            backend, device = self.made.pop()
            backend.destroy_device(device)
