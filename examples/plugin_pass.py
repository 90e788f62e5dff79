"""A pass written in code: register it, build a config around it, render, save the images.

    python examples/plugin_pass.py --out out/plugin
    python examples/plugin_pass.py --set invert.amount=0.5 --backend vk

The shader, ``invert.comp.glsl``, lies beside this file (a pass's shader is resolved next to
the file that defines the class); the same SPIR-V runs on wgpu and vk.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Annotated, ClassVar

import numpy as np
from _common import out_problem  # this folder is on the path: the script runs from it

import rfw
from rfw.argtypes import size as wxh
from rfw.authoring import ComputePass, Range, Settings, Slot, Tex2D, register_pass


@register_pass("invert")
class InvertPass(ComputePass):
    """Inverts a display color: mix(color, 1 - color, amount)."""

    replay = "auto"  # its commands depend on its settings and images only
    shader = "invert.comp.glsl"  # resolved next to this file
    inputs: ClassVar[dict[str, Slot]] = {"color": Tex2D(desc="display color (rgba8unorm)")}
    outputs: ClassVar[dict[str, Slot]] = {
        "inverted": Tex2D("rgba8unorm", size_of="color", desc="inverted color")}

    class Params(Settings):
        amount: Annotated[float, Range(0.0, 1.0)] = 1.0  # 0: unchanged, 1: inverted

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("inverted"), t_color=ctx.sampled("color"),
                     o_inverted=ctx.storage("inverted"), u_params=self.params)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=wxh, default="320x180", help="WxH")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--backend", default="wgpu")
    ap.add_argument("--out", default="out/plugin", help="folder for the images")
    args = ap.parse_args()
    why = out_problem(Path(args.out))
    if why:
        print(f"plugin_pass: error: {why}", file=sys.stderr)
        return 2

    try:
        cfg = rfw.make_config(
            "plugin_demo",
            [{"name": "flat"},  # a built-in pass: the scene, flat shaded
             {"name": "invert", "inputs": {"color": "flat.color"}}],
            outputs=["flat.color", "invert.inverted"], size=args.size)
        result = rfw.run(cfg, *args.set, backend=args.backend)
        written = result.save(args.out)
    except rfw.RfwError as e:
        print(f"plugin_pass: error: {e}", file=sys.stderr)
        return 2

    color = result.images["flat.color"][..., :3].astype(int)
    inverted = result.images["invert.inverted"][..., :3].astype(int)
    print(f"invert: {result.gpu_ms['invert']:.3f} GPU ms on {result.timings['device']}")
    print(f"max |inverted - (255 - color)| = {np.abs(inverted - (255 - color)).max()}")
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
