#!/usr/bin/env bash
# benchmarks/bench_rt.py on a GPU machine without network (issue 6's NVIDIA run).
#
# Run from the repository root, with PYTHONPATH holding rfw's dependencies (numpy, vulkan,
# pygltflib, trimesh, pillow, embreex; open3d and mitsuba are optional peers), glslangValidator
# on PATH and a Vulkan driver. Scenes come from .scenes/ (git ignores it) if there:
# <name>.glb copied from ~/.cache/rfw/scenes after `rfw scenes fetch dragon city`, or the
# .npz that `benchmarks/bench_meshlets.py --export-scenes .scenes` writes.
#
# Usage (results into $OUT: bench_rt.md, bench_rt.json, bench_rt.log and device.txt):
#
#   bash benchmarks/device_rt.sh                     # 1920x1080, courtyard + dragon + city
#   bash benchmarks/device_rt.sh --size 1280x720     # anything else goes to the benchmark
#
# RayScene.cast alone (921,600 primary rays on the courtyard: wall time, where it goes, staged
# and mapped placements, against Embree on every core), from the repository root:
#
#   source benchmarks/device_env.sh
#   OUT=$OUT/rt bash benchmarks/device_rt.sh --sections cast --size 1280x720 --scenes "" \
#       --repeats 7
#
# A device without VK_KHR_ray_query (NVIDIA's at the time of writing) gets the ray-pipeline
# rows only; the report's notes say which rows were skipped and why.
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
PYTHON=${PYTHON:-python3}
SCENES_DIR=${SCENES_DIR:-.scenes}

# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export RFW_CACHE=${RFW_CACHE:-/tmp/rfw-cache/scenes}
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"

if ! command -v glslangValidator >/dev/null; then
    echo "device_rt.sh: glslangValidator is not on PATH (rfw compiles GLSL with it)" >&2
    exit 1
fi
if ! "$PYTHON" -c "import numpy, vulkan, pygltflib, trimesh, PIL, embreex" 2>/dev/null; then
    echo "device_rt.sh: $PYTHON cannot import numpy, vulkan, pygltflib, trimesh, PIL and" \
         "embreex: set PYTHONPATH" >&2
    exit 1
fi

. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

start=$SECONDS
set +e
"$PYTHON" benchmarks/bench_rt.py --size 1920x1080 --scene-dir "$SCENES_DIR" \
    --out "$OUT/bench_rt.md" "$@" 2>&1 | tee "$OUT/bench_rt.log"
status=${PIPESTATUS[0]}
set -e
echo "device_rt.sh: took $((SECONDS - start)) s (exit $status)" | tee -a "$OUT/bench_rt.log"
exit "$status"
