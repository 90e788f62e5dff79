#!/usr/bin/env bash
# Zero-copy arrays on a GPU machine without network (issue 24, item 1): the probe of each
# step (Vulkan export, CUDA import, torch, CuPy, a device cast, an image export), then
# benchmarks/bench_zerocopy.py: 921,600 rays from and to torch/CuPy device arrays against
# Embree on all cores, a 1920x1080 RGBA16F output to a torch tensor, and the proof of zero
# device-to-host copies.
#
# From the repository root, with the git-ignored .gl, .whl and .deb folders carried (this
# script sources benchmarks/device_env.sh, keeping the PYTHONPATH it was given, where that
# machine's torch and cupy may live):
#
#   OUT=/path/to/results bash benchmarks/device_zerocopy.sh [bench_zerocopy.py arguments]
#
# Writes into $OUT: device.txt, bench_zerocopy_probe.json/.log, bench_zerocopy.json/.log.
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
PYTHON=${PYTHON:-python3}
given=${PYTHONPATH:-}
set +u
. "$(dirname "$0")/device_env.sh"
set -u
export PYTHONPATH=$PYTHONPATH${given:+:$given}
# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export RFW_CACHE=${RFW_CACHE:-/tmp/rfw-cache/scenes}
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"

. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

start=$SECONDS
set +e
"$PYTHON" benchmarks/bench_zerocopy.py --probe --out "$OUT/bench_zerocopy.json" \
    > "$OUT/bench_zerocopy_probe.log" 2>&1
echo "device_zerocopy.sh: probe exit $? (first failure:" \
     "$(grep -o '"first_failure": [^,}]*' "$OUT/bench_zerocopy_probe.json" 2>/dev/null))"
"$PYTHON" benchmarks/bench_zerocopy.py --out "$OUT/bench_zerocopy.json" "$@" 2>&1 \
    | tee "$OUT/bench_zerocopy.log"
status=${PIPESTATUS[0]}
set -e
echo "device_zerocopy.sh: took $((SECONDS - start)) s (exit $status)" \
    | tee -a "$OUT/bench_zerocopy.log"
exit "$status"
