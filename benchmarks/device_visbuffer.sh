#!/usr/bin/env bash
# The visibility-buffer G-buffer against the raster one on a GPU machine without network
# (issue 13, item 2: the courtyard's deferred frame under 0.5 ms of GPU time at 1280x720).
# Run from the repository root with .gl, .whl and .deb carried (benchmarks/device_prepare.sh):
#
#   RFW_COMMIT=<hash> OUT=<folder> bash benchmarks/device_visbuffer.sh
#
# One rfw bench per size (BENCH_SIZES, default 1280x720 and 3840x2160): deferred@vk (the
# raster G-buffer) and deferred_vis@vk (visbuffer + vis_resolve) with vis_write=attachment
# (an r32uint color target) and vis_write=atomic (no color target: 64-bit atomic min into a
# buffer vis_clear fills), the same lighting and tonemap, each in its own process, repeats
# rotated; per-pass GPU ms and the image difference are in $OUT/<size>/report.md. Before that, one validated run of each
# (--validate: any validation message fails it) and the G-buffer comparison test
# (tests/vkext/test_visbuffer.py, whose bounds were measured on lavapipe) into $OUT/test.log
# (VALIDATE_SIZE, default 1280x720).
set -uo pipefail

: "${OUT:?set OUT to the folder for the results}"
mkdir -p "$OUT"
PYTHON=${PYTHON:-python3}
. "$(dirname "$0")/device_ready.sh" "rfw, vulkan"
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export PYTHONUNBUFFERED=1
. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

status=0
for run in deferred: deferred_vis:vis_write=attachment deferred_vis:vis_write=atomic; do
    cfg=${run%%:*}; set_=${run#*:}
    "$PYTHON" -m rfw.cli run "configs/$cfg.toml" --backend vk --validate \
        --size "${VALIDATE_SIZE:-1280x720}" --frames 3 ${set_:+--set "$set_"} \
        --out "$OUT/validate_$cfg${set_:+_${set_#*=}}" >>"$OUT/test.log" 2>&1 || status=1
done
"$PYTHON" -m pytest -q -p no:cacheprovider tests/vkext/test_visbuffer.py >>"$OUT/test.log" 2>&1 \
    || status=1
tail -3 "$OUT/test.log"
for size in ${BENCH_SIZES:-1280x720 3840x2160}; do
    "$PYTHON" -m rfw.cli bench deferred@vk deferred_vis@vk --vary vis_write=attachment,atomic \
        --size "$size" --frames "${BENCH_FRAMES:-60}" --warmup 5 --repeat "${BENCH_REPEAT:-3}" \
        --out "$OUT/$size" 2>&1 | tee -a "$OUT/bench.log" || status=1
done
echo "device_visbuffer.sh: exit $status; reports in $OUT/<size>/report.md"
exit "$status"
