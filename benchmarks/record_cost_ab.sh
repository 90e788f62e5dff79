#!/usr/bin/env bash
# benchmarks/record_cost.py for an earlier tree (./old22: `git archive COMMIT | tar -x -C old22`)
# and this one, in ROUNDS rounds that alternate which goes first, for deferred on vk and wgpu
# and forward on wgpu at 1280x720; one JSON line per run appended to OUTFILE. Source
# benchmarks/device_env.sh first on the GPU machine (PY: the python, default python3).
#
#   bash benchmarks/record_cost_ab.sh OUTFILE ROUNDS FRAMES
site=${PYTHONPATH%%:$PWD*}
for k in $(seq 1 $2); do
  for side in old new; do
    [ $((k % 2)) = 0 ] && side=$([ $side = old ] && echo new || echo old)
    t=$PWD; [ $side = old ] && t=$PWD/old22
    for c in "vk deferred" "wgpu deferred" "wgpu forward"; do
      set -- "$1" "$2" "$3"; b=${c% *}; cf=${c#* }
      res=$(cd $t && PYTHONPATH=$site:$t ${PY:-python3} $OLDPWD/benchmarks/record_cost.py $t $3 $b $cf 1280x720 2>/dev/null | tail -1)
      echo "{\"round\": $k, \"side\": \"$side\", \"backend\": \"$b\", \"config\": \"$cf\", \"r\": $res}" >> $1
    done
  done
done
