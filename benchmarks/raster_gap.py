"""The lavapipe raster gap: rfw's ``flat`` frame beside moderngl's, one hypothesis at a time.

    python benchmarks/raster_gap.py [--size 320x180] [--frames 60] [--warmup 5]
        [--repeats 8] [--variants a,b,...] [--out DIR]

Every variant runs in its own process; the repeats rotate the order so drift hits every
variant alike (interleaved A/B). A process times only its frames: wall ms per frame, process
CPU ms per frame (user + sys of every thread, lavapipe's and llvmpipe's workers included,
from ``getrusage``), and minor page faults per frame. The table gives, per variant, the
median over repeats of each run's median wall ms, and the ratio to ``mgl`` paired by repeat
(median of the per-repeat ratios, bootstrap 95 % interval over repeats). Numbers go to
``$OUT`` (or ``--out``) as ``raster_gap.jsonl`` and ``raster_gap.md``.

A variant is a backend plus changes applied in its process (environment, or a patch of one
piece of state); see ``VARIANTS``. The patches are experiments: several change the image
(``img``), they measure what a piece of state costs, they are not rfw's behaviour.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

NO_TRIM = "glibc.malloc.trim_threshold=4294967295:glibc.malloc.mmap_threshold=33554432"
ONE_ARENA = "glibc.malloc.arena_max=1"

# the same per-vertex ALU work on both sides (a result too small to change a pixel): the
# CPU it adds, divided by the CPU it adds on the other side, is their ratio of vertex
# shader invocations (same JIT, same code)
ALU_ITERATIONS = 48
ALU_FN = f"""
float alu(vec3 p) {{
    float a = p.x + p.y;
    for (int i = 0; i < {ALU_ITERATIONS}; i++) {{ a = sin(a) * 1.0001 + p.z; }}
    return a * 1e-30;
}}
"""


COF = ("(sign(dot(instance.model[0].xyz, cross(instance.model[1].xyz, instance.model[2].xyz)))"
       " * mat3(cross(instance.model[1].xyz, instance.model[2].xyz), cross(instance.model[2]"
       ".xyz, instance.model[0].xyz), cross(instance.model[0].xyz, instance.model[1].xyz))"
       " * v_normal)")
# moderngl with rfw's vertex work: each vertex's instance matrices (model, inverse transpose)
# read from a storage buffer by the vertex's instance number, positions and normals local
INST_VERT = """
#version 430
uniform mat4 u_viewproj; uniform vec3 u_light; uniform float u_ambient;
struct Inst { mat4 model; mat4 normal; };
layout(std430, binding = 0) readonly buffer Insts { Inst items[]; };
in vec3 in_pos; in vec3 in_nrm; in vec3 in_col; in uint in_inst;
out vec3 v_col;
void main() {
    Inst it = items[in_inst];
    vec3 n = normalize((it.normal * vec4(in_nrm, 0.0)).xyz);
    float lam = max(dot(n, u_light), 0.0);
    v_col = in_col * (u_ambient + (1.0 - u_ambient) * lam);
    gl_Position = u_viewproj * (it.model * vec4(in_pos, 1.0));
}
"""


# name: (runner, backend, environment, patches, what it tests)
VARIANTS: dict[str, tuple[str, str, dict[str, str], tuple[str, ...], str]] = {
    "mgl": ("mgl", "gl", {}, (), "moderngl peer, as benchmarks/peers/moderngl_peer.py"),
    "mgl_d32f": ("mgl", "gl", {}, ("d32f",), "moderngl, depth DEPTH_COMPONENT32F"),
    "mgl_streams": ("mgl", "gl", {}, ("streams",),
                    "moderngl, rfw's vertex layout: 4 buffers, uv and tangent fetched"),
    "vk": ("rfw", "vk", {}, (), "rfw flat@vk as it is"),
    "wgpu": ("rfw", "wgpu", {}, (), "rfw flat@wgpu as it is"),
    "vk_fif1": ("rfw", "vk", {"RFW_FRAMES_IN_FLIGHT": "1"}, (), "vk, 1 frame in flight"),
    "vk_nots": ("rfw", "vk", {}, ("no_timestamps",), "vk, no timestamp queries"),
    "vk_d24": ("rfw", "vk", {}, ("d24",), "vk, depth X8_D24 instead of D32_SFLOAT"),
    "vk_vin2": ("rfw", "vk", {}, ("vin2",),
                "vk, vertex input of position + normal only (uv, tangent not fetched)"),
    "vk_nonrm": ("rfw", "vk", {}, ("nonrm",),
                 "vk, VS reads one instance matrix, not two (normal from the model's 3x3)"),
    "vk_bake": ("rfw", "vk", {}, ("bake",),
                "vk, the scene baked into one mesh per material (13 draws, identity instances)"),
    "vk_bare": ("rfw", "vk", {}, ("bake", "bare"),
                "vk, baked, and the VS reads no instance matrix (moderngl's vertex work)"),
    "vk_bare_vin2": ("rfw", "vk", {}, ("bake", "bare", "vin2"),
                     "vk, baked, bare VS, position + normal fetched only"),
    "mgl_alu": ("mgl", "gl", {}, ("alu",), f"moderngl, + a {ALU_ITERATIONS}-sin loop per vertex"),
    "vk_alu": ("rfw", "vk", {}, ("alu",), "vk, + the same loop per vertex"),
    "vk_bare_alu": ("rfw", "vk", {}, ("bake", "bare", "alu"), "vk, baked, bare VS, + the loop"),
    "vk_baseinst": ("rfw", "vk", {}, ("baseinst",),
                    "vk, the instance row indexed by gl_BaseInstance (uniform) not gl_InstanceIndex"),
    "vk_sgfirst": ("rfw", "vk", {}, ("sgfirst",),
                   "vk, the instance row indexed by subgroupBroadcastFirst(gl_InstanceIndex)"),
    "vk_cof": ("rfw", "vk", {}, ("cof",),
               "vk, the normal from the model matrix's cofactors (one matrix read)"),
    "wgpu_cof": ("rfw", "wgpu", {}, ("cof",), "wgpu, the normal from the cofactors"),
    "mgl_inst": ("mgl", "gl", {}, ("inst",),
                 "moderngl, local vertices + per-vertex instance matrices from an SSBO"),
    "vk_nobundle": ("rfw", "vk", {"RFW_VK_BUNDLES": "0", "RFW_VK_FRAME_REPLAY": "0"}, (),
                    "vk, every frame recorded again (no secondary buffers, no replay)"),
    "vk_notrim": ("rfw", "vk", {"GLIBC_TUNABLES": NO_TRIM}, (),
                  "vk, glibc never trims the queue thread's arena"),
    "vk_arena1": ("rfw", "vk", {"GLIBC_TUNABLES": ONE_ARENA}, (),
                  "vk, one malloc arena for all threads"),
    "wgpu_arena1": ("rfw", "wgpu", {"GLIBC_TUNABLES": ONE_ARENA}, (),
                    "wgpu, one malloc arena for all threads"),
    "vk_arena1_vin2": ("rfw", "vk", {"GLIBC_TUNABLES": ONE_ARENA}, ("vin2",),
                       "vk, one arena + vin2"),
    "vk_lp1": ("rfw", "vk", {"LP_NUM_THREADS": "1"}, (), "vk, LP_NUM_THREADS=1"),
    "mgl_lp1": ("mgl", "gl", {"LP_NUM_THREADS": "1"}, (), "moderngl, LP_NUM_THREADS=1"),
}
# the table of benchmarks/results/2026-12-03/raster_gap/README.md, in one run
DEFAULT = ("mgl", "vk", "wgpu", "vk_nots", "vk_fif1", "vk_d24", "vk_vin2", "vk_notrim",
           "vk_bake", "vk_bare", "vk_cof", "mgl_inst", "mgl_streams", "mgl_d32f")


# --- child: one variant's frames -------------------------------------------------------------
TICK_MS = 1e3 / os.sysconf("SC_CLK_TCK")


def threads_cpu() -> dict[str, float]:
    """CPU ms (user + sys) of each thread of this process so far, by role: ``main`` (the
    Python thread; moderngl's GL driver works in it), ``raster`` (llvmpipe's ``llvmpipe-N``
    rasterizer workers) and, per name, the others (lavapipe's queue thread is ``other:python``:
    it keeps the name of the thread that made it)."""
    out: dict[str, float] = {}
    pid = os.getpid()
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/self/task/{tid}/comm") as f:
                comm = f.read().strip()
        except OSError:
            continue  # the thread ended
        ms = (int(fields[11]) + int(fields[12])) * TICK_MS
        role = ("main" if int(tid) == pid else "raster" if comm.startswith("llvmpipe")
                else f"other:{comm}")
        out[role] = out.get(role, 0.0) + ms
    return out


class Meter:
    """Wall, process CPU, minor faults and per-thread CPU around each timed frame."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, int]] = []
        self.threads: list[dict[str, float]] = []

    def around(self, fn: Any) -> Any:
        def wrapped(*a: Any, **k: Any) -> Any:
            th = threads_cpu()
            t, r = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
            out = fn(*a, **k)
            r2 = resource.getrusage(resource.RUSAGE_SELF)
            self.rows.append(((time.perf_counter() - t) * 1e3,
                              (r2.ru_utime + r2.ru_stime - r.ru_utime - r.ru_stime) * 1e3,
                              r2.ru_minflt - r.ru_minflt))
            th2 = threads_cpu()
            self.threads.append({k: v - th.get(k, 0.0) for k, v in th2.items()})
            return out
        return wrapped

    def last(self, n: int) -> dict[str, Any]:
        rows, threads = self.rows[-n:], self.threads[-n:]
        per: dict[str, float] = {}
        for d in threads:
            for k, v in d.items():
                per[k] = per.get(k, 0.0) + v / len(threads)
        return {"wall_ms": [r[0] for r in rows], "cpu_ms": [r[1] for r in rows],
                "minflt": [r[2] for r in rows],
                "threads_ms": {k: round(v, 3) for k, v in sorted(per.items())}}


def _flat_shaders(patches: tuple[str, ...]) -> Path | None:
    """A folder with passes/flat's shaders changed as ``patches`` say (None: unchanged)."""
    if not {"vin2", "nonrm", "bare", "alu", "baseinst", "sgfirst", "cof"} & set(patches):
        return None
    src = ROOT / "passes" / "flat"
    vert = (src / "flat.vert.glsl").read_text()
    if "vin2" in patches:  # declare only the attributes the shader reads
        vert = vert.replace("#define MESH_VERTEX_INPUT\n", "#define MESH_VERTEX_INPUT\n"
                            "#define RFW_GAP_VIN2\n")
    if "nonrm" in patches:
        vert = vert.replace("(instance.normal * vec4(v_normal, 0.0)).xyz",
                            "mat3(instance.model) * v_normal")
    if "cof" in patches:  # the normal matrix from the model's 3x3 (cofactors x det's sign)
        vert = vert.replace("(instance.normal * vec4(v_normal, 0.0)).xyz", COF)
    if "bare" in patches:  # moderngl's vertex work: positions already in world space
        vert = vert.replace("instance.model * vec4(v_position, 1.0)", "vec4(v_position, 1.0)")
        vert = vert.replace("(instance.normal * vec4(v_normal, 0.0)).xyz", "v_normal")
    if "alu" in patches:  # a fixed cost per vertex invocation: the slope counts invocations
        vert = vert.replace("void main() {", ALU_FN + "void main() {")
        vert = vert.replace("o_light = u_params.ambient", "o_light = alu(v_position) + u_params.ambient")
    folder = Path(tempfile.mkdtemp(prefix="rfw-gap-"))
    (folder / "flat.vert.glsl").write_text(vert)
    (folder / "flat.frag.glsl").write_text((src / "flat.frag.glsl").read_text())
    mesh = (ROOT / "shaders" / "common" / "mesh.glsl").read_text()
    row = "#define instance (scene_instances.items[gl_InstanceIndex])"
    if "baseinst" in patches:  # the draw's firstInstance: uniform across the draw
        mesh = mesh.replace(row, "#extension GL_ARB_shader_draw_parameters : require\n"
                            + row.replace("gl_InstanceIndex", "gl_BaseInstanceARB"))
    if "sgfirst" in patches:  # the same row, read once per subgroup (lane 0's)
        mesh = mesh.replace(row, "#extension GL_KHR_shader_subgroup_ballot : require\n"
                            + row.replace("gl_InstanceIndex",
                                          "subgroupBroadcastFirst(gl_InstanceIndex)"))
    (folder / "mesh.glsl").write_text(mesh)
    if "vin2" in patches:
        for line in ("layout(location = 2) in vec2 v_uv;", "layout(location = 3) in vec4 v_tangent;"):
            mesh = mesh.replace(line, "#ifndef RFW_GAP_VIN2\n" + line + "\n#endif")
        (folder / "mesh.glsl").write_text(mesh)  # found before shaders/common (beside)
    return folder


def _patch_rfw(patches: tuple[str, ...]) -> None:
    if "no_timestamps" in patches:
        from vkext.device import VkDevice

        caps = VkDevice._caps
        VkDevice._caps = lambda self: caps(self) - {"timestamp"}  # type: ignore[method-assign]
    if "d24" in patches:
        from passes.flat.flat import FlatPass
        from rfw.authoring import DepthAttachment

        FlatPass.outputs = dict(FlatPass.outputs, depth=DepthAttachment("depth24plus"))
    if "vin2" in patches:
        import vkext.programs as vp
        from rfw.backends.wgpu import context as wctx

        vp._VERTEX = vp._VERTEX[:2]
        original = vp._vertex_input

        def two(keep: list[Any], topology: str = "triangle-list") -> tuple[Any, Any]:
            vertex, assembly = original(keep, topology)
            vertex.vertexBindingDescriptionCount = vertex.vertexAttributeDescriptionCount = 2
            return vertex, assembly

        vp._vertex_input = two
        wctx.VERTEX_BUFFERS = wctx.VERTEX_BUFFERS[:2]
    folder = _flat_shaders(patches)
    if folder is not None:
        from rfw.registry import get_pass

        get_pass("flat").shader_folder = folder


def baked(scene: Any) -> Any:
    """``scene`` with every instance baked into world space, one mesh (and one identity
    instance) per material: the peers' one mesh, split where the material changes."""
    import dataclasses

    import numpy as np

    from rfw.scene.model import Instance, Mesh

    parts: dict[int, list[tuple[np.ndarray, ...]]] = {}
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        t = np.asarray(inst.transform, np.float64)
        det = np.linalg.det(t[:3, :3])
        p = m.positions.astype(np.float64) @ t[:3, :3].T + t[:3, 3]
        n = m.normals.astype(np.float64) @ np.linalg.inv(t[:3, :3])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        tri = m.indices.reshape(-1, 3)
        parts.setdefault(m.material, []).append(
            (p, n, m.uvs, m.tangents, tri[:, [0, 2, 1]] if det < 0 else tri))
    meshes = []
    for mat, ps in sorted(parts.items()):
        base, idx = 0, []
        for p in ps:
            idx.append(p[4].astype(np.uint32) + base)
            base += len(p[0])
        cat = [np.ascontiguousarray(np.concatenate([p[k] for p in ps]), np.float32)
               for k in range(4)]
        meshes.append(Mesh(f"baked{mat}", *cat, np.concatenate(idx).ravel(), material=mat))
    eye = np.eye(4, dtype=np.float32)
    return dataclasses.replace(scene, meshes=meshes, cameras=scene.cameras or
                               [scene.default_camera()],
                               instances=[Instance(i, eye.copy()) for i in range(len(meshes))])


def child_rfw(backend: str, patches: tuple[str, ...], size: tuple[int, int], frames: int,
              warmup: int) -> dict[str, Any]:
    import numpy as np

    from rfw.backends.base import FrameExecutor
    from rfw.config import apply_overrides, load_config
    from rfw.options import RunOptions
    from rfw.render import render

    _patch_rfw(patches)
    cfg = apply_overrides(load_config(ROOT / "configs" / "flat.toml"),
                          [f"size={size[0]}x{size[1]}"])
    scene = None
    if "bake" in patches:
        from benchmarks.peers.common import load_scene

        scene = baked(load_scene("default"))
    meter = Meter()
    original = FrameExecutor.frame
    FrameExecutor.frame = meter.around(original)  # type: ignore[method-assign]
    try:
        result = render(cfg, backend=backend, scene=scene,
                        options=RunOptions.from_env(frames=frames, warmup=warmup))
    finally:
        FrameExecutor.frame = original  # type: ignore[method-assign]
    out = meter.last(frames)
    out["device"] = result.timings.get("device")
    img = np.asarray(result.images["flat.color"])
    _save_image(img[..., :3] if img.dtype == np.uint8 else
                np.clip(np.rint(img[..., :3] * 255), 0, 255).astype(np.uint8), out)
    return out


def child_mgl(patches: tuple[str, ...], size: tuple[int, int], frames: int,
              warmup: int) -> dict[str, Any]:
    import moderngl
    import numpy as np

    from benchmarks.peers import moderngl_peer as mp
    from benchmarks.peers.common import geometry, load_scene

    w, h = size
    scene = load_scene("default")
    geo, cam = geometry(scene), scene.default_camera()
    ctx = moderngl.create_standalone_context(backend="egl")
    ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
    vert = mp.VERT
    if "streams" in patches:  # fetch uv and tangent too (GL fetches only what is read)
        vert = vert.replace("in vec3 in_col;", "in vec3 in_col; in vec2 in_uv; in vec4 in_tan;")
        vert = vert.replace("v_col = in_col", "v_col = (in_col + 1e-30 * (in_uv.x + in_tan.w))")
    if "alu" in patches:
        vert = vert.replace("void main() {", ALU_FN + "void main() {")
        vert = vert.replace("v_col = in_col", "v_col = alu(in_pos) + in_col")
    if "inst" in patches:
        vert = INST_VERT
    prog = ctx.program(vertex_shader=vert, fragment_shader=mp.FRAG)
    vp = cam.projection(w / h).astype(np.float64) @ cam.view()
    vp = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]]) @ vp
    prog["u_viewproj"].write(vp.T.astype("f4").tobytes())
    prog["u_light"].value = tuple(float(v) for v in geo.light_dir)
    prog["u_ambient"].value = mp.AMBIENT
    ibo = ctx.buffer(geo.indices.astype("u4").tobytes())
    if "inst" in patches:
        data, ibo, ssbo = _instanced(ctx, scene, geo)
        ssbo.bind_to_storage_buffer(0)
        vao = ctx.vertex_array(prog, [(data, "3f 3f 3f u4", "in_pos", "in_nrm", "in_col",
                                       "in_inst")], index_buffer=ibo, index_element_size=4)
    elif "streams" in patches:
        n = len(geo.positions)
        bufs = [(ctx.buffer(a.astype("f4").tobytes()), f, name) for a, f, name in (
            (geo.positions, "3f", "in_pos"), (geo.normals, "3f", "in_nrm"),
            (geo.colors, "3f", "in_col"), (np.zeros((n, 2)), "2f", "in_uv"),
            (np.zeros((n, 4)), "4f", "in_tan"))]
        vao = ctx.vertex_array(prog, [(b, f, name) for b, f, name in bufs], index_buffer=ibo,
                               index_element_size=4)
    else:
        data = np.hstack([geo.positions, geo.normals, geo.colors]).astype("f4")
        vao = ctx.vertex_array(prog, [(ctx.buffer(data.tobytes()), "3f 3f 3f", "in_pos",
                                       "in_nrm", "in_col")], index_buffer=ibo,
                               index_element_size=4)
    depth = (ctx.depth_texture((w, h)) if "d32f" in patches
             else ctx.depth_renderbuffer((w, h)))
    fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((w, h))], depth_attachment=depth)

    def frame() -> None:
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        vao.render(moderngl.TRIANGLES)
        ctx.finish()

    meter = Meter()
    timed = meter.around(frame)
    for _ in range(warmup + frames):
        timed()
    out = meter.last(frames)
    out["device"] = ctx.info["GL_RENDERER"]
    rgb = np.frombuffer(fbo.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    _save_image(rgb, out)
    ctx.release()
    return out


def _instanced(ctx: Any, scene: Any, geo: Any) -> tuple[Any, Any, Any]:
    """The peer's one draw with rfw's vertex work: each instance's local vertices with its
    number, and the instances' model and normal matrices in a storage buffer."""
    import numpy as np

    from rfw.backends.scene_data import instance_blocks

    rows, verts, idx, base = [], [], [], 0
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        t = np.asarray(inst.transform, np.float64)
        det = np.linalg.det(t[:3, :3])
        c = np.asarray(scene.materials[m.material].base_color[:3], np.float32)
        v = np.zeros(len(m.positions), [("p", "f4", 3), ("n", "f4", 3), ("c", "f4", 3),
                                         ("i", "u4")])
        v["p"], v["n"], v["c"], v["i"] = m.positions, m.normals, c, len(rows)
        tri = m.indices.reshape(-1, 3).astype(np.uint32) + base
        idx.append(tri[:, [0, 2, 1]] if det < 0 else tri)
        verts.append(v)
        rows.append(inst.transform)
        base += len(v)
    blocks = np.asarray(instance_blocks(rows))
    return (ctx.buffer(np.concatenate(verts).tobytes()),
            ctx.buffer(np.concatenate(idx).tobytes()), ctx.buffer(blocks.tobytes()))


def _save_image(rgb: Any, out: dict[str, Any]) -> None:
    """The frame's 8-bit RGB beside the numbers (the parent compares variants' images)."""
    import numpy as np

    path = Path(tempfile.mkdtemp(prefix="rfw-gap-img-")) / "image.npy"
    np.save(path, np.ascontiguousarray(rgb))
    out["image"] = str(path)


def psnr(a: Any, b: Any) -> float:
    import numpy as np

    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0 ** 2 / mse)


def child(name: str, size: tuple[int, int], frames: int, warmup: int) -> dict[str, Any]:
    runner, backend, _env, patches, _what = VARIANTS[name]
    if runner == "mgl":
        return child_mgl(patches, size, frames, warmup)
    return child_rfw(backend, patches, size, frames, warmup)


# --- parent: interleaved runs and the table --------------------------------------------------
def median(v: list[float]) -> float:
    s = sorted(v)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def boot_ci(v: list[float], *, n: int = 2000, seed: int = 1) -> tuple[float, float]:
    rng = random.Random(seed)
    meds = sorted(median([rng.choice(v) for _ in v]) for _ in range(n))
    return meds[int(0.025 * n)], meds[int(0.975 * n) - 1]


def run_variant(name: str, args: argparse.Namespace) -> dict[str, Any]:
    env = dict(os.environ, **VARIANTS[name][2])
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", name, "--size", args.size,
           "--frames", str(args.frames), "--warmup", str(args.warmup)]
    p = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=600)
    if p.returncode:
        return {"variant": name, "error": (p.stderr or p.stdout)[-2000:]}
    return {"variant": name, **json.loads(p.stdout.strip().splitlines()[-1])}


def _image_psnr(runs: dict[int, Any], ref: dict[int, Any]) -> float | None:
    import numpy as np

    if not runs or not ref:
        return None
    a = np.load(next(iter(runs.values()))["image"])
    b = np.load(next(iter(ref.values()))["image"])
    return psnr(a, b) if a.shape == b.shape else None


def summarize(rows: list[dict[str, Any]], names: list[str], ref: str) -> list[dict[str, Any]]:
    by: dict[str, dict[int, dict[str, Any]]] = {n: {} for n in names}
    for r in rows:
        if "error" not in r:
            by[r["variant"]][r["repeat"]] = r
    out = []
    for n in names:
        runs = by[n]
        if not runs:
            out.append({"variant": n, "error": "no run worked"})
            continue
        s: dict[str, Any] = {"variant": n, "what": VARIANTS[n][4], "runs": len(runs)}
        s["psnr_vs_vk"] = _image_psnr(runs, by.get("vk", {}))
        s["psnr_vs_mgl"] = _image_psnr(runs, by.get("mgl", {}))
        lo = sorted(median(r["wall_ms"]) for r in runs.values())
        s["wall_ms_q25"] = lo[len(lo) // 4]
        for key in ("wall_ms", "cpu_ms"):
            s[key] = median([median(r[key]) for r in runs.values()])
        s["minflt"] = median([sum(r["minflt"]) / len(r["minflt"]) for r in runs.values()])
        roles = sorted({k for r in runs.values() for k in r["threads_ms"]})
        s["threads_ms"] = {k: median([r["threads_ms"].get(k, 0.0) for r in runs.values()])
                           for k in roles}
        for key in ("wall_ms", "cpu_ms"):
            pairs = [median(runs[k][key]) / median(by[ref][k][key])
                     for k in runs if k in by[ref]]
            if pairs:
                s[f"{key}_ratio"] = median(pairs)
                s[f"{key}_ci"] = boot_ci(pairs)
        out.append(s)
    return out


def table(summary: list[dict[str, Any]], ref: str, args: argparse.Namespace) -> str:
    lines = [f"size {args.size}, {args.frames} frames (+{args.warmup} warm-up) per process, "
             f"{args.repeats} interleaved repeats; ratios are variant / {ref}, paired by "
             "repeat (median, bootstrap 95 % CI); q25: the lower quartile of the runs' "
             "median wall (the least disturbed runs); thread CPU ms per frame: main (Python, "
             "and moderngl's GL driver), queue (lavapipe's queue thread: vertex shading, "
             "clipping, binning), raster (llvmpipe's workers); PSNR of the image against "
             "vk's and moderngl's", "",
             "| variant | what | wall ms | q25 | / mgl wall (CI) | CPU ms/frame | / mgl CPU (CI) "
             "| main / queue / raster | faults/frame | PSNR vk / mgl |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]

    def db(v: float | None) -> str:
        return "-" if v is None else "inf" if v == float("inf") else f"{v:.1f}"

    for s in summary:
        if "error" in s:
            lines.append(f"| {s['variant']} | failed | | | | | | | | |")
            continue
        wr, wc = s.get("wall_ms_ratio", float("nan")), s.get("wall_ms_ci", (0, 0))
        cr, cc = s.get("cpu_ms_ratio", float("nan")), s.get("cpu_ms_ci", (0, 0))
        th = s["threads_ms"]
        queue = sum(v for k, v in th.items() if k.startswith("other"))
        lines.append(f"| {s['variant']} | {s['what']} | {s['wall_ms']:.2f} | "
                     f"{s['wall_ms_q25']:.2f} | {wr:.3f} ({wc[0]:.3f}-{wc[1]:.3f}) | "
                     f"{s['cpu_ms']:.2f} | {cr:.3f} ({cc[0]:.3f}-{cc[1]:.3f}) | "
                     f"{th.get('main', 0):.1f} / {queue:.1f} / {th.get('raster', 0):.1f} | "
                     f"{s['minflt']:.0f} | {db(s['psnr_vs_vk'])} / {db(s['psnr_vs_mgl'])} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="benchmarks/raster_gap.py")
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=8)
    ap.add_argument("--variants", default=",".join(DEFAULT))
    ap.add_argument("--out", default=os.environ.get("OUT"))
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    if args.child:
        print(json.dumps(child(args.child, size, args.frames, args.warmup)))
        return 0
    names = [n.strip() for n in args.variants.split(",") if n.strip()]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        ap.error(f"unknown variants {unknown}; known: {', '.join(VARIANTS)}")
    ref = "mgl" if "mgl" in names else names[0]
    rows = []
    for k in range(args.repeats):
        order = names[k % len(names):] + names[:k % len(names)]
        for name in order:
            r = run_variant(name, args)
            r["repeat"] = k
            rows.append(r)
            msg = r.get("error", "").strip().splitlines()[-1:] if "error" in r else None
            print(f"repeat {k} {name}: " + (f"FAILED {msg}" if msg is not None else
                  f"wall {median(r['wall_ms']):.2f} ms cpu {median(r['cpu_ms']):.2f} ms"),
                  file=sys.stderr, flush=True)
    summary = summarize(rows, names, ref)
    text = table(summary, ref, args)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "raster_gap.jsonl", "w") as f:
            for r in rows:
                f.write(json.dumps(r) + "\n")
        (out / "raster_gap.md").write_text(text)
        (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
