"""Which rule `rfw bench replay` judges an image by: bit-identical on the same adapter,
the CPU bounds for llvmpipe on another processor, the vendor bounds for another device."""

from rfw.bench.replay import rule_for

LAVAPIPE = {"device": "llvmpipe (LLVM 15.0.6, 256 bits)", "driver": "Mesa 25.0.7",
            "backend": "wgpu", "cpu": "AMD EPYC"}
H200 = {"device": "NVIDIA H200", "driver": "580.159.04", "backend": "wgpu", "cpu": "Intel Xeon"}


def test_same_adapter_is_bit_identical_and_the_cpu_matters_only_for_llvmpipe():
    assert rule_for(LAVAPIPE, dict(LAVAPIPE)) == "bit-identical"
    assert rule_for(LAVAPIPE, {**LAVAPIPE, "cpu": "Intel Xeon"}) == "golden"
    assert rule_for(H200, {**H200, "cpu": "AMD EPYC"}) == "bit-identical"
    assert rule_for(LAVAPIPE, H200) == "vendor"
    assert rule_for(H200, {**H200, "driver": "575.0"}) == "vendor"
    assert rule_for(LAVAPIPE, {**LAVAPIPE, "backend": "vk"}) == "vendor"
