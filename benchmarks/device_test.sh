#!/usr/bin/env bash
# The test suite on a GPU machine without network (issue 11's H200 run), from the repository
# root with .gl, .whl and .deb carried (benchmarks/device_prepare.sh builds them):
#
#   bash benchmarks/device_test.sh            # the suite; log and summary into $OUT
#   bash benchmarks/device_test.sh --golden   # then this adapter's goldens, as $OUT/golden.tgz
#
# Anything else goes to pytest (e.g. tests/passes). TEST_WORKERS (default 8) sets -n. Bring
# goldens back into tests/golden/<adapter>/ with `tar xzf golden.tgz` in the repository root.
set -uo pipefail

: "${OUT:?set OUT to the folder for the results}"
golden=0
if [[ ${1:-} == --golden ]]; then
    golden=1
    shift
fi
. "$(dirname "$0")/device_env.sh" >"$OUT/env.log" 2>&1
# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE=${RFW_CACHE:-/tmp/rfw-cache/scenes}
export RFW_CACHE_MESHLETS=${RFW_CACHE_MESHLETS:-/tmp/rfw-cache/meshlets}
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export PYTHONUNBUFFERED=1
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader

start=$SECONDS
python3 -m pytest -q -n "${TEST_WORKERS:-8}" -p no:cacheprovider -rfEs "$@" 2>&1 \
    | tee "$OUT/log" | grep -vE '^[.sFEx]+ +\[ *[0-9]+%\]$'
status=${PIPESTATUS[0]}
echo "device_test.sh: suite took $((SECONDS - start)) s (exit $status)" | tee -a "$OUT/log"
if [[ $golden == 1 ]]; then
    before=$(ls tests/golden)
    RFW_REGEN_GOLDEN=1 python3 -m pytest -q -n "${TEST_WORKERS:-8}" -p no:cacheprovider \
        tests/test_golden.py 2>&1 | tail -3 | tee "$OUT/golden.log"
    # only folders this run wrote files into
    new=$(find tests/golden -newer "$OUT/log" -type f -printf '%h\n' | sort -u)
    [[ -n $new ]] && tar czf "$OUT/golden.tgz" $new && echo "goldens: $new (was: $before)"
fi
exit "$status"
