#!/usr/bin/env bash
# benchmarks/aa_pairs.py on the GPU machine: AA_RUNS (default 120) runs of one config, one
# process each, cut into >= 30 disjoint A/A pairs of 2 runs a side (and 20 of 3); the false
# positive rate of the significance mark, pass by pass, and the detection of planted 2% and
# 5% changes, into $OUT (aa.json, aa.md, results.jsonl.gz).
#
#   OUT=/tmp/out bash benchmarks/device_aa.sh            # deferred at 640x360, 20 frames
#   AA_CONFIG=flat AA_SIZE=1280x720 bash benchmarks/device_aa.sh -- --backend vk
set -euo pipefail
: "${OUT:?set OUT to the folder for the results}"
cd "$(dirname "$0")/.."
if [ ! -d /tmp/site ]; then source benchmarks/device_env.sh; else
    export PATH=/tmp/gl/usr/bin:$PATH LD_LIBRARY_PATH=/tmp/gl/usr/lib/x86_64-linux-gnu \
        PYTHONPATH=/tmp/site:/tmp/site2:$PWD VK_LAYER_PATH=/tmp/gl/usr/share/vulkan/explicit_layer.d \
        VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json \
        RFW_COMMIT=$(cat .rfw_commit 2>/dev/null || echo unknown)
fi
export RFW_CACHE_SPIRV=/tmp/rfw-cache/spirv PYTHONUNBUFFERED=1
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
start=$(date +%s)
python3 benchmarks/aa_pairs.py --config "${AA_CONFIG:-deferred}" --runs "${AA_RUNS:-120}" \
    --size "${AA_SIZE:-640x360}" --frames "${AA_FRAMES:-20}" --out "$OUT" \
    --note "one NVIDIA H200 through the device tool, nothing else running on it" "$@"
echo "device_aa: $(( $(date +%s) - start )) s in all"
