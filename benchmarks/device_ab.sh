#!/usr/bin/env bash
# The device frame table of two trees in one session, on one GPU machine: an earlier commit
# (OLD, a checkout or `git archive` of it) and this tree, with the same matrix
# (benchmarks/device_bench.sh: BENCH_SIZE, BENCH_FRAMES, BENCH_REPEAT; peers and the graph
# benchmark off), then `rfw bench compare OLD_OUT NEW_OUT`. Source device_env.sh first.
#
#   bash benchmarks/device_ab.sh OLD OUT
set -euo pipefail
cd "$(dirname "$0")/.."
old=$(cd "$1" && pwd)
out=$2
site=${PYTHONPATH%%:$PWD*}  # device_env.sh's site-packages, without this tree
export BENCH_GRAPH=0
(cd "$old" && PYTHONPATH="$site:$old" bash benchmarks/device_bench.sh "$out/old" --peers none)
PYTHONPATH="$site:$PWD" bash benchmarks/device_bench.sh "$out/new" --peers none
PYTHONPATH="$site:$PWD" python3 -m rfw.cli bench compare "$out/old" "$out/new" --out "$out/compare"
