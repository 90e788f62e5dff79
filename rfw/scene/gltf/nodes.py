"""The node hierarchy of the chosen scene (TRS or matrix) and what its nodes carry: mesh
instances, perspective cameras (orthographic ones approximated) and KHR_lights_punctual
lights, in world space."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from ..animation import Node
from ..model import WORLD_LIMIT, Camera, Light, Material, Scene
from ..util import normalize
from .file import GltfFile
from .meshes import Meshes


def _finite32(a: Any) -> bool:
    """True when every value lies within the world renderers can hold in float32 (no NaN,
    no infinity, nothing beyond ``WORLD_LIMIT``)."""
    a = np.asarray(a, np.float64)
    return bool(np.all(np.isfinite(a)) and np.all(np.abs(a) <= WORLD_LIMIT))


class SceneGraph:
    """Walks the nodes of ``file`` from the scene's roots into ``scene``: instances through
    ``meshes``, cameras and lights here."""

    def __init__(self, file: GltfFile, meshes: Meshes, scene: Scene):
        self.file = file
        self.meshes = meshes
        self.scene = scene

    def build(self) -> None:
        doc = self.file.doc
        scenes = doc.scenes or []
        if doc.scene is not None:
            roots = self.file.item("scenes", doc.scene, "scene").nodes or []
            where = f"scenes[{doc.scene}]"
        elif scenes:
            roots, where = scenes[0].nodes or [], "scenes[0]"
        else:
            # no scenes: show every root node rather than nothing
            children = {c for n in doc.nodes or [] for c in n.children or []}
            roots = [i for i in range(len(doc.nodes or [])) if i not in children]
            where = "nodes"
        stack = [(self.file.item("nodes", r, f"{where}.nodes[{k}]"), r, np.identity(4), -1)
                 for k, r in enumerate(roots)][::-1]
        seen: set[int] = set()
        open_zfar: list[int] = []
        # an animated file keeps its hierarchy: animations pose nodes, instances follow
        keep = bool(doc.animations)
        if keep:
            self.scene.nodes = [Node(name=n.name or f"nodes[{k}]")
                                for k, n in enumerate(doc.nodes or [])]
        while stack:
            node, index, parent, parent_index = stack.pop()
            nwhere = f"nodes[{index}]"
            if index in seen:
                self.file.fail(nwhere, "reached twice (the node hierarchy has a cycle or a node "
                                       "with two parents)")
            seen.add(index)
            with self.file.element(nwhere):
                local = self.local(node, nwhere)
                world = parent @ local
                if keep:
                    self.keep(node, index, parent_index, local, world, nwhere)
                if node.mesh is not None:
                    self.meshes.instance(node, index, world, placed_by=index if keep else None)
                if node.camera is not None:
                    cam, infinite = self.camera(node.camera, nwhere, world)
                    if infinite:
                        open_zfar.append(len(self.scene.cameras))
                    if cam is not None:
                        self.scene.cameras.append(cam)
                ext = (node.extensions or {}).get("KHR_lights_punctual")
                if ext is not None:
                    self.light(ext, nwhere, world)
                for k, c in reversed(list(enumerate(node.children or []))):
                    stack.append((self.file.item("nodes", c, f"{nwhere}.children[{k}]"), c, world,
                                  index))
        if not self.scene.materials:
            self.scene.materials.append(Material())
        if open_zfar:
            # glTF's infinite far plane: far enough for the whole scene
            far = 500.0
            if self.scene.instances:
                lo, hi = self.scene.bounds()
                far = max(far, 10.0 * float(np.linalg.norm(hi - lo)))
            for i in open_zfar:
                self.scene.cameras[i].zfar = far

    def keep(self, node: Any, index: int, parent: int, local: np.ndarray, world: np.ndarray,
             where: str) -> None:
        """Node ``index`` of the hierarchy as animations need it: parent, rest TRS (or
        matrix) and rest matrices."""
        kept = self.scene.nodes[index]
        kept.parent, kept.local, kept.world = parent, local, world
        if node.matrix is not None:
            kept.matrix = local
            return
        kept.translation = self.file.numbers(node.translation, 3, where, "translation",
                                             (0.0, 0.0, 0.0))
        q = self.file.numbers(node.rotation, 4, where, "rotation", (0.0, 0.0, 0.0, 1.0))
        qn = math.sqrt(sum(c * c for c in q))
        kept.rotation = tuple(c / qn for c in q)
        kept.scale = self.file.numbers(node.scale, 3, where, "scale", (1.0, 1.0, 1.0))

    def local(self, node: Any, where: str) -> np.ndarray:
        if node.matrix is not None:
            m = self.file.numbers(node.matrix, 16, where, "matrix", ())
            return np.array(m, np.float64).reshape(4, 4).T  # glTF stores column-major
        t = self.file.numbers(node.translation, 3, where, "translation", (0.0, 0.0, 0.0))
        q = self.file.numbers(node.rotation, 4, where, "rotation", (0.0, 0.0, 0.0, 1.0))
        s = self.file.numbers(node.scale, 3, where, "scale", (1.0, 1.0, 1.0))
        qn = math.sqrt(sum(c * c for c in q))
        if qn < 1e-12:
            self.file.fail(where, "rotation is a zero quaternion")
        x, y, z, w = (c / qn for c in q)
        r = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        m = np.identity(4)
        m[:3, :3] = r * np.array(s)[None, :]  # T @ R @ S
        m[:3, 3] = t
        return m

    def camera(self, index: Any, where: str,
               world: np.ndarray) -> tuple[Camera | None, bool]:
        cam = self.file.item("cameras", index, f"{where}.camera")
        cwhere = f"cameras[{index}]"
        eye = world[:3, 3]
        forward = normalize((world[:3, :3] @ [0.0, 0.0, -1.0])[None])[0]
        up = normalize((world[:3, :3] @ [0.0, 1.0, 0.0])[None])[0]
        if not _finite32(world) or abs(float(forward @ up)) > 0.999:
            # a zero scale is valid glTF: the camera sees nothing, so it is left out
            self.file.skipped(where, f"{cwhere} skipped: its transform is degenerate")
            return None, False
        name = cam.name or cwhere
        if cam.type == "orthographic" or (cam.type is None and cam.orthographic is not None):
            o = cam.orthographic
            if o is None:
                self.file.fail(cwhere, "type is orthographic but there is no orthographic object")
            ymag = self.file.number(o.ymag, cwhere, "ymag", 1.0)
            znear = max(self.file.number(o.znear, cwhere, "znear", 0.01), 1e-3)
            zfar = self.file.number(o.zfar, cwhere, "zfar", 500.0)
            # the model is perspective only: a camera far back with a narrow field of view
            # sees about what the orthographic one sees around its target
            self.file.warn(f"{cwhere} is orthographic; approximated by a perspective camera")
            back = max(10.0 * abs(ymag), 10.0)
            yfov = 2.0 * math.atan(abs(ymag) / back) if ymag else math.radians(5.0)
            pos = eye - forward * back
            if not _finite32(pos) or not _finite32(zfar + back):
                self.file.skipped(where, f"{cwhere} skipped: it lies beyond {WORLD_LIMIT:g}")
                return None, False
            return Camera(tuple(map(float, pos)), tuple(map(float, eye)),
                          tuple(map(float, up)), yfov, znear, zfar + back, name), False
        if cam.type not in ("perspective", None) or cam.perspective is None:
            self.file.fail(cwhere, f"type {json.dumps(cam.type)} needs a perspective object")
        p = cam.perspective
        yfov = self.file.number(p.yfov, cwhere, "perspective.yfov", 0.0)
        if not 0.0 < yfov < math.pi:
            self.file.fail(cwhere, f"perspective.yfov {yfov} must lie in (0, pi)")
        znear = self.file.number(p.znear, cwhere, "perspective.znear", 0.0)
        if znear <= 0:
            self.file.fail(cwhere, "perspective.znear must be > 0")
        zfar = p.zfar
        if zfar is not None:
            zfar = self.file.number(zfar, cwhere, "perspective.zfar", 0.0)
            if zfar <= znear:
                self.file.fail(cwhere, f"perspective.zfar {zfar} must exceed znear {znear}")
        target = eye + forward
        if not _finite32(target):
            self.file.skipped(where, f"{cwhere} skipped: it lies beyond {WORLD_LIMIT:g}")
            return None, False
        return Camera(tuple(map(float, eye)), tuple(map(float, target)), tuple(map(float, up)),
                      yfov, znear, 500.0 if zfar is None else zfar, name), zfar is None

    def light(self, ext: Any, where: str, world: np.ndarray) -> None:
        lwhere = f"{where}.extensions.KHR_lights_punctual"
        if not isinstance(ext, dict):
            self.file.fail(lwhere, "must be an object")
        top = (self.file.doc.extensions or {}).get("KHR_lights_punctual")
        lights = top.get("lights") if isinstance(top, dict) else None
        if not isinstance(lights, list):
            self.file.fail(lwhere, "refers to a light, but the file has no KHR_lights_punctual "
                                   "lights array")
        index = ext.get("light")
        if isinstance(index, bool) or not isinstance(index, int) \
                or not 0 <= index < len(lights):
            self.file.fail(lwhere, f"light {json.dumps(index)} is not an index into the "
                                   f"{len(lights)} KHR_lights_punctual lights")
        src = lights[index]
        swhere = f"extensions.KHR_lights_punctual.lights[{index}]"
        if not isinstance(src, dict):
            self.file.fail(swhere, "must be an object")
        kind = src.get("type")
        if kind not in ("directional", "point", "spot"):
            self.file.fail(swhere, f"type {json.dumps(kind)} must be directional, point or spot")
        light = Light(kind=kind, name=src.get("name") if isinstance(src.get("name"), str)
                      else swhere)
        light.color = self.file.numbers(src.get("color"), 3, swhere, "color", (1.0, 1.0, 1.0))
        light.intensity = self.file.number(src.get("intensity"), swhere, "intensity", 1.0)
        if src.get("range") is not None:
            light.range = self.file.number(src.get("range"), swhere, "range", 0.0)
            if light.range <= 0:
                self.file.fail(swhere, "range must be > 0")
        if kind == "spot":
            spot = src.get("spot")
            if not isinstance(spot, dict):
                self.file.fail(swhere, "a spot light needs a spot object")
            light.inner_cone = self.file.number(spot.get("innerConeAngle"), swhere,
                                                "spot.innerConeAngle", 0.0)
            light.outer_cone = self.file.number(spot.get("outerConeAngle"), swhere,
                                                "spot.outerConeAngle", math.pi / 4)
            if not 0.0 <= light.inner_cone < light.outer_cone <= math.pi / 2:
                self.file.fail(swhere, "spot cone angles need 0 <= inner < outer <= pi/2")
        light.position = tuple(map(float, world[:3, 3]))
        direction = world[:3, :3] @ [0.0, 0.0, -1.0]
        if not _finite32(world) or np.linalg.norm(direction) < 1e-12:
            # a zero scale is valid glTF: such a light has no direction, so it is left out
            self.file.skipped(where, f"{swhere} skipped: its transform is degenerate")
            return
        light.direction = tuple(map(float, normalize(direction[None])[0]))
        self.scene.lights.append(light)
