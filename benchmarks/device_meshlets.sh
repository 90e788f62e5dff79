#!/usr/bin/env bash
# benchmarks/bench_meshlets.py on a GPU machine without network (issue 5's NVIDIA run).
#
# Run from the repository root, with PYTHONPATH holding rfw's dependencies (numpy, vulkan,
# meshoptimizer, pygltflib, trimesh, pillow), glslangValidator on PATH and a Vulkan driver;
# where they are not importable and .whl is there, benchmarks/device_env.sh is sourced first
# (carry .gl .whl .deb .scenes). Scenes come from .scenes/ (git ignores it), written beforehand
# on a machine with network by benchmarks/device_prepare.sh, or by hand:
#
#   rfw scenes fetch dragon city
#   .venv/bin/python benchmarks/bench_meshlets.py --export-scenes .scenes   # about 8 MiB
#
# Usage (results into $OUT: bench_meshlets[_PART].md, .jsonl and .log, and device.txt):
#
#   bash benchmarks/device_meshlets.sh                  # both scenes
#   bash benchmarks/device_meshlets.sh dragon_grid      # one scene: PART is dragon_grid or city
#   bash benchmarks/device_meshlets.sh city --repeats 3 # anything after PART goes to the benchmark
#
# BENCH_BUDGET_S (default 540, less the seconds the setup took) is passed as --budget: no
# measurement starts that would likely end after it, so a call ends inside a 10-minute limit
# with a report of what was done. Both
# scenes with the GPU defaults (4x4 dragons, 1920x1080, 10 variants, 2 repeats) may need more:
# then run the two parts as two calls and merge their reports here with
#
#   .venv/bin/python benchmarks/bench_meshlets.py --from-jsonl bench_meshlets_*.jsonl \
#       --out out/bench_meshlets_h100.md
#
# RFW_COMMIT, if set, is recorded as the commit (the copy there may have no .git); every
# record also carries source_sha, a digest of the sources (`bench_meshlets.py --digest`).
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
PYTHON=${PYTHON:-python3}
BUDGET=${BENCH_BUDGET_S:-540}
SCENES_DIR=${SCENES_DIR:-.scenes}

part=all
if [[ $# -gt 0 && $1 != -* ]]; then
    part=$1
    shift
fi
case $part in
    all) scenes=dragon_grid,city; suffix="" ;;
    dragon_grid|city) scenes=$part; suffix="_$part" ;;
    *) echo "device_meshlets.sh: unknown part '$part' (all, dragon_grid or city)" >&2; exit 2 ;;
esac

# caches in /tmp: the machine starts bare and its home may not be writable
export RFW_CACHE_MESHLETS=${RFW_CACHE_MESHLETS:-/tmp/rfw-cache/meshlets}
export RFW_CACHE_SPIRV=${RFW_CACHE_SPIRV:-/tmp/rfw-cache/spirv}
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"

. "$(dirname "$0")/device_ready.sh" "rfw, vulkan, meshoptimizer"

missing=0
for f in dragon.npz city.npz; do
    if [[ ! -f $SCENES_DIR/$f ]]; then
        echo "device_meshlets.sh: $SCENES_DIR/$f is missing (see the top of this script)" >&2
        missing=1
    fi
done
if ! command -v glslangValidator >/dev/null; then
    echo "device_meshlets.sh: glslangValidator is not on PATH (rfw compiles GLSL with it)" >&2
    missing=1
fi
if ! "$PYTHON" -c "import numpy, vulkan, meshoptimizer, pygltflib, PIL" 2>/dev/null; then
    echo "device_meshlets.sh: $PYTHON cannot import numpy, vulkan, meshoptimizer, pygltflib" \
         "and PIL: set PYTHONPATH" >&2
    missing=1
fi
[[ $missing == 0 ]] || exit 1

. "$(dirname "$0")/device_info.sh"
device_info "$OUT/device.txt"

start=$SECONDS
# the budget counts from this script's start: unpacking device_env.sh's wheels comes off it
BUDGET=$((BUDGET - SECONDS))
set +e
"$PYTHON" benchmarks/bench_meshlets.py --scene-dir "$SCENES_DIR" --scenes "$scenes" \
    --budget "$BUDGET" --out "$OUT/bench_meshlets$suffix.md" \
    --jsonl "$OUT/bench_meshlets$suffix.jsonl" "$@" 2>&1 | tee "$OUT/bench_meshlets$suffix.log"
status=${PIPESTATUS[0]}
set -e
echo "device_meshlets.sh: $part took $((SECONDS - start)) s (exit $status)" \
    | tee -a "$OUT/bench_meshlets$suffix.log"
exit "$status"
