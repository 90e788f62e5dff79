"""Pass registry: ``@register_pass("id")``; passes are found through the ``rfw.passes``
entry-point group, the built-ins in ``passes/<id>/`` (listed in rfw's pyproject.toml) like
third-party ones."""

from __future__ import annotations

import os
from collections.abc import Callable

from .errors import RfwTypeError, check_identifier, check_path, check_type, type_name
from .graph.errors import GraphError, did_you_mean
from .passes import REPLAY, Pass
from .plugins import entry_points

ENTRY_POINT_GROUP = "rfw.passes"
_REGISTRY: dict[str, type[Pass]] = {}
_loaded = False


def register_pass(pass_id: str, *, folder: str | os.PathLike | None = None,
                  ) -> Callable[[type[Pass]], type[Pass]]:
    """Class decorator: make a pass available to configs under ``pass_id``. ``folder``
    names the folder of its shader files (default: beside the file defining the class;
    a class defined in a notebook or the REPL needs it, or its shaders as
    ``shader_source`` text)."""
    check_type(pass_id, "pass_id", str, "a pass id (str)", element="rfw.register_pass")
    where = f"@register_pass({pass_id!r})"
    check_identifier("pass", pass_id, element=where)
    shaders = None
    if folder is not None:
        shaders = check_path(folder, "folder", element=where).resolve()
        if not shaders.is_dir():
            raise GraphError(f"'folder' {str(shaders)!r} is not a folder", element=where)

    def wrap(cls: type[Pass]) -> type[Pass]:
        if not (isinstance(cls, type) and issubclass(cls, Pass)):
            raise RfwTypeError(f"needs a Pass subclass, not {type_name(cls)}", element=where)
        if shaders is not None:
            cls.shader_folder = shaders
        old = _REGISTRY.get(pass_id)
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__,
                                                                      cls.__qualname__):
            raise GraphError(f"pass id '{pass_id}' is registered twice: by "
                             f"{old.__module__}.{old.__qualname__} and "
                             f"{cls.__module__}.{cls.__qualname__}")
        if cls.replay not in REPLAY:
            raise GraphError(f"'replay' must be \"auto\" or False, not {cls.replay!r}",
                             element=where)
        cls.id = pass_id
        if cls.shader:  # a bad shader_source, or no file to find shaders beside: here,
            cls.folder()  # when the class is defined, not at its first render
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
    check_type(pass_id, "pass_id", str, "a pass id (str)", file=file,
               element=element or "rfw.get_pass")
    _load_all()
    try:
        return _REGISTRY[pass_id]
    except KeyError:
        raise GraphError(f"unknown pass '{pass_id}'" + did_you_mean(pass_id, _REGISTRY),
                         file=file, element=element) from None


def available() -> dict[str, type[Pass]]:
    _load_all()
    return dict(sorted(_REGISTRY.items()))
