"""Writing pixels through the raster pipeline against writing them from compute (issue 13,
item 2: what the G-buffer's per-pixel cost is).

bench_scaling.py shows the ``gbuffer`` pass costing far more than the depth-only floor, by an
amount that grows with the pixels written and not with geometry or textures. This bench takes
geometry out entirely and writes the same bytes two ways, on the wgpu backend's device:

- ``raster``: one full-screen triangle into the attachments (cleared, then every pixel written
  by a fragment shader that outputs constants);
- ``clear``: the attachments cleared by the render pass and nothing drawn;
- ``compute``: a compute shader storing the same constants into the same formats as storage
  textures, 8x8 threads a group.

Attachment sets: ``gbuffer`` (rfw's four G-buffer targets, 24 bytes a pixel: rgba8unorm,
rgba16float, rgba8unorm, rgba16float), ``hdr`` (one rgba16float, 8 bytes) and ``id`` (one
r32uint, 4 bytes: what a visibility buffer writes). sRGB formats cannot be storage textures,
so the G-buffer's albedo is rgba8unorm here in both ways. GPU ms from timestamps around each
pass, median over the frames; gigapixels and gigabytes a second follow from them.

    .venv/bin/python benchmarks/bench_fill.py --sizes 1280x720,3840x2160 --frames 50
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SETS = {"gbuffer": ("rgba8unorm", "rgba16float", "rgba8unorm", "rgba16float"),
        "hdr": ("rgba16float",), "id": ("r32uint",)}
BYTES = {"rgba8unorm": 4, "rgba16float": 8, "r32uint": 4}
WAYS = ("clear", "raster", "compute")


def _value(fmt: str, k: int) -> tuple[str, str]:
    # (WGSL type, a constant of it) for target k's format
    if fmt == "r32uint":
        return "vec4<u32>", f"vec4<u32>({k + 7}u, 0u, 0u, 1u)"
    return "vec4<f32>", f"vec4<f32>(0.25, 0.5, {0.1 * (k + 1):.2f}, 1.0)"


def fragment_source(formats: tuple[str, ...]) -> str:
    fields = "\n".join(f"    @location({k}) o{k}: {_value(f, k)[0]}," for k, f in
                       enumerate(formats))
    values = ", ".join(_value(f, k)[1] for k, f in enumerate(formats))
    return f"""
struct Out {{
{fields}
}};
@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {{
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
}}
@fragment
fn fs() -> Out {{
    return Out({values});
}}
"""


def compute_source(formats: tuple[str, ...]) -> str:
    decls = "\n".join(f"@group(0) @binding({k}) var t{k}: texture_storage_2d<{f}, write>;"
                      for k, f in enumerate(formats))
    stores = "\n".join(f"    textureStore(t{k}, p, {_value(f, k)[1]});"
                       for k, f in enumerate(formats))
    return f"""
{decls}
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {{
    let size = textureDimensions(t0);
    if (id.x >= size.x || id.y >= size.y) {{ return; }}
    let p = vec2<i32>(id.xy);
{stores}
}}
"""


class Bench:
    """One device, a timestamp query set and the programs of each attachment set."""

    def __init__(self) -> None:
        import wgpu

        from rfw.backends.wgpu import Device
        self.wgpu = wgpu
        self.dev = Device()
        if "timestamp-query" not in self.dev.features:
            raise SystemExit("bench_fill.py: the device has no timestamp queries")
        self.d = self.dev.device
        self.queries = self.d.create_query_set(type="timestamp", count=2)
        self.resolve = self.d.create_buffer(size=16, usage=wgpu.BufferUsage.QUERY_RESOLVE |
                                            wgpu.BufferUsage.COPY_SRC)

    def targets(self, formats: tuple[str, ...], size: tuple[int, int]) -> list[Any]:
        u = self.wgpu.TextureUsage
        return [self.d.create_texture(size=(*size, 1), format=f,
                                      usage=u.RENDER_ATTACHMENT | u.STORAGE_BINDING | u.COPY_SRC)
                for f in formats]

    def _stamps(self) -> dict[str, Any]:
        return {"query_set": self.queries, "beginning_of_pass_write_index": 0,
                "end_of_pass_write_index": 1}

    def _ms(self, encoder: Any) -> float:
        encoder.resolve_query_set(self.queries, 0, 2, self.resolve, 0)
        self.d.queue.submit([encoder.finish()])
        raw = np.frombuffer(self.d.queue.read_buffer(self.resolve, 0, 16), np.uint64)
        return float(raw[1] - raw[0]) * self.dev.timestamp_period / 1e6

    def raster(self, formats: tuple[str, ...], views: list[Any], draw: bool) -> Any:
        module = self.d.create_shader_module(code=fragment_source(formats))
        pipe = self.d.create_render_pipeline(
            layout="auto", vertex={"module": module, "entry_point": "vs"},
            fragment={"module": module, "entry_point": "fs",
                      "targets": [{"format": f} for f in formats]},
            primitive={"topology": "triangle-list"})

        def frame() -> float:
            enc = self.d.create_command_encoder()
            rp = enc.begin_render_pass(color_attachments=[
                {"view": v, "load_op": "clear", "store_op": "store",
                 "clear_value": (0, 0, 0, 0)} for v in views], timestamp_writes=self._stamps())
            if draw:
                rp.set_pipeline(pipe)
                rp.draw(3)
            rp.end()
            return self._ms(enc)
        return frame

    def compute(self, formats: tuple[str, ...], views: list[Any],
                size: tuple[int, int]) -> Any:
        module = self.d.create_shader_module(code=compute_source(formats))
        pipe = self.d.create_compute_pipeline(layout="auto",
                                              compute={"module": module, "entry_point": "main"})
        group = self.d.create_bind_group(layout=pipe.get_bind_group_layout(0), entries=[
            {"binding": k, "resource": v} for k, v in enumerate(views)])

        def frame() -> float:
            enc = self.d.create_command_encoder()
            cp = enc.begin_compute_pass(timestamp_writes=self._stamps())
            cp.set_pipeline(pipe)
            cp.set_bind_group(0, group)
            cp.dispatch_workgroups((size[0] + 7) // 8, (size[1] + 7) // 8)
            cp.end()
            return self._ms(enc)
        return frame

    def check(self, tex: Any, fmt: str, size: tuple[int, int], k: int) -> None:
        """Every pixel of target ``k`` holds the constant: the way wrote them all."""
        px = BYTES[fmt]
        data = self.d.queue.read_texture({"texture": tex}, {"bytes_per_row": px * size[0]},
                                         (*size, 1))
        dtype = {"rgba8unorm": np.uint8, "rgba16float": np.float16, "r32uint": np.uint32}[fmt]
        a = np.frombuffer(data, dtype).reshape(size[1], size[0], -1)
        want = a[0, 0].copy()
        first, tol = {"r32uint": (k + 7, 0), "rgba8unorm": (64, 1),
                      "rgba16float": (0.25, 1e-3)}[fmt]
        if not (np.all(a == want) and abs(float(want[0]) - first) <= tol):
            raise SystemExit(f"bench_fill.py: target {k} ({fmt}) was not filled")


def measure(bench: Bench, name: str, size: tuple[int, int], frames: int,
            warmup: int) -> list[dict[str, Any]]:
    formats = SETS[name]
    texs = bench.targets(formats, size)
    views = [t.create_view() for t in texs]
    runs = {"clear": bench.raster(formats, views, draw=False),
            "raster": bench.raster(formats, views, draw=True),
            "compute": bench.compute(formats, views, size)}
    out = []
    for way in WAYS:
        for _ in range(warmup):
            runs[way]()
        ms = statistics.median(runs[way]() for _ in range(frames))
        if way != "clear":
            for k, (t, f) in enumerate(zip(texs, formats, strict=True)):
                bench.check(t, f, size, k)
        pixels = size[0] * size[1]
        nbytes = pixels * sum(BYTES[f] for f in formats)
        out.append({"set": name, "way": way, "size": f"{size[0]}x{size[1]}", "gpu_ms": ms,
                    "gpix_s": pixels / ms / 1e6, "gb_s": nbytes / ms / 1e6,
                    "bytes_per_pixel": nbytes // pixels})
    for t in texs:
        t.destroy()
    return out


def report(rows: list[dict[str, Any]], device: str) -> str:
    lines = [f"# Raster against compute writes (bench_fill.py)\n\n{device}\n",
             "| targets | size | way | GPU ms | Gpixel/s | GB/s | raster ÷ compute |",
             "|---|---|---|---:|---:|---:|---:|"]
    by = {(r["set"], r["size"], r["way"]): r for r in rows}
    for r in rows:
        comp = by[(r["set"], r["size"], "compute")]["gpu_ms"]
        ratio = f"{r['gpu_ms'] / comp:.2f}x" if r["way"] != "compute" else ""
        lines.append(f"| {r['set']} ({r['bytes_per_pixel']} B/px) | {r['size']} | {r['way']} "
                     f"| {r['gpu_ms']:.3f} | {r['gpix_s']:.2f} | {r['gb_s']:.1f} | {ratio} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1280x720,3840x2160")
    ap.add_argument("--sets", default=",".join(SETS))
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--out", help="folder for fill.md and fill.json (default: print only)")
    args = ap.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    bench = Bench()
    rows = [row for name in args.sets.split(",") for size in sizes
            for row in measure(bench, name, size, args.frames, args.warmup)]
    info = bench.dev.describe()
    text = report(rows, f"{info['device']} ({info['driver']}), wgpu over {info['api']}; "
                        f"median of {args.frames} frames after {args.warmup}")
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "fill.md").write_text(text)
        (out / "fill.json").write_text(json.dumps({"device": info, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
