"""rfw's path tracer against Mitsuba 3 on the agreement scenes (not a test).

    .venv/bin/python benchmarks/mitsuba_check.py [--scenes cornell,spheres,GLTF]
        [--size 256x256]
        [--spp 1024] [--seed 0] [--max-depth -1] [--sky 1.0]
        [--rfw cornell=out/pt/cornell/pt.hdr.exr ...] [--rfw-config configs/pathtrace.toml]
        [--rfw-frames 256] [--no-controls] [--out out/mitsuba_check]

For each scene (a built-in name, ``rfw.scene.agreement``, or a scene file: the default
list ends with the glTF agreement scene ``tests/data/agreement/still_life.gltf``, which
``scripts/make_still_life.py`` writes), Mitsuba (``rfw.truth.mitsuba``, llvm_ad_rgb on the
CPU) renders the reference at ``--spp``, cached as an EXR under ``OUT/mitsuba/`` keyed by the
scene's arrays and texels, the conversion's source, Mitsuba's version, size, spp, seed, depth
and sky. SCENE below is the scene's name (a file's stem: ``still_life``). The image checked
against it is, in this order: the EXR ``--rfw SCENE=PATH`` names; else,
when ``--rfw-config`` exists, its output ``pt.hdr`` of ``rfw run CONFIG --backend vk --scene
SCENE --size WxH --frames N --exr --out OUT/rfw/SCENE``; else a stand-in, Mitsuba at seed
``--seed + 1``, so the script runs end to end before the path tracer exists.

Each comparison prints, over all pixels and channels of linear radiance (camera misses are 0
in both):

- ``rel_mae``: mean |test - ref| / mean ref (the mean relative error),
- ``rel_bias``: mean test / mean ref - 1 (what a brighter or darker image shows first),
- ``hdr_flip``: mean HDR-FLIP (``flip-evaluator``; FLIP takes the exposure range from ref).

Beside the checked image it prints, unless ``--no-controls``: the noise floor (Mitsuba at
seed ``--seed + 1`` against the reference: two independent estimates at the same spp) and
the negative controls, rendered at that same seed so only the change separates them from
the floor: every light 10 % brighter; in scenes with a metal, its roughness 0.1 lower; in
scenes with a base colour texture, its image upside down (v read the wrong way).
``x floor`` is each metric over the floor's. Results are JSON lines in
``OUT/mitsuba_check.jsonl``, one per comparison, with the render times and versions.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.bench.images import hdr_flip  # noqa: E402
from rfw.fileio import read_exr, write_exr  # noqa: E402
from rfw.scene import Scene, is_builtin, load_scene  # noqa: E402
from rfw.truth import mitsuba as truth  # noqa: E402


def metrics(ref: np.ndarray, test: np.ndarray) -> dict[str, float]:
    """The module docstring's three numbers of ``test`` against ``ref``."""
    ref, test = ref.astype(np.float64), test.astype(np.float64)
    mean = float(ref.mean())
    return {"rel_mae": float(np.abs(test - ref).mean()) / mean,
            "rel_bias": float(test.mean()) / mean - 1.0,
            "hdr_flip": hdr_flip(ref, test)}


def scene_digest(scene: Scene) -> str:
    """What the reference depends on: the scene's arrays, texels, materials, lights and
    cameras, the conversion's source and Mitsuba's version."""
    import mitsuba

    h = hashlib.sha256()
    for m in scene.meshes:
        for a in (m.positions, m.normals, m.uvs, m.indices):
            h.update(a.tobytes())
    for i in scene.instances:
        h.update(i.transform.tobytes() + str(i.mesh).encode())
    for t in scene.textures:
        h.update(t.pixels.tobytes() + repr(replace(t, pixels=None)).encode())
    h.update(repr((scene.materials, scene.lights, scene.cameras)).encode())
    h.update(inspect.getsource(truth).encode() + mitsuba.__version__.encode())
    return h.hexdigest()[:12]


def timed_render(scene: Scene, args: argparse.Namespace, seed: int) -> tuple[np.ndarray, float]:
    t = time.perf_counter()
    image = truth.render(scene, args.size, spp=args.spp, seed=seed, max_depth=args.max_depth,
                         sky=args.sky)
    return image, time.perf_counter() - t


def reference(scene: Scene, args: argparse.Namespace) -> tuple[np.ndarray, float | None, Path]:
    """Mitsuba's reference, from the cache when it holds it (time None)."""
    w, h = args.size
    path = (args.out / "mitsuba" / f"{scene.name}-{scene_digest(scene)}-{w}x{h}-{args.spp}spp"
            f"-seed{args.seed}-depth{args.max_depth}-sky{args.sky:g}.exr")
    if path.is_file():
        return read_exr(path)[..., :3].astype(np.float32), None, path
    image, seconds = timed_render(scene, args, args.seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_exr(path, image)
    return image, seconds, path


def rfw_image(name: str, source: str,
              args: argparse.Namespace) -> tuple[str, np.ndarray | None, float]:
    """The image to check and what it is: the ``--rfw`` EXR, the path tracer's run of
    ``source`` (a built-in name or a file), or None (the caller renders the stand-in)."""
    if name in args.rfw:
        return f"rfw {args.rfw[name]}", read_exr(args.rfw[name])[..., :3], 0.0
    if not args.rfw_config.is_file():
        return "stand-in", None, 0.0
    out = args.out / "rfw" / name
    cmd = [sys.executable, "-m", "rfw.cli", "run", str(args.rfw_config), "--backend", "vk",
           "--scene", source, "--size", f"{args.size[0]}x{args.size[1]}", "--frames",
           str(args.rfw_frames), "--exr", "--out", str(out)]
    t = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if done.returncode != 0:
        raise SystemExit(f"mitsuba_check: {' '.join(cmd)} failed ({done.returncode}):\n"
                         f"{done.stderr.strip()}")
    exr = out / "pt.hdr.exr"
    if not exr.is_file():
        found = sorted(p.name for p in out.glob("*.exr"))
        raise SystemExit(f"mitsuba_check: {out} has no pt.hdr.exr (it has {found})")
    return f"rfw {args.rfw_config.name} x{args.rfw_frames} frames", read_exr(exr)[..., :3], \
        seconds


def controls(scene: Scene) -> dict[str, Scene]:
    """The negative controls: every light 10 % brighter; each metal 0.1 smoother; each
    texture a base colour reads upside down."""
    out = {"light +10%": replace(scene, lights=[replace(li, intensity=li.intensity * 1.1)
                                                for li in scene.lights])}
    if any(m.metallic == 1.0 for m in scene.materials):
        out["roughness -0.1"] = replace(scene, materials=[
            replace(m, roughness=m.roughness - 0.1) if m.metallic == 1.0 else m
            for m in scene.materials])
    based = {m.base_color_texture for m in scene.materials} - {None}
    if based:
        out["texture flipped"] = replace(scene, textures=[
            replace(t, pixels=t.pixels[::-1].copy()) if k in based else t
            for k, t in enumerate(scene.textures)])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="cornell,spheres,tests/data/agreement/still_life.gltf")
    ap.add_argument("--size", default="256x256", help="WxH")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-depth", type=int, default=-1, help="Mitsuba's: -1 is unlimited")
    ap.add_argument("--sky", type=float, default=1.0)
    ap.add_argument("--rfw", action="append", default=[], metavar="SCENE=EXR")
    ap.add_argument("--rfw-config", type=Path, default=ROOT / "configs" / "pathtrace.toml")
    ap.add_argument("--rfw-frames", type=int, default=256)
    ap.add_argument("--no-controls", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "mitsuba_check")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    args.size = (w, h)
    args.rfw = dict(item.split("=", 1) for item in args.rfw)
    args.out.mkdir(parents=True, exist_ok=True)
    import drjit
    import mitsuba

    about = {"size": f"{w}x{h}", "spp": args.spp, "seed": args.seed,
             "max_depth": args.max_depth, "sky": args.sky, "variant": truth.VARIANT,
             "mitsuba": mitsuba.__version__, "drjit": drjit.__version__,
             "cpus": os.cpu_count(), "machine": platform.node()}
    print(f"mitsuba {mitsuba.__version__} ({truth.VARIANT}), {w}x{h}, {args.spp} spp, "
          f"seed {args.seed}, max_depth {args.max_depth}, sky {args.sky:g}, "
          f"{os.cpu_count()} cpus")
    print(f"{'scene':<10} {'image':<34} {'rel_mae':>8} {'rel_bias':>9} {'hdr_flip':>8} "
          f"{'x floor (mae flip)':>18} {'seconds':>8}")
    records = []
    for given in args.scenes.split(","):
        # a file from the repository root (ROOT / an absolute path is that path)
        source = given if is_builtin(given) else str(ROOT / given)
        scene = load_scene(source)
        name = scene.name
        ref, ref_s, ref_path = reference(scene, args)
        rows: list[tuple[str, np.ndarray, float]] = []
        label, image, seconds = rfw_image(name, source, args)
        floor = None
        if image is None or not args.no_controls:
            floor, floor_s = timed_render(scene, args, args.seed + 1)
        if image is None:
            label, image, seconds = (f"stand-in = floor: mitsuba seed {args.seed + 1}", floor,
                                     floor_s)
        if image.shape != ref.shape:
            raise SystemExit(f"mitsuba_check: {name}: {label} is {image.shape[1]}x"
                             f"{image.shape[0]}, the reference {w}x{h}")
        rows.append((label, image, seconds))
        if not args.no_controls:
            if image is not floor:  # the stand-in is the floor itself
                rows.append((f"noise floor: mitsuba seed {args.seed + 1}", floor, floor_s))
            for what, changed in controls(scene).items():
                control, control_s = timed_render(changed, args, args.seed + 1)
                rows.append((f"control: {what}", control, control_s))
        print(f"{name:<10} reference {ref_path.name[-40:]}: "
              f"{'cached' if ref_s is None else f'{ref_s:.1f} s'}")
        base = metrics(ref, floor) if floor is not None else None
        for label, image, seconds in rows:
            m = metrics(ref, image)
            ratio = (f"{m['rel_mae'] / base['rel_mae']:5.1f} {m['hdr_flip'] / base['hdr_flip']:5.1f}"
                     if base and label.startswith("control") else "")
            print(f"{name:<10} {label[:34]:<34} {m['rel_mae']:8.4f} {m['rel_bias']:+9.4f} "
                  f"{m['hdr_flip']:8.4f} {ratio:>18} {seconds:8.1f}")
            records.append({**about, "scene": name, "image": label, **m, "seconds": seconds,
                            "reference": str(ref_path), "reference_seconds": ref_s})
    with (args.out / "mitsuba_check.jsonl").open("a") as f:
        for r in records:
            f.write(json.dumps(r) + "\n")
    print(f"wrote {args.out / 'mitsuba_check.jsonl'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
