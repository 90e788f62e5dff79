#!/usr/bin/env bash
# benchmarks/bench_scaling.py on a GPU machine without network (issue 13, item 2: GPU ms of
# each raster pass against resolution, instances, triangles and textures, beside the
# depth-only floor). Run from the repository root with .gl, .whl and .deb carried
# (benchmarks/device_prepare.sh builds them; no scene is needed: the scenes are generated):
#
#   RFW_COMMIT=<hash> OUT=<folder> bash benchmarks/device_scaling.sh   # the full grid, vk
#   OUT=<folder> bash benchmarks/device_scaling.sh --backend wgpu      # anything else goes on
#
# Results into $OUT: scaling.md, scaling.json, scaling_<axis>.png, scaling.log, device.txt.
# BENCH_BUDGET_S (default 200, less the seconds the setup took) is passed as --budget: no
# point starts that would likely end after it (the points run cheapest first, so the budget
# cuts the extremes, named in the report). The full grid is 18 points.
set -uo pipefail

: "${OUT:?set OUT to the folder for the results}"
mkdir -p "$OUT"
PYTHON=${PYTHON:-python3}
. "$(dirname "$0")/device_ready.sh" "rfw, vulkan"
# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export PYTHONUNBUFFERED=1
if ! command -v glslangValidator >/dev/null; then
    echo "device_scaling.sh: glslangValidator is not on PATH (rfw compiles GLSL with it)" >&2
    exit 1
fi

. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

start=$SECONDS
# the budget counts from this script's start: unpacking device_env.sh's wheels comes off it
budget=$((${BENCH_BUDGET_S:-200} - SECONDS))
"$PYTHON" benchmarks/bench_scaling.py --grid full --budget "$budget" \
    --timeout 120 --out "$OUT" "$@" 2>&1 | tee "$OUT/scaling.log"
status=${PIPESTATUS[0]}
echo "device_scaling.sh: took $((SECONDS - start)) s (exit $status)" | tee -a "$OUT/scaling.log"
exit "$status"
