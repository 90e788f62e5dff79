#!/usr/bin/env python3
"""Check that some Vulkan device has what rfw needs (mesh shaders, ray tracing, BDA).

Runs `vulkaninfo` (text output, no display needed) and parses the per-GPU sections.
Stdlib only, so it runs with the system /usr/bin/python3 before any venv exists.

Exit status: 0 if at least one device has every capability, 1 otherwise.
  --json   print {"ok": bool, "icd_override": str|null, "devices": [dict per device]}
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import platform
import re
import shutil
import subprocess
import sys

# mesa names lavapipe's icd lvp_icd.json (newer) or lvp_icd.<arch>.json (older)
ICD_DIRS = ("/usr/share/vulkan/icd.d", "/usr/local/share/vulkan/icd.d", "/etc/vulkan/icd.d")

# (capability, extension, [(feature struct names, feature field)])
# feature structs are matched by name so that e.g. the NV mesh shader struct,
# which has fields of the same name, does not count.
CAPABILITIES: list[tuple[str, str | None, list[tuple[tuple[str, ...], str]]]] = [
    (
        "mesh_shader",
        "VK_EXT_mesh_shader",
        [
            (("VkPhysicalDeviceMeshShaderFeaturesEXT",), "taskShader"),
            (("VkPhysicalDeviceMeshShaderFeaturesEXT",), "meshShader"),
        ],
    ),
    (
        "acceleration_structure",
        "VK_KHR_acceleration_structure",
        [(("VkPhysicalDeviceAccelerationStructureFeaturesKHR",), "accelerationStructure")],
    ),
    (
        "ray_query",
        "VK_KHR_ray_query",
        [(("VkPhysicalDeviceRayQueryFeaturesKHR",), "rayQuery")],
    ),
    (
        "ray_tracing_pipeline",
        "VK_KHR_ray_tracing_pipeline",
        [(("VkPhysicalDeviceRayTracingPipelineFeaturesKHR",), "rayTracingPipeline")],
    ),
    (
        "buffer_device_address",
        None,  # core in vulkan 1.2; the feature bit is what matters
        [
            (
                (
                    "VkPhysicalDeviceVulkan12Features",
                    "VkPhysicalDeviceBufferDeviceAddressFeatures",
                    "VkPhysicalDeviceBufferDeviceAddressFeaturesKHR",
                ),
                "bufferDeviceAddress",
            )
        ],
    ),
]

INSTALL_HINT = (
    "install mesa-vulkan-drivers >= 25 (lavapipe; on debian 12 from bookworm-backports: "
    "apt-get install -t bookworm-backports mesa-vulkan-drivers) or a GPU driver "
    "exposing these; run scripts/setup-system.sh as root on debian 12"
)

GPU_RE = re.compile(r"^GPU(\d+):\s*$")
STRUCT_RE = re.compile(r"^\s*(Vk\w+)(?:\s*\[[^\]]*\])?\s*:\s*$")
FIELD_RE = re.compile(r"^\s*(\w+)\s*=\s*(.*?)\s*$")
EXT_RE = re.compile(r"^\s*(VK_\w+)\s*:\s*extension revision\s*(\d+)")
TRUE_VALUES = {"true", "vk_true", "1"}


def parse_vulkaninfo(text: str) -> list[dict]:
    """Split vulkaninfo's text output into per-device dicts of properties, extensions, features."""
    # instance extensions and layers come before this header; only devices follow it.
    marker = text.find("Device Properties and Extensions")
    body = text[marker:] if marker >= 0 else text
    devices: list[dict] = []
    dev: dict | None = None
    struct = None
    for line in body.splitlines():
        m = GPU_RE.match(line)
        if m:
            dev = {"index": int(m.group(1)), "extensions": {}, "structs": {}}
            devices.append(dev)
            struct = None
            continue
        if dev is None:
            continue
        m = EXT_RE.match(line)
        if m:
            dev["extensions"][m.group(1)] = int(m.group(2))
            continue
        m = STRUCT_RE.match(line)
        if m:
            struct = m.group(1)
            dev["structs"].setdefault(struct, {})
            continue
        if line.strip().startswith("Device Extensions"):
            struct = None
            continue
        m = FIELD_RE.match(line)
        if m and struct is not None:
            dev["structs"][struct].setdefault(m.group(1), m.group(2))
    return devices


def evaluate(dev: dict) -> dict:
    """Reduce a parsed device to name/driver info plus ok/missing per capability."""
    props = dev["structs"].get("VkPhysicalDeviceProperties", {})
    drv = dev["structs"].get("VkPhysicalDeviceDriverProperties", {})
    caps: dict[str, dict] = {}
    for cap, ext, feats in CAPABILITIES:
        missing = []
        if ext is not None and ext not in dev["extensions"]:
            missing.append(f"extension {ext}")
        for structs, field in feats:
            value = None
            for s in structs:
                value = dev["structs"].get(s, {}).get(field)
                if value is not None and value.lower() in TRUE_VALUES:
                    break
            if value is None or value.lower() not in TRUE_VALUES:
                missing.append(f"feature {structs[0]}.{field} ({value or 'absent'})")
        caps[cap] = {"ok": not missing, "extension": ext, "missing": missing}
    return {
        "index": dev["index"],
        "name": props.get("deviceName", "?"),
        "type": props.get("deviceType", "?"),
        "api_version": props.get("apiVersion", "?"),
        "driver_version": props.get("driverVersion", "?"),
        "driver_name": drv.get("driverName", "?"),
        "driver_info": drv.get("driverInfo", ""),
        "ok": all(c["ok"] for c in caps.values()),
        "capabilities": caps,
    }


def find_lavapipe_icd() -> str | None:
    arch = platform.machine()
    for d in ICD_DIRS:
        for name in (f"lvp_icd.{arch}.json", "lvp_icd.json"):
            if os.path.exists(os.path.join(d, name)):
                return os.path.join(d, name)
        found = sorted(glob.glob(os.path.join(d, "lvp_icd*.json")))
        if found:
            return found[0]
    return None


def run_vulkaninfo(env: dict[str, str]) -> tuple[int, str, str]:
    try:
        proc = subprocess.run(
            ["vulkaninfo"],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        return 124, "", "vulkaninfo timed out"
    return proc.returncode, proc.stdout, proc.stderr


def collect() -> dict:
    if shutil.which("vulkaninfo") is None:
        return {
            "ok": False,
            "error": "vulkaninfo not found (install vulkan-tools and libvulkan1)",
            "icd_override": None,
            "devices": [],
        }
    env = dict(os.environ)
    env.pop("DISPLAY", None)  # no window system needed; avoids hangs on a dead X server
    env.pop("WAYLAND_DISPLAY", None)
    rc, out, err = run_vulkaninfo(env)
    devices = [evaluate(d) for d in parse_vulkaninfo(out)] if rc == 0 else []
    override = None
    # only point the loader at lavapipe by hand if it found nothing by itself.
    icd = None if devices else find_lavapipe_icd()
    if icd:
        env["VK_DRIVER_FILES"] = icd  # loader >= 1.3.207
        env["VK_ICD_FILENAMES"] = icd  # older loaders
        rc2, out2, err2 = run_vulkaninfo(env)
        devices2 = [evaluate(d) for d in parse_vulkaninfo(out2)] if rc2 == 0 else []
        if devices2:
            rc, out, err, devices, override = rc2, out2, err2, devices2, icd
    result: dict = {
        "ok": any(d["ok"] for d in devices),
        "icd_override": override,
        "devices": devices,
    }
    if not devices:
        tail = "\n".join((err or out).strip().splitlines()[-5:])
        result["error"] = f"vulkaninfo found no usable device (exit {rc}): {tail}"
    return result


def report(result: dict) -> None:
    if result.get("icd_override"):
        print(
            f"check_vulkan: loader found no device by itself; used VK_DRIVER_FILES={result['icd_override']}"
        )
    if result.get("error"):
        print(f"check_vulkan: {result['error']}")
    for d in result["devices"]:
        info = f" [{d['driver_info']}]" if d["driver_info"] else ""
        print(
            f"check_vulkan: GPU{d['index']}: {d['name']} ({d['type']}), "
            f"driver {d['driver_name']} {d['driver_version']}{info}, api {d['api_version']}"
        )
        for cap, c in d["capabilities"].items():
            label = c["extension"] or cap
            print(f"check_vulkan:   {'ok     ' if c['ok'] else 'missing'} {label}")
    if result["ok"]:
        good = next(d for d in result["devices"] if d["ok"])
        print(
            f"check_vulkan: ok: GPU{good['index']} ({good['name']}) has every required capability"
        )
        return
    if not result["devices"]:
        print("check_vulkan: FAILED: no vulkan device found")
    else:
        print("check_vulkan: FAILED: no device has every required capability; missing:")
    for d in result["devices"]:
        for cap, c in d["capabilities"].items():
            for m in c["missing"]:
                print(f"check_vulkan:   GPU{d['index']} {d['name']}: {cap}: {m}")
    print(f"check_vulkan: to fix: {INSTALL_HINT}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    result = collect()
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        print()
    else:
        report(result)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
