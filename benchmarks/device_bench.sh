#!/usr/bin/env bash
# `make bench` on a GPU machine (e.g. an NVIDIA H100) that has no package installs: python
# from $PYTHON (default python3), rfw and its dependencies from PYTHONPATH (the repository
# root plus a site-packages holding rfw's pins, and the `peers` extra where it can be
# carried). Peers whose packages or system libraries are missing are reported "unavailable"
# in the report, not dropped.
#
#   PYTHONPATH=$PWD:/path/to/site-packages benchmarks/device_bench.sh [OUT] [extra rfw bench args]
#
# BENCH_SIZE, BENCH_FRAMES, BENCH_REPEAT change the matrix; BENCH_GRAPH=0 skips the graph
# compiler's benchmark (bench_graph.py, CPU only, minutes) after it; RFW_MITSUBA_VARIANT=cuda_ad_rgb
# runs the Mitsuba peer on the GPU (default llvm_ad_rgb, CPU). Then compare with lavapipe's:
#   rfw bench compare out/bench OUT   (devices differ: read it as a ratio table, not a verdict)
set -euo pipefail
cd "$(dirname "$0")/.."
py=${PYTHON:-python3}
out=${1:-out/bench-device}
shift || true
"$py" -c "import rfw, wgpu, vulkan" || {
  echo "device_bench: rfw or its dependencies are not importable: set PYTHONPATH" >&2; exit 1; }
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
"$py" -m rfw.cli bench deferred deferred@vk deferred_vis@vk forward deferred_ssao_shadows meshlet@vk \
  flat flat@vk \
  --vary ao=on,off --size "${BENCH_SIZE:-1280x720}" --frames "${BENCH_FRAMES:-100}" \
  --warmup 5 --repeat "${BENCH_REPEAT:-5}" --peers all --peer-frames 20 --out "$out" "$@"
if [ "${BENCH_GRAPH:-1}" != 0 ]; then
  "$py" benchmarks/bench_graph.py --out "$out/bench_graph.jsonl"
fi
echo "device_bench: report in $out/report.md and $out/report.html"
