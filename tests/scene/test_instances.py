"""Instance data that scales: every instance's matrices in one read-only storage buffer,
indexed by each draw's first instance, on both backends.

A scene's Vulkan descriptor sets do not grow with its instances, a scene too large for the
device's storage-buffer limits is one SceneError naming it (before wgpu-native or the driver
could abort), and the SPIR-V handed to wgpu marks a ``readonly buffer`` read-only where naga
looks for it. Images are covered by the goldens and tests/scene/test_stress.py."""

from __future__ import annotations

import pytest

from rfw.backends.scene_data import INSTANCE_BYTES, check_instance_limits
from rfw.backends.wgpu import scene as wgpu_scene
from rfw.scene import SceneError, stress
from rfw.spirv import compile_glsl, readonly_blocks_marked, reflect

_WGPU_LIMITS = wgpu_scene.INSTANCE_LIMIT_KEYS


def _vk_check():
    vk_scene = pytest.importorskip("vkext.scene")
    return lambda scene, limits: check_instance_limits(scene, limits,
                                                       vk_scene.INSTANCE_LIMIT_KEYS)


def _wgpu_check(scene, limits):
    return check_instance_limits(scene, limits, wgpu_scene.INSTANCE_LIMIT_KEYS)


@pytest.mark.parametrize("key", _WGPU_LIMITS)
def test_wgpu_refuses_instances_over_a_limit_in_one_line(key):
    scene = stress(1000)
    need = 1000 * INSTANCE_BYTES
    limits = {k: 1 << 30 for k in _WGPU_LIMITS}
    assert _wgpu_check(scene, {**limits, key: need}) == need  # just fits
    with pytest.raises(SceneError) as e:
        _wgpu_check(scene, {**limits, key: need - 1})
    line = str(e.value)
    assert "\n" not in line
    assert line.startswith("stress:1000: instances: 1,000 instances need 128,000 bytes")
    assert f"{key} (127,999): at most 999 fit" in line


def test_vk_refuses_instances_over_the_storage_range_in_one_line():
    check = _vk_check()
    scene = stress(1000)
    need = 1000 * INSTANCE_BYTES
    assert check(scene, {"maxStorageBufferRange": need}) == need  # just fits
    with pytest.raises(SceneError, match=r"^stress:1000: instances: 1,000 instances need "
                                         r"128,000 bytes .*maxStorageBufferRange \(127,999\)"):
        check(scene, {"maxStorageBufferRange": need - 1})


def test_the_full_stress_scene_fits_webgpus_default_limits():
    # 100,000 rows are 12.8 MB: far under WebGPU's default binding size (128 MiB)
    scene = stress()
    assert _wgpu_check(
        scene, {"max-storage-buffer-binding-size": 128 << 20, "max-buffer-size": 256 << 20}) \
        == 100_000 * INSTANCE_BYTES


_VERT = """#version 460
#define MESH_VERTEX_INPUT
#include "mesh.glsl"
layout(set = 0, binding = 0, std430) buffer Counts { uint n[]; } counts;
void main() {
    counts.n[gl_VertexIndex] = 1u;
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
}
"""


def _decorated_non_writable(code: bytes) -> set[int]:
    import struct

    words = struct.unpack(f"<{len(code) // 4}I", code)
    out, i = set(), 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        if op == 71 and words[i + 2] == 24:  # OpDecorate id NonWritable
            out.add(words[i + 1])
        i += count
    return out


def test_readonly_blocks_are_marked_for_naga(tmp_path, monkeypatch):
    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    path = tmp_path / "probe.vert.glsl"
    path.write_text(_VERT)
    code = compile_glsl(path).code
    marked = readonly_blocks_marked(code)
    added = _decorated_non_writable(marked) - _decorated_non_writable(code)
    assert len(added) == 1  # the scene's instances, not the writable counts block
    refl = reflect(marked)
    assert refl.descriptors["scene_instances"].writable is False
    assert refl.descriptors["counts"].writable is True  # negative control: left alone
    assert readonly_blocks_marked(marked) == marked  # already marked: nothing to add
    plain = tmp_path / "plain.vert.glsl"
    plain.write_text("#version 460\nvoid main() { gl_Position = vec4(0.0); }\n")
    untouched = compile_glsl(plain).code
    assert readonly_blocks_marked(untouched) == untouched


def test_vk_descriptor_sets_do_not_grow_with_instances(monkeypatch):
    vk_scene = pytest.importorskip("vkext.scene")
    from vkext import VkDevice, VkUnavailableError

    try:
        device = VkDevice(validation=True, label="rfw-tests")
    except VkUnavailableError as e:
        pytest.skip(f"no Vulkan: {e}")
    sets: list[int] = []
    allocate = vk_scene.DescriptorPool.allocate

    def counted(self, layouts):
        sets.append(len(layouts))
        return allocate(self, layouts)

    monkeypatch.setattr(vk_scene.DescriptorPool, "allocate", counted)
    try:
        for count in (10, 3000):
            s = vk_scene.VkScene(device, stress(count))
            assert len(s.instance_sets) == count
            assert s.instance_sets[count - 1] is s.instance_sets[0] is s.instance_set
            s.destroy()
        one_more = stress(10)
        one_more.materials = [*one_more.materials, one_more.materials[0]]
        vk_scene.VkScene(device, one_more).destroy()
    finally:
        device.destroy()
    device.check_validation()
    # cameras (2), materials (4) and one set for every instance: 7 for 10 and 3,000 alike
    assert sets[:2] == [7, 7]
    assert sets[2] == 8  # negative control: a fifth material is one set more
