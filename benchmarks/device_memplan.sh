#!/usr/bin/env bash
# benchmarks/bench_memplan.py on a GPU machine without network (issue 24 item 4: the
# transient bytes `rfw graph plan --device-profile` predicts against what the vk executor
# allocates, every config and the 28 Raptor graphs at 1280x720, 1920x1080 and 3840x2160).
#
# Run from the repository root with .gl .whl .deb carried (benchmarks/device_env.sh is
# sourced when rfw or vulkan is not importable). Nothing is rendered: images and buffers are
# created, their requirements read and bound into the plan's heaps, then freed. The Raptor
# graphs come from tests/data/raptor (the same 28 files as ../shared/data/raptor-graphs).
#
# Usage (results into $OUT: memplan.md, memplan.json, memplan.log and device.txt):
#
#   bash benchmarks/device_memplan.sh                     # profile nvidia (NVIDIA's driver)
#   bash benchmarks/device_memplan.sh --profile lavapipe  # anything else goes to the benchmark
#
# memplan.json holds, per graph and size, the resources whose modelled requirements differ
# from the driver's, a probe of the driver's requirements over heights, and the profile
# parameters that fit this device best ("fit"): saved as a .json, that is a --device-profile.
# About a minute: the setup (unpacking the wheels) and creating a device take most of it.
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
PYTHON=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"

. "$(dirname "$0")/device_ready.sh" "rfw, vulkan"
if ! "$PYTHON" -c "import numpy, vulkan, rfw" 2>/dev/null; then
    echo "device_memplan.sh: $PYTHON cannot import numpy, vulkan and rfw: set PYTHONPATH" >&2
    exit 1
fi

. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

start=$SECONDS
set +e
"$PYTHON" benchmarks/bench_memplan.py --out "$OUT" "$@" 2>&1 | tee "$OUT/memplan.log"
status=${PIPESTATUS[0]}
set -e
echo "device_memplan.sh: took $((SECONDS - start)) s (exit $status)" | tee -a "$OUT/memplan.log"
exit "$status"
