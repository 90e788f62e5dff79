"""rfw.authoring, the pass API: the scene views passes are typed against are what both
backends' uploaded scenes give, and a view missing a member is told apart."""

from __future__ import annotations

import types

from rfw.authoring import MeshletSceneView, SceneView, VkSceneView
from tests.conftest import tiny_scene


def _members(protocol: type) -> set[str]:
    out: set[str] = set()
    for klass in protocol.__mro__:
        if getattr(klass, "_is_protocol", False) and klass is not object:
            out |= set(getattr(klass, "__annotations__", {}))
            out |= {n for n, v in vars(klass).items() if callable(v) and not n.startswith("_")}
    return out


def test_the_wgpu_scene_is_a_scene_view(device):
    from rfw.backends.wgpu.scene import GpuScene

    scene = GpuScene(device.device, tiny_scene())
    try:
        scene.set_viewport((32, 18))
        assert isinstance(scene, SceneView)
        missing = [m for m in _members(SceneView) if not hasattr(scene, m)]
        assert missing == []
    finally:
        scene.destroy()


def test_the_vk_scene_is_a_vk_scene_view_with_meshlets():
    from vkext.device import VkDevice
    from vkext.meshlet import meshlet_scene
    from vkext.scene import VkScene

    dev = VkDevice()
    try:
        scene = VkScene(dev, tiny_scene())
        try:
            scene.set_viewport((32, 18))
            assert isinstance(scene, VkSceneView) and isinstance(scene, SceneView)
            if "VK_EXT_mesh_shader" in dev.caps:
                assert isinstance(meshlet_scene(scene), MeshletSceneView)
        finally:
            scene.destroy()
    finally:
        dev.destroy()


def test_a_view_without_a_member_is_no_scene_view():
    full = {m: None for m in _members(SceneView)}
    full["bindings"] = lambda: {}
    assert isinstance(types.SimpleNamespace(**full), SceneView)
    del full["shadow_sampler"]  # negative control
    assert not isinstance(types.SimpleNamespace(**full), SceneView)

