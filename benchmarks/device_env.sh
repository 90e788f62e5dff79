# Source this on the GPU machine (Ubuntu 24.04, no network) from the repository root, with the
# git-ignored folders carried: .gl (Vulkan loader .debs), .whl (py3.12 wheels and the
# meshoptimizer sdist), .deb (Debian 12's glslang-tools, spirv-tools, vulkan-validationlayers),
# .scenes (bench_meshlets.py --export-scenes). It sets PATH, LD_LIBRARY_PATH, PYTHONPATH,
# VK_LAYER_PATH and VK_DRIVER_FILES so that rfw, its tests and the benchmarks run there.
# benchmarks/device_prepare.sh builds .gl, .whl and .deb on a machine with network;
# benchmarks/device_test.sh runs the test suite there.
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl
PYTHONPATH=/tmp/site python3 -m pip install -q --no-index --no-deps --no-build-isolation \
    --target /tmp/site2 .whl/meshoptimizer-*.tar.gz
mkdir -p /tmp/gl
for f in .deb/*.deb; do dpkg -x "$f" /tmp/gl; done
export PATH=/tmp/gl/usr/bin:$PATH
export LD_LIBRARY_PATH=/tmp/gl/usr/lib/x86_64-linux-gnu
export PYTHONPATH=/tmp/site:/tmp/site2:$PWD
export VK_LAYER_PATH=/tmp/gl/usr/share/vulkan/explicit_layer.d
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
export RFW_COMMIT=${RFW_COMMIT:-$(cat .rfw_commit 2>/dev/null || echo unknown)}
