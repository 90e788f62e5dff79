"""Materials: metallic-roughness factors and their five textures, KHR_materials_specular's
factor, the one TEXCOORD set and KHR_texture_transform a material's textures are sampled with,
and materials tinted by a primitive's constant COLOR_0."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from typing import Any

import numpy as np
import pygltflib

from ..model import Material, Scene
from .file import GltfFile
from .textures import Textures


class Materials:
    """The materials of ``file`` as ``scene.materials``, each made once (glTF's default
    material too, when a primitive has none)."""

    def __init__(self, file: GltfFile, textures: Textures, scene: Scene):
        self.file = file
        self.textures = textures
        self.scene = scene
        # the file's material -> its index in scene.materials
        self.scene_index: dict[int, int] = {}
        self.tinted: dict[tuple[int, tuple[float, ...]], int] = {}
        # per scene material with textures: (TEXCOORD set, KHR_texture_transform 2x3 or None,
        # the file's material it comes from)
        self.uv_sets: dict[int, tuple[int, np.ndarray | None, str]] = {}
        # the textures of the material being read: (where, TEXCOORD set, transform)
        self.texture_uses: list[tuple[str, int, np.ndarray | None]] = []
        self.default_material: int | None = None

    def material(self, index: Any, where: str) -> int:
        if index is None:
            if self.default_material is None:
                # glTF's default material: the metallic-roughness defaults
                self.default_material = len(self.scene.materials)
                self.scene.materials.append(Material(name="default", metallic=1.0))
            return self.default_material
        if index in self.scene_index:
            return self.scene_index[index]
        m = self.file.item("materials", index, where)
        mwhere = f"materials[{index}]"
        self.texture_uses = []
        with self.file.element(mwhere):
            pbr = m.pbrMetallicRoughness or pygltflib.PbrMetallicRoughness()
            out = Material(name=m.name or mwhere)
            out.base_color = self.file.numbers(pbr.baseColorFactor, 4, mwhere, "baseColorFactor",
                                               (1.0, 1.0, 1.0, 1.0))
            out.metallic = self.file.number(pbr.metallicFactor, mwhere, "metallicFactor", 1.0)
            out.roughness = self.file.number(pbr.roughnessFactor, mwhere, "roughnessFactor", 1.0)
            emissive = self.file.numbers(m.emissiveFactor, 3, mwhere, "emissiveFactor",
                                         (0.0, 0.0, 0.0))
            strength = (m.extensions or {}).get("KHR_materials_emissive_strength")
            if isinstance(strength, dict):
                k = self.file.number(strength.get("emissiveStrength"), mwhere,
                                     "KHR_materials_emissive_strength.emissiveStrength", 1.0)
                emissive = tuple(c * k for c in emissive)
            out.emissive = emissive
            out.specular = self.specular(m.extensions, mwhere)
            out.base_color_texture = self.texture_info(pbr.baseColorTexture, True,
                                                       f"{mwhere}.baseColorTexture")
            out.metallic_roughness_texture = self.texture_info(
                pbr.metallicRoughnessTexture, False, f"{mwhere}.metallicRoughnessTexture")
            out.normal_texture = self.texture_info(m.normalTexture, False,
                                                   f"{mwhere}.normalTexture")
            if m.normalTexture is not None:
                out.normal_scale = self.file.number(m.normalTexture.scale, mwhere,
                                                    "normalTexture.scale", 1.0)
            out.occlusion_texture = self.texture_info(m.occlusionTexture, False,
                                                      f"{mwhere}.occlusionTexture")
            if m.occlusionTexture is not None:
                out.occlusion_strength = self.file.number(m.occlusionTexture.strength, mwhere,
                                                          "occlusionTexture.strength", 1.0)
            out.emissive_texture = self.texture_info(m.emissiveTexture, True,
                                                     f"{mwhere}.emissiveTexture")
            mode = m.alphaMode if m.alphaMode is not None else "OPAQUE"
            if mode not in ("OPAQUE", "MASK", "BLEND"):
                self.file.fail(mwhere, f"alphaMode {json.dumps(mode)} must be OPAQUE, MASK "
                                       "or BLEND")
            out.alpha_mode = mode
            out.alpha_cutoff = self.file.number(m.alphaCutoff, mwhere, "alphaCutoff", 0.5)
            out.double_sided = bool(m.doubleSided)
        self.scene_index[index] = k = len(self.scene.materials)
        self.scene.materials.append(out)
        if self.texture_uses:
            self.uv_sets[k] = (*self.uv_set(mwhere), mwhere)
        return k

    def specular(self, extensions: Any, mwhere: str) -> float:
        """KHR_materials_specular's specularFactor (1 without the extension). Its texture and
        its colour (factor or texture) are not read: recorded as read past."""
        ext = (extensions or {}).get("KHR_materials_specular")
        if ext is None:
            return 1.0
        where = f"{mwhere}.extensions.KHR_materials_specular"
        if not isinstance(ext, dict):
            self.file.fail(where, "must be an object")
        factor = self.file.number(ext.get("specularFactor"), where, "specularFactor", 1.0)
        color = self.file.numbers(ext.get("specularColorFactor"), 3, where,
                                  "specularColorFactor", (1.0, 1.0, 1.0))
        if ext.get("specularTexture") is not None or ext.get("specularColorTexture") is not None \
                or color != (1.0, 1.0, 1.0):
            self.file.unread["specular"].append(where)
        return factor

    def uv_set(self, mwhere: str) -> tuple[int, np.ndarray | None]:
        """The one TEXCOORD set and transform the material's textures are sampled with: the
        model has one per vertex, so where they differ the first texture's wins (warned)."""
        first, texcoord, matrix = self.texture_uses[0]
        for where, t, m in self.texture_uses[1:]:
            same = (m is None and matrix is None) or (
                m is not None and matrix is not None and np.allclose(m, matrix))
            if t != texcoord or not same:
                self.file.warn(f"{where} uses other texture coordinates than {first} (TEXCOORD or "
                               f"KHR_texture_transform); only one set per material is read, "
                               f"{first}'s")
        return texcoord, matrix

    def tint(self, material: int, colors: np.ndarray, where: str) -> int:
        """``material`` times a primitive's COLOR_0, which the model cannot carry per vertex:
        its mean (exact for one colour), warned where the colours vary."""
        rgba = np.ones((len(colors), 4))
        rgba[:, :colors.shape[1]] = np.clip(colors, 0.0, 1.0)
        mean = rgba.mean(axis=0)
        if np.abs(rgba - mean).max() > 1.0 / 255.0:
            self.file.warn(f"{where}: COLOR_0 varies per vertex; drawn with its mean "
                           "(vertex colours are not interpolated)")
        if np.all(np.abs(mean - 1.0) <= 0.5 / 255.0):
            return material  # white: the material as it is
        key = (material, tuple(np.round(mean, 6)))
        if key not in self.tinted:
            base = self.scene.materials[material]
            color = tuple(float(c * m) for c, m in zip(base.base_color, mean, strict=True))
            self.tinted[key] = len(self.scene.materials)
            self.scene.materials.append(replace(base, name=f"{base.name} (COLOR_0)",
                                                base_color=color))
            if material in self.uv_sets:
                self.uv_sets[self.tinted[key]] = self.uv_sets[material]
        return self.tinted[key]

    def texture_info(self, info: Any, srgb: bool, where: str) -> int | None:
        if info is None:
            return None
        if info.index is None:
            self.file.fail(where, "has no index")
        texcoord = self.file.integer(info.texCoord, where, "texCoord", default=0)
        ext = (info.extensions or {}).get("KHR_texture_transform")
        matrix = None
        if ext is not None:
            texcoord, matrix = self.texture_transform(ext, texcoord,
                                                      f"{where}.extensions.KHR_texture_transform")
        if texcoord > 1:
            self.file.warn(f"{where} uses TEXCOORD_{texcoord}; only TEXCOORD_0 and TEXCOORD_1 are "
                           "read (TEXCOORD_0 is used)")
            texcoord = 0
        out = self.textures.texture(info.index, srgb, where)
        if out is not None:
            self.texture_uses.append((where, texcoord, matrix))
        return out

    def texture_transform(self, ext: Any, texcoord: int,
                          where: str) -> tuple[int, np.ndarray | None]:
        """KHR_texture_transform's texCoord and its matrix T * R * S (2x3), None for the
        identity."""
        if not isinstance(ext, dict):
            self.file.fail(where, "must be an object")
        ox, oy = self.file.numbers(ext.get("offset"), 2, where, "offset", (0.0, 0.0))
        sx, sy = self.file.numbers(ext.get("scale"), 2, where, "scale", (1.0, 1.0))
        r = self.file.number(ext.get("rotation"), where, "rotation", 0.0)
        texcoord = self.file.integer(ext.get("texCoord"), where, "texCoord", default=texcoord)
        c, s_ = math.cos(r), math.sin(r)
        # the extension's matrices: translation, then rotation (clockwise in uv), then scale
        m = np.array([[c * sx, s_ * sy, ox], [-s_ * sx, c * sy, oy]])
        if np.array_equal(m, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]):
            return texcoord, None
        return texcoord, m
