#!/usr/bin/env bash
# rfw system setup: vulkan (mesa lavapipe >= 25 with mesh shaders and ray tracing),
# shader tools, glfw, xvfb and python venv support.
# idempotent: when everything is already in place it only runs the capability check.
# usage: scripts/setup-system.sh   (as root on debian 12; elsewhere it prints what to install)
set -euo pipefail

export DEBIAN_FRONTEND=noninteractive
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"

mesa_min=25
backports_file=/etc/apt/sources.list.d/bookworm-backports.sources
keyring=/usr/share/keyrings/debian-archive-keyring.gpg
# base packages come from the normal suite; mesa comes from bookworm-backports.
# xauth is needed by xvfb-run (only a recommends of xvfb, and recommends are skipped).
# libegl1 and libusb-1.0-0: the benchmark peers (moderngl/VTK on headless EGL; open3d links libusb).
# libllvm19: Dr.Jit's LLVM backend (mitsuba's llvm_ad_rgb, rfw.truth) loads libLLVM at run time;
# with only 14 and 15 (mesa's) present it picks one that fails on its kernels ("LLVM ERROR:
# Cannot select: fminimum").
base_pkgs=(libvulkan1 vulkan-tools vulkan-validationlayers glslang-tools spirv-tools g++ python3-dev
  libglfw3 xvfb xauth python3-venv python3-pip graphviz libegl1 libusb-1.0-0 libllvm19)
# mesa's gl/egl/gbm libraries come from backports too, so every mesa library is one version.
mesa_pkgs=(mesa-vulkan-drivers libgl1-mesa-dri libglx-mesa0 libegl-mesa0 libgbm1)
apt_opts=(-y -q --no-install-recommends -o DPkg::Lock::Timeout=300
  -o Dpkg::Options::=--force-confdef -o Dpkg::Options::=--force-confold)

say() { echo "rfw setup: $*"; }

# runs the vulkan capability check with the system python (stdlib only).
check_caps() {
  say "checking vulkan capabilities"
  /usr/bin/python3 "$here/check_vulkan.py"
}

os_id="" os_version=""
if [[ -r /etc/os-release ]]; then
  # shellcheck disable=SC1091  # sourced in a subshell so its variables stay out of ours
  read -r os_id os_version < <(. /etc/os-release && echo "${ID:-} ${VERSION_ID:-}") || true
fi

# --- not debian 12: say what is needed, then check what is there -------------
if [[ "$os_id" != debian || "$os_version" != 12 ]]; then
  say "unsupported os '${os_id:-unknown} ${os_version}' for automatic install (only debian 12 is automated)"
  cat <<'EOF'
rfw setup: install these with your package manager, then re-run this script:
  - mesa >= 25.0 vulkan drivers with lavapipe (debian/ubuntu: mesa-vulkan-drivers,
    fedora: mesa-vulkan-drivers, arch: vulkan-swrast); lavapipe must expose
    VK_EXT_mesh_shader, VK_KHR_acceleration_structure, VK_KHR_ray_query,
    VK_KHR_ray_tracing_pipeline (or use a gpu driver that does)
  - vulkan loader        (libvulkan1 | vulkan-loader | vulkan-icd-loader)
  - vulkaninfo           (vulkan-tools)
  - validation layers    (vulkan-validationlayers | vulkan-validation-layers)
  - glslangValidator     (glslang-tools | glslang)
  - spirv-val/spirv-opt  (spirv-tools)
  - glfw 3               (libglfw3 | glfw | glfw-x11)
  - Xvfb + xvfb-run      (xvfb + xauth | xorg-x11-server-Xvfb | xorg-server-xvfb)
  - python >= 3.11 with venv and pip (python3-venv python3-pip)
  - graphviz
EOF
  # tools the framework calls by name: a missing one fails here, not later.
  missing_tools=()
  for tool in vulkaninfo glslangValidator spirv-val Xvfb dot; do
    command -v "$tool" >/dev/null 2>&1 || missing_tools+=("$tool")
  done
  if ((${#missing_tools[@]})); then
    say "missing commands: ${missing_tools[*]}"
  fi
  rc=0
  check_caps || rc=$?
  if ((rc != 0 || ${#missing_tools[@]})); then
    say "system NOT ready (see above)"
    exit 1
  fi
  say "system ready"
  exit 0
fi

# --- debian 12 ---------------------------------------------------------------
# one dpkg-query for every package keeps the already-done path fast.
declare -A installed=()
while read -r name status; do
  [[ "$status" == installed ]] && installed[$name]=1
done < <(dpkg-query -W -f='${Package} ${db:Status-Status}\n' "${base_pkgs[@]}" "${mesa_pkgs[0]}" 2>/dev/null || true)

missing_base=()
for p in "${base_pkgs[@]}"; do
  [[ -n "${installed[$p]:-}" ]] || missing_base+=("$p")
done

mesa_version=""
if [[ -n "${installed[mesa-vulkan-drivers]:-}" ]]; then
  mesa_version="$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)"
fi
need_mesa=0
if [[ -z "$mesa_version" ]] || dpkg --compare-versions "$mesa_version" lt "$mesa_min"; then
  need_mesa=1
fi

# backports counts as enabled if any active sources entry already names it.
have_backports=0
shopt -s nullglob
for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources; do
  if grep -Eqs '^[^#]*bookworm-backports' "$f"; then have_backports=1; break; fi
done
shopt -u nullglob

if ((need_mesa == 0 && ${#missing_base[@]} == 0)); then
  say "packages present (mesa-vulkan-drivers $mesa_version)"
else
  # the plan is a list of shell commands: run as root, printed otherwise.
  plan=()
  if ((need_mesa && !have_backports)); then
    plan+=("printf '%s\n' 'Types: deb' 'URIs: http://deb.debian.org/debian' 'Suites: bookworm-backports' 'Components: main' 'Signed-By: $keyring' > $backports_file")
  fi
  plan+=("apt-get -q update")
  if ((${#missing_base[@]})); then
    plan+=("apt-get install ${apt_opts[*]} ${missing_base[*]}")
  fi
  if ((need_mesa)); then
    # -t lets apt take mesa's dependencies (libllvm, libdrm, ...) from backports too.
    plan+=("apt-get install ${apt_opts[*]} -t bookworm-backports ${mesa_pkgs[*]}")
  fi

  ((${#missing_base[@]})) && say "missing packages: ${missing_base[*]}"
  ((need_mesa)) && say "mesa-vulkan-drivers ${mesa_version:-not installed}, need >= $mesa_min (from bookworm-backports)"

  if ((EUID != 0)); then
    say "not root: run these commands as root (or re-run this script with sudo):"
    for cmd in "${plan[@]}"; do echo "  $cmd"; done
    exit 1
  fi
  if [[ ! -r "$keyring" ]]; then
    say "error: $keyring is missing (install debian-archive-keyring)"
    exit 1
  fi

  for cmd in "${plan[@]}"; do
    say "+ $cmd"
    eval "$cmd" </dev/null
  done

  mesa_version="$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)"
  if [[ -z "$mesa_version" ]] || dpkg --compare-versions "$mesa_version" lt "$mesa_min"; then
    say "error: mesa-vulkan-drivers is '${mesa_version:-not installed}' after install, need >= $mesa_min"
    say "check 'apt-cache policy mesa-vulkan-drivers' (bookworm-backports may lack it)"
    exit 1
  fi
  say "installed (mesa-vulkan-drivers $mesa_version)"
fi

if ! check_caps; then
  say "system NOT ready: vulkan capability check failed (see above)"
  exit 1
fi
say "system ready"
