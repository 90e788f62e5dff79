#!/usr/bin/env bash
# Builds, on a Debian 12 x86-64 machine with network, the git-ignored folders that
# benchmarks/device_env.sh unpacks on the GPU machine (Ubuntu 24.04, python 3.12, no network):
#
#   .gl   the Vulkan loader and GL dispatch .debs (unpacked into / there)
#   .whl  py3.12 manylinux wheels of rfw's pins that the GPU image lacks, and the meshoptimizer
#         sdist (device_env.sh builds it there)
#   .deb  Debian 12's glslang-tools, spirv-tools and vulkan-validationlayers (unpacked into /tmp/gl)
#   .scenes  the dragon and city scenes as compact .npz (about 8 MiB), fetched here and exported
#         by bench_meshlets.py --export-scenes: the GPU machine cannot fetch them
#
#   bash benchmarks/device_prepare.sh        # then carry .gl .whl .deb (.scenes) in the device call
#
# The image already holds numpy, pillow, matplotlib, tqdm, pytest, pytest-xdist, hypothesis,
# setuptools, wheel, packaging, wrapt, typing-inspect and mypy-extensions, so they are not
# carried: everything carried counts towards the call's 64 MiB. A second run fetches nothing new.
set -euo pipefail
cd "$(dirname "$0")/.."
# the venv has setuptools, which reading the sdist's metadata needs
py=${PYTHON:-$(test -x .venv/bin/python && echo .venv/bin/python || echo python3)}

# git never sees them (the device call carries ignored folders only when named)
exclude=$(git rev-parse --git-path info/exclude)
mkdir -p "$(dirname "$exclude")"
for d in .gl .whl .deb .scenes; do
    grep -qxF "/$d/" "$exclude" 2>/dev/null || echo "/$d/" >>"$exclude"
done
mkdir -p .gl .whl .deb

# amd64 lists of their own, so that the host's apt state is left alone
lists=/tmp/rfw-apt-amd64
mkdir -p "$lists/partial"
apt_o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
apt-get "${apt_o[@]}" -qq update
(cd .gl && apt-get "${apt_o[@]}" -qq download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 \
    libglx0 libgles2)
(cd .deb && apt-get "${apt_o[@]}" -qq download glslang-tools spirv-tools vulkan-validationlayers)

# rfw's pins (pyproject.toml) and their needs, less what the image has
wheels=(
    wgpu==0.32.0 rendercanvas==2.7.2 cffi==2.1.1 pycparser==3.12
    vulkan==1.3.275.1 glfw==2.11.0 trimesh==5.2.0 tomli-w==1.2.0
    pygltflib==1.16.5 dataclasses-json==0.6.7 marshmallow==3.26.2 deprecated==1.3.1
    flip-evaluator==1.7 embreex==4.4.0.post1 rtoml==0.14.0 openexr==3.5.3
    # the raster peers (benchmarks/peers: moderngl, pygfx) and what they need; pyvista's VTK
    # (566 MiB installed) cannot travel in a device call
    moderngl==5.13.0 glcontext==3.1.0 pygfx==0.17.0 pylinalg==0.6.8 freetype-py==2.5.1
    uharfbuzz==0.57.0 hsluv==5.0.5 jinja2==3.1.6 markupsafe==3.0.4
    # glTF KHR_draco_mesh_compression
    DracoPy==2.2.0
)
platforms=()
for n in 17 27 28 31 34 35; do platforms+=(--platform "manylinux_2_${n}_x86_64"); done
platforms+=(--platform manylinux2014_x86_64 --platform manylinux1_x86_64)
"$py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp "${platforms[@]}" -d .whl "${wheels[@]}"
# PyPI has only its source; device_env.sh compiles it there
"$py" -m pip download -q --no-deps --no-binary=:all: --no-build-isolation -d .whl \
    meshoptimizer==0.2.30a0

# one version of each wheel, or pip refuses the whole install there
dupes=$(ls .whl | sed -E 's/-[0-9].*//' | tr '[:upper:]_' '[:lower:]-' | sort | uniq -d)
if [[ -n $dupes ]]; then
    echo "device_prepare.sh: more than one version in .whl of: $dupes" >&2
    exit 1
fi

# the benchmarks' fetched scenes (bench_meshlets.py, bench_rt.py read .scenes/<name>.npz)
if [[ ! -f .scenes/dragon.npz || ! -f .scenes/city.npz ]]; then
    "$py" -m rfw.cli scenes fetch dragon city
    "$py" benchmarks/bench_meshlets.py --export-scenes .scenes
fi
total=$(du -scm .gl .whl .deb .scenes | tail -1 | cut -f1)
echo "device_prepare.sh: .gl .whl .deb .scenes hold ${total} MiB (a device call carries 64 MiB" \
     "at most, the working tree included)"
[[ $total -lt 60 ]] || { echo "device_prepare.sh: too large to carry" >&2; exit 1; }
