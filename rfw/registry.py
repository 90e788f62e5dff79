"""Pass registry: ``@register_pass("id")``; passes are found through the ``rfw.passes``
entry-point group, the built-ins in ``passes/<id>/`` (listed in rfw's pyproject.toml) like
third-party ones."""

from __future__ import annotations

from collections.abc import Callable

from .graph.errors import GraphError, did_you_mean
from .passes import Pass
from .plugins import entry_points

ENTRY_POINT_GROUP = "rfw.passes"
_REGISTRY: dict[str, type[Pass]] = {}
_loaded = False


def register_pass(pass_id: str) -> Callable[[type[Pass]], type[Pass]]:
    """Class decorator: make a pass available to configs under ``pass_id``."""

    def wrap(cls: type[Pass]) -> type[Pass]:
        if not (isinstance(cls, type) and issubclass(cls, Pass)):
            raise TypeError(f"@register_pass('{pass_id}') needs a Pass subclass, got {cls!r}")
        old = _REGISTRY.get(pass_id)
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__,
                                                                      cls.__qualname__):
            raise GraphError(f"pass id '{pass_id}' is registered twice: by "
                             f"{old.__module__}.{old.__qualname__} and "
                             f"{cls.__module__}.{cls.__qualname__}")
        cls.id = pass_id
        _REGISTRY[pass_id] = cls
        return cls

    return wrap


def _load_all() -> None:
    # every module the group names registers its passes as it is imported
    global _loaded
    if _loaded:
        return
    _loaded = True
    for ep in entry_points(ENTRY_POINT_GROUP):
        try:
            ep.load()
        except Exception as e:  # a broken plugin must not hide the others
            raise GraphError(f"cannot load pass plugin '{ep.name}' ({ep.value}) from the "
                             f"'{ENTRY_POINT_GROUP}' entry points: {e}") from e


def reload() -> None:
    """Look for built-in and installed passes again (after installing a plugin)."""
    global _loaded
    _loaded = False
    _load_all()


def get_pass(pass_id: str, *, file: str | None = None,
             element: str | None = None) -> type[Pass]:
    """The class registered as ``pass_id``; an unknown id is a GraphError naming ``file`` and
    ``element`` (the config and its pass) with the closest ids."""
    _load_all()
    try:
        return _REGISTRY[pass_id]
    except KeyError:
        raise GraphError(f"unknown pass '{pass_id}'" + did_you_mean(pass_id, _REGISTRY),
                         file=file, element=element) from None


def available() -> dict[str, type[Pass]]:
    _load_all()
    return dict(sorted(_REGISTRY.items()))
