#!/usr/bin/env bash
# The error-versus-cost fronts against the path tracer's truth (issue 23), one scene:
#
#   full     every raster and ray-traced config against the whole path-traced image
#   ao       no AO, SSAO (samples x radius) and rt_ao (1, 4, 16 rays) against the AO truth
#   shadows  shadow maps of 512-4096 texels and ray-traced shadows against the direct light
#            through pixel centres (the ambient term off; no anti-aliasing in the way)
#   aa       none, FXAA and TAA along an orbit, against the direct light over each pixel's
#            footprint, judged on the displayed image
#
# Each is one `rfw bench ... --reference pathtrace:COMPONENT:SPP` into $OUT/<scene>/<front>/.
#
#   OUT=out/fronts bash benchmarks/truth_fronts.sh                     # CI size, lavapipe
#   OUT=... SIZE=1280x720 SPP=1024 RT=ray_pipeline REPEAT=2 bash benchmarks/truth_fronts.sh
#   SCENE=.scenes/monastery.glb CAMERA="camera.position=[15,6,20] camera.target=[-5,3,-5]
#       camera.yfov=50" ...                                             # another scene
#   FRONTS="ao shadows" ...                                             # some of them
#
# RT: ray_query (lavapipe) or ray_pipeline (NVIDIA: no VK_KHR_ray_query). The runs use
# `rfw` from PATH, else python3 -m rfw.cli.
set -euo pipefail

: "${OUT:?set OUT to the folder for the results}"
SIZE=${SIZE:-256x144}
SPP=${SPP:-64}
RT=${RT:-ray_query}
FRAMES=${FRAMES:-10}
PATH_FRAMES=${PATH_FRAMES:-30}
REPEAT=${REPEAT:-2}
SCENE=${SCENE:-default}
CAMERA=${CAMERA:-}
FRONTS=${FRONTS:-full ao shadows aa}
RFW=${RFW:-$(command -v rfw || echo "python3 -m rfw.cli")}
name=$(basename "${SCENE%.*}")
sets=()
for c in $CAMERA; do sets+=(--set "$c"); done
common=(--scene "$SCENE" --size "$SIZE" --warmup 2 --repeat "$REPEAT" --no-progress "${sets[@]}")

for front in $FRONTS; do
    out="$OUT/$name/$front"
    echo "== $name $front -> $out"
    case $front in
    full)
        $RFW bench deferred@vk forward@vk deferred_ssao_shadows@vk rt_shadows@vk \
            deferred_vis@vk flat@vk --frames "$FRAMES" "${common[@]}" \
            --reference "pathtrace:full:$SPP" --out "$out" ;;
    ao)
        $RFW bench rt_shadows@vk --vary "ao=off,ssao,$RT" --vary ssao.samples=4,16,64 \
            --vary ssao.radius=0.5,1,2 --vary rt_ao.samples=1,4,16 --set "shadows=$RT" \
            --frames "$FRAMES" "${common[@]}" --reference "pathtrace:ao:$SPP" --out "$out" ;;
    shadows)
        $RFW bench rt_shadows@vk --vary "shadows=shadow_map,$RT" \
            --vary shadow.resolution=512,1024,2048,4096 --set ao=off --frames "$FRAMES" \
            "${common[@]}" --reference "pathtrace:direct_centre:$SPP" --out "$out" ;;
    aa)
        $RFW bench deferred_ssao_shadows@vk --vary aa=none,fxaa,taa --set camera.path=orbit \
            --set camera.path.turns=0.05 --frames "$PATH_FRAMES" "${common[@]}" \
            --reference "pathtrace:direct:$SPP" --out "$out" ;;
    *)
        echo "truth_fronts.sh: unknown front '$front' (full, ao, shadows, aa)" >&2
        exit 2 ;;
    esac
done
