"""Scenes by name: ``--scene dragon`` is the fetched scene's GLB in the cache.

A scene argument is, in this order: a built-in scene (``default``, ``courtyard``,
``cornell``, ``spheres``, ``stress``, ``stress:COUNT``), an existing file, a file path (it has a suffix: left to the
loader, which says it is not found), or the name of a fetchable scene
(:data:`rfw.scene.fetch.SCENES`). A fetchable scene not in the cache is fetched on demand
only when allowed (``rfw run --fetch`` or ``RFW_FETCH=1``), with a progress bar; otherwise,
and for names nobody knows, one line says what to do.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from ..errors import close_matches
from .model import SceneError

FETCH_ENV = "RFW_FETCH"  # 1: fetch a named scene that is not cached yet


def config_scene(cfg: Any, *, fetch: bool = False, flag: bool = False) -> Any:
    """``cfg`` with its scene resolved as the loaders take it (:func:`resolve_scene`: a
    fetched scene's name becomes its cached GLB, fetched first with ``fetch``). ``flag``:
    the name came from ``--scene`` (an error names that, else the config's ``scene``)."""
    from dataclasses import replace

    return replace(cfg, scene=resolve_scene(cfg.scene, fetch=fetch, file=cfg.source,
                                            element="--scene" if flag else "scene"))


def fetch_allowed(flag: bool = False) -> bool:
    """``flag`` (``--fetch``), else ``RFW_FETCH`` (1/true/yes/on; 0/false/no/off or unset:
    no; anything else is refused, :func:`rfw.env.flag`)."""
    from .. import env

    return flag or env.get(FETCH_ENV)


def known_names() -> list[str]:
    """Every scene name: the built-in ones, then the fetchable ones."""
    from . import BUILTIN_SCENES
    from .fetch.catalogue import SCENES

    return [*BUILTIN_SCENES[:-1], *SCENES]  # stress:COUNT is a pattern, not a name


def resolve_scene(text: str, *, fetch: bool = False, cache: Path | None = None,
                  file: str | None = None, element: str = "scene") -> str:
    """What ``text`` names, as the loaders take it: the text itself for built-in scenes,
    files and paths, the cached GLB's path for a fetchable scene's name (fetched first when
    ``fetch`` allows and it is not cached).

    Raises
    ------
    SceneError
        For an unknown name (with the close matches), a fetchable scene that is not cached
        and may not be fetched (how to fetch it), or a fetch that failed.
    """
    from . import is_builtin

    if not text.strip():  # Path("") is "."; the default scene would show without a word
        raise SceneError(f"{text!r} names no scene: give a scene file, a built-in scene "
                         f"(default, courtyard, cornell, spheres, stress:COUNT) or a name from "
                         f"'rfw scenes list'",
                         file=file, element=element)
    path = Path(text)
    if is_builtin(text) or path.exists() or path.suffix or not path.name:
        return text
    name = path.name  # a config's "scene = 'dragon'" arrives as configs/dragon
    from .fetch.cache import cached, default_cache
    from .fetch.catalogue import SCENES

    spec = SCENES.get(name)
    if spec is None:
        near = close_matches(name, known_names())
        hint = f"did you mean {' or '.join(repr(m) for m in near)}? " if near else ""
        raise SceneError(f"no scene file or scene named {name!r}: {hint}('rfw scenes list' "
                         f"shows the scene names; a file needs its suffix, e.g. .glb)",
                         file=file, element=element)
    cache = cache if cache is not None else default_cache()
    glb = cache / f"{name}.glb"
    if cached(spec, cache) is not None:
        return str(glb)
    if not fetch_allowed(fetch):
        raise SceneError(f"scene {name!r} is not fetched yet: run 'rfw scenes fetch {name}' "
                         f"(or add --fetch, or set {FETCH_ENV}=1, to fetch it on demand)",
                         file=file, element=element)
    _fetch_with_progress(name, cache, file=file, element=element)
    return str(glb)


def _fetch_with_progress(name: str, cache: Path, *, file: str | None, element: str) -> None:
    """Fetch one scene with a progress bar on stderr (a log gets its lines on stdout, so
    stderr keeps to the one error line of a failure)."""
    from .fetch.cache import fetch
    from .fetch.download import FetchError

    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=1, unit="scene", desc=f"fetching {name}", file=sys.stderr,
                   leave=False)

    def report(line: str) -> None:
        if line.startswith("rfw: error:"):
            return  # the error becomes this function's one line
        if bar is not None:
            bar.write(line, file=sys.stderr)
        else:
            print(f"rfw: {line}", flush=True)

    if bar is None:
        print(f"rfw: fetching scene {name!r} into {cache} ...", flush=True)
    try:
        results = fetch([name], cache, report=report)
    except FetchError as e:
        raise SceneError(f"cannot fetch scene {name!r}: {e}", file=file,
                         element=element) from None
    finally:
        if bar is not None:
            bar.update(1)
            bar.close()
    failed = [r for r in results if isinstance(r, FetchError)]
    if failed:
        raise SceneError(f"cannot fetch scene {name!r}: {failed[0]} (without a network, "
                         f"fetch it where there is one: 'rfw scenes fetch {name}', then copy "
                         f"the cache folder {cache})", file=file, element=element)


BUILTIN_ROWS = (
    ("default", "the generated courtyard (alias of courtyard)"),
    ("courtyard", "the generated courtyard: columns, fountain, textured floor"),
    ("cornell", "a Cornell box with a point light (Lambert; rfw.truth's agreement scene)"),
    ("spheres", "a Lambert and a rough metal sphere on a plane, sun and sky (agreement scene)"),
    ("stress", "100,000 generated cubes (stress:COUNT for another count)"),
)


def scene_table(cache: Path) -> str:
    """``rfw scenes list``: the built-in and fetchable scenes, what is cached (GLB size and
    triangles), each scene's license and description; the cache folder last."""
    from .fetch.cache import byte_size, cached
    from .fetch.catalogue import SCENES

    rows = [("NAME", "KIND", "CACHED", "SIZE", "LICENSE", "DESCRIPTION")]
    for name, text in BUILTIN_ROWS:
        rows.append((name, "built-in", "-", "-", "rfw's own", text))
    for spec in SCENES.values():
        info = cached(spec, cache)
        size = "-" if info is None else f"{byte_size(info['glb_bytes'])}, {info['triangles']:,} tris"
        rows.append((spec.name, f"fetch ({spec.source.registry})",
                     "no" if info is None else "yes", size, spec.license, spec.description))
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    lines = ["  ".join(r[i].ljust(widths[i]) for i in range(5)) + "  " + r[5] for r in rows]
    return "\n".join(lines) + (f"\ncache: {cache} (fetch: 'rfw scenes fetch NAME', or "
                               f"'rfw run --scene NAME --fetch')\n")
