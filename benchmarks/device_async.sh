#!/usr/bin/env bash
# Async compute on a GPU machine without network (issue 13, item 7): the plan, a validated
# run with it on, bench_async.py (frame GPU span on/off) and rfw bench's matrix on/off.
#
# From the repository root, after `source benchmarks/device_env.sh` (rfw and its pins on
# PYTHONPATH, glslang and the validation layers on PATH):
#
#   OUT=/path/to/results bash benchmarks/device_async.sh [--size 1280x720] [--frames 60]
#
# Writes into $OUT: plan.txt, validate.txt, bench_async.json/.log, bench/ (rfw bench report).
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
PYTHON=${PYTHON:-python3}
SIZE=1280x720
FRAMES=60
while [ $# -gt 0 ]; do
    case "$1" in
        --size) SIZE=$2; shift 2 ;;
        --frames) FRAMES=$2; shift 2 ;;
        *) echo "unknown argument $1" >&2; exit 2 ;;
    esac
done
mkdir -p "$OUT"
# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export RFW_CACHE=${RFW_CACHE:-/tmp/rfw-cache/scenes}

"$PYTHON" -m rfw.cli graph plan configs/deferred_ssao_shadows.toml --caps compute_queue \
    > "$OUT/plan.txt"
"$PYTHON" -m rfw.cli run configs/deferred_ssao_shadows.toml --backend vk --validate \
    --set async_compute=on --size "$SIZE" --frames 10 --out "$OUT/validate" \
    > "$OUT/validate.txt" 2>&1
"$PYTHON" benchmarks/bench_async.py --size "$SIZE" --frames "$FRAMES" --warmup 5 --repeat 3 \
    --out "$OUT/bench_async.json" 2>&1 | tee "$OUT/bench_async.log"
# the same on the graphics family's second queue (RFW_VK_ASYNC_QUEUE's other choice)
RFW_VK_ASYNC_QUEUE=graphics "$PYTHON" benchmarks/bench_async.py --size "$SIZE" \
    --frames "$FRAMES" --warmup 5 --repeat 3 --out "$OUT/bench_async_graphics.json" 2>&1 \
    | tee "$OUT/bench_async_graphics.log"
"$PYTHON" -m rfw.cli bench deferred_ssao_shadows@vk --vary async_compute=on,off \
    --size "$SIZE" --frames "$FRAMES" --warmup 5 --repeat 3 --out "$OUT/bench" \
    2>&1 | tee "$OUT/bench.log"
