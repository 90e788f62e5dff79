#!/usr/bin/env bash
# The device frame table of two trees in one session, on one GPU machine: an earlier commit
# (OLD, a checkout or `git archive` of it) and this tree, with the same matrix
# (benchmarks/device_bench.sh: BENCH_SIZE, BENCH_FRAMES; peers and the graph benchmark off),
# in AB_ROUNDS rounds (default 3) of one repeat a side that alternate which tree goes first,
# so drift in the machine's state falls on both; then `rfw bench compare` of the two sides'
# records. Source device_env.sh first (its PYTHONPATH ends with this tree).
#
#   bash benchmarks/device_ab.sh OLD OUT
set -euo pipefail
cd "$(dirname "$0")/.."
py=${PYTHON:-python3}
old=$(cd "$1" && pwd)
out=$2
site=${PYTHONPATH%%:$PWD*}  # device_env.sh's site-packages, without this tree
export BENCH_GRAPH=0 BENCH_REPEAT=1
side() {  # side NAME ROUND
  if [ "$1" = old ]; then
    (cd "$old" && PYTHONPATH="$site:$old" bash benchmarks/device_bench.sh "$out/old/r$2" --peers none)
  else
    PYTHONPATH="$site:$PWD" bash benchmarks/device_bench.sh "$out/new/r$2" --peers none
  fi
}
for k in $(seq 1 "${AB_ROUNDS:-3}"); do
  if [ $((k % 2)) = 1 ]; then side old "$k"; side new "$k"; else side new "$k"; side old "$k"; fi
done
# one record file a side: round k's runs are repeat k-1, their images found where they are
for s in old new; do
  "$py" - "$out/$s" > "$out/$s.jsonl" <<'PY'
import json, sys
from pathlib import Path

side = Path(sys.argv[1])
for k, folder in enumerate(sorted(side.glob("r*"), key=lambda f: int(f.name[1:]))):
    for line in (folder / "results.jsonl").read_text().splitlines():
        record = json.loads(line)
        record["repeat"] = k
        if record.get("image"):
            record["image"] = str(folder / record["image"])
        print(json.dumps(record))
PY
done
PYTHONPATH="$site:$PWD" "$py" -m rfw.cli bench compare "$out/old.jsonl" "$out/new.jsonl" \
  --out "$out/compare"
