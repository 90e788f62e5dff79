#!/usr/bin/env bash
# benchmarks/truth_fronts.sh on the GPU machine (issue 23's H200 fronts): 1280x720, 1024 spp
# references, ray pipelines (no VK_KHR_ray_query there), then each scene packed into
# $OUT/<scene>.tgz by pack_fronts.py (the trip back takes 8 files of 16 MiB at most).
#
#   bash benchmarks/device_truth.sh courtyard "full ao"
#   bash benchmarks/device_truth.sh monastery "shadows aa"
#
# The monastery comes from .scenes/monastery.glb (carried: the machine cannot fetch it),
# seen from inside its courtyard.
set -euo pipefail
: "${OUT:?set OUT to the folder for the results}"
scene=${1:?scene: courtyard or monastery}
fronts=${2:-full ao shadows aa}
if [ ! -d /tmp/site ]; then source benchmarks/device_env.sh; else
    export PATH=/tmp/gl/usr/bin:$PATH LD_LIBRARY_PATH=/tmp/gl/usr/lib/x86_64-linux-gnu \
        PYTHONPATH=/tmp/site:/tmp/site2:$PWD VK_LAYER_PATH=/tmp/gl/usr/share/vulkan/explicit_layer.d \
        VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json \
        RFW_COMMIT=$(cat .rfw_commit 2>/dev/null || echo unknown)
fi
export RFW_CACHE_SPIRV=/tmp/rfw-cache/spirv RFW_CACHE_TRUTH=/tmp/rfw-cache/truth PYTHONUNBUFFERED=1
work=/tmp/fronts
case $scene in
courtyard) SCENE=default CAMERA= ;;
monastery) SCENE=.scenes/monastery.glb
           CAMERA="camera.position=[15,6,20] camera.target=[-5,3,-5] camera.yfov=50" ;;
*) echo "device_truth.sh: unknown scene $scene" >&2; exit 2 ;;
esac
OUT=$work SCENE=$SCENE CAMERA=$CAMERA SIZE=${SIZE:-1280x720} SPP=${SPP:-1024} RT=ray_pipeline \
    FRAMES=${FRAMES:-10} PATH_FRAMES=${PATH_FRAMES:-120} REPEAT=${REPEAT:-2} FRONTS="$fronts" \
    RFW="python3 -P -m rfw.cli" bash benchmarks/truth_fronts.sh
name=$(basename "${SCENE%.*}")
python3 benchmarks/pack_fronts.py "$work/$name" "$OUT/${name}_${fronts// /_}.tgz"
