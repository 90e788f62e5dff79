"""The ``rfw bench`` arguments and what they run (kept light: argparse only at import).

    rfw bench CONFIG... [options]        run the matrix, write results.jsonl and the reports
        [--executor ray [--ray-address ADDR]]  its runs as Ray tasks, one per GPU
    rfw bench compare OLD NEW [--out D]  per-pass changes beyond the noise (D: md/html)
    rfw bench report DIR [--reference]   re-write the reports from DIR/results.jsonl
    rfw bench report BUNDLE [--out D]    the reports again from a bundle alone (D: out/report)
    rfw bench replay BUNDLE [--out D]    re-run a bundle (OUT/bundle.tar), compare images
                                         and timings (D: out/replay; rfw.bench.replay)
    --diff-scale shared                  difference images on one scale (default: own)

Relative paths (configs, scenes, ``--out``, folders to compare) mean what they mean in the
caller's working directory, and the runs happen there. Exit code: 0 when every run worked,
1 when any failed (one line each on stderr; the report of the others is still written),
2 for bad input, found before any run starts.
"""

from __future__ import annotations

import argparse
import sys
import typing
from functools import partial
from pathlib import Path

from .. import argtypes
from ..errors import RfwError, check_number

if typing.TYPE_CHECKING:
    from ..outdir import OutputFolder

PEER_NAMES = ("moderngl", "pyvista", "pygfx", "open3d", "mitsuba", "embree", "rfw_raycast")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("configs", nargs="+", metavar="CONFIG",
                   help="config TOMLs or names in configs/ (deferred, forward, ...), "
                        "CONFIG@vk to pin one config's backend; or 'compare OLD NEW', "
                        "'report DIR|BUNDLE' or 'replay BUNDLE'")
    p.add_argument("--scene", action="append", help="scene file, 'default', a built-in or "
                   "fetched scene's name ('rfw scenes list'); repeatable: a matrix axis")
    p.add_argument("--fetch", action="store_true",
                   help="fetch a named scene (--scene dragon) that is not cached yet "
                   "(also RFW_FETCH=1)")
    p.add_argument("--size", type=argtypes.size, help="output size WxH (default: the first config's)")
    p.add_argument("--frames", type=int, default=10, help="timed frames per run (default 10)")
    p.add_argument("--warmup", type=int, default=2, help="untimed frames first (default 2)")
    p.add_argument("--repeat", type=int, default=3,
                   help="runs (processes) per variant, interleaved (default 3)")
    p.add_argument("--backend", action="append", choices=["wgpu", "vk"],
                   help="repeatable: a matrix axis (default wgpu)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="applied to every run, as in rfw run (repeatable)")
    p.add_argument("--vary", action="append", metavar="KEY=V1,V2",
                   help="a matrix axis of --set values, e.g. ao=on,off (repeatable)")
    p.add_argument("--peers", default="none",
                   help=f"peers to measure side by side: all, none or a comma list of "
                        f"{', '.join(PEER_NAMES)} (default none)")
    p.add_argument("--peer-frames", type=int,
                   help="timed frames of a peer run (default: --frames)")
    p.add_argument("--reference", help="variant the images are compared against: index or "
                   "label (default: the first); or pathtrace[:SPP] (default SPP 256): the "
                   "path tracer's ground truth of every view, each variant's error against "
                   "it and the error-versus-GPU-ms fronts (Vulkan; cached in "
                   "$RFW_CACHE_TRUTH, else ~/.cache/rfw/truth)")
    p.add_argument("--diff-scale", choices=["own", "shared"], default="own",
                   help="difference images: each from 0 to its own largest difference "
                        "(own, default), or all on the largest of the report (shared) to "
                        "compare magnitudes across variants; also for compare and report")
    p.add_argument("--order", choices=["rotate", "shuffle"], default="rotate",
                   help="order of variants within a repeat (default rotate)")
    p.add_argument("--seed", type=int, default=0, help="seed of --order shuffle")
    p.add_argument("--timeout", type=float, default=600, help="seconds per run (default 600)")
    p.add_argument("--executor", choices=["local", "ray"], default="local",
                   help="local: one run after another here (default); ray: the runs as Ray "
                        "tasks, one per GPU (one per CPU where there is none)")
    p.add_argument("--ray-address", metavar="ADDR", type=ray_address,
                   help="with --executor ray: an existing cluster (auto, HOST:6379, "
                        "ray://HOST:10001); default: a local Ray instance rfw starts and stops")
    p.add_argument("--out", help="output folder (default out/bench); compare: where "
                   "compare.md and compare.html go (default: print only); replay: the "
                   "replay's folder (default out/replay); report BUNDLE: where the reports "
                   "go (default out/report)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--threshold", type=threshold, default=0.05,
                   help="compare: relative change that counts (default 0.05)")
    p.add_argument("--fail-on-regression", action="store_true",
                   help="compare: exit 1 when a regression is flagged")
    p.add_argument("--all", action="store_true", help="compare: list unchanged entries too")
    p.add_argument("--allow-mismatch", action="store_true",
                   help="compare: compare runs whose size, frames, warm-up, scene or settings "
                        "differ (the report says what differs at its top)")


def threshold(text: str) -> float:
    """An argparse type: ``--threshold``, a finite relative change at least 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {text!r}") from None
    if not 0.0 <= value < float("inf"):  # nan fails both comparisons
        raise argparse.ArgumentTypeError(f"must be a finite number at least 0 (0.05: 5%), "
                                         f"not {text}")
    return value


def ray_address(text: str) -> str:
    """An argparse type: ``auto``, ``HOST:PORT`` or ``ray://HOST:PORT``, checked while the
    arguments are parsed (before anything is printed); whether anything answers there is
    checked when Ray connects."""
    if text == "auto":
        return text
    if text.startswith(("http://", "https://")):
        raise argparse.ArgumentTypeError(
            f"expected auto, HOST:PORT or ray://HOST:PORT, not {text!r} (the dashboard's http "
            "address is not the cluster's)")
    host, colon, port = text.removeprefix("ray://").rpartition(":")
    if not colon or not host or "/" in host or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(
            f"expected auto, HOST:PORT or ray://HOST:PORT, not {text!r}")
    return text


def run(args: argparse.Namespace) -> int:
    """Exit code: 0 when every run worked, 1 when any failed (the report of the others is
    still written), 2 for bad input (raised as an RfwError before any run)."""
    from ..graph import GraphError

    head, rest = args.configs[0], args.configs[1:]
    if head == "compare":
        from .compare import compare

        if len(rest) != 2:
            raise GraphError("usage: rfw bench compare OLD NEW (folders or results.jsonl)",
                             element="bench compare")
        return compare(Path(rest[0]), Path(rest[1]), threshold=args.threshold,
                       fail_on_regression=args.fail_on_regression, show_all=args.all,
                       out=_out_dir(args.out) if args.out else None,
                       allow_mismatch=args.allow_mismatch, diff_scale=args.diff_scale)
    if head == "replay":
        from .replay import replay

        if len(rest) != 1:
            raise GraphError("usage: rfw bench replay BUNDLE [--out DIR]",
                             element="bench replay")
        return replay(Path(rest[0]), _out_dir(args.out or "out/replay"),
                      progress=not args.no_progress)
    if head == "report":
        from .report import main_report

        if len(rest) != 1:
            raise GraphError("usage: rfw bench report DIR", element="bench report")
        if Path(rest[0]).is_file():  # a bundle: its reports again, from it alone
            from .replay import report

            return report(Path(rest[0]), _out_dir(args.out or "out/report"))
        try:
            return main_report(rest[0], reference=args.reference, diff_scale=args.diff_scale)
        except ValueError as e:
            if isinstance(e, RfwError):
                raise
            raise GraphError(str(e), file=rest[0]) from None
    from .runner import make_plan, run_plan

    peers = _peers(args.peers)
    _check_peer_camera(peers, args.set, args.vary)
    plan = make_plan(args.configs, scenes=args.scene, fetch=args.fetch, size=args.size,
                     frames=args.frames,
                     warmup=args.warmup, repeat=args.repeat, backends=args.backend,
                     sets=args.set, vary=args.vary, peers=peers, order=args.order,
                     seed=args.seed, timeout=args.timeout, peer_frames=args.peer_frames)
    from .truth import parse as parse_truth

    truth = parse_truth(args.reference)  # pathtrace[:SPP], checked before any run
    if truth is None:
        _check_reference(args.reference, [j.label for j in plan.jobs if j.kind == "rfw"])
    elif args.executor != "local":
        raise RfwError("--reference pathtrace runs with --executor local only (the runs' "
                       "linear images stay on the node that rendered them)",
                       element="--reference")
    plan.truth = truth
    if peers:  # a config's own [camera] table is a camera the peers do not render either
        _check_config_camera(plan)
    if args.ray_address is not None and args.executor != "ray":
        raise RfwError("--ray-address needs --executor ray", element="--ray-address")
    if args.ray_address is not None and args.ray_address != "auto":
        from .ray_executor import check_address

        check_address(args.ray_address)  # nothing answering there: said before the header
    out = _out_dir(args.out or "out/bench")
    print(f"rfw bench: {len(plan.jobs)} variant(s) x {plan.repeat} repeat(s) at "
          f"{plan.size[0]}x{plan.size[1]}, {plan.frames} frames (+{plan.warmup} warm-up) "
          f"-> {out}")
    for note in plan.notes:
        print(f"  note: {note}")
    executor = None  # one process after another, here
    if args.executor == "ray":
        from .ray_executor import ray_runs

        executor = partial(ray_runs, address=args.ray_address)
    from ..outdir import OutputFolder

    # the runs and the report are staged: the folder's earlier bench is replaced only by a
    # complete new one; an interrupted or failed bench keeps what it ran as partial-<time>/
    folder = OutputFolder(out)
    for name in ("results.jsonl", "results.csv", "truth.json", "truth.csv", "attribution.csv",
                 REPORT_MD, REPORT_HTML, BUNDLE):
        folder.target(name)  # a FIFO or device there is refused before any run
    with folder:
        try:
            results = run_plan(plan, folder.staging, progress=not args.no_progress,
                               executor=executor)
            if truth is not None:
                from .runner import load_results
                from .truth import render_references

                render_references(folder.staging, load_results(results), truth,
                                  timeout=plan.timeout, progress=not args.no_progress)
            code, written = _finish(folder.staging, results, args.reference, args.diff_scale)
            from .bundle import write_bundle

            # everything that defines this bench, in one file (rfw bench replay BUNDLE)
            bundle, _ = write_bundle(folder.staging, plan, reference=args.reference,
                                     diff_scale=args.diff_scale)
            written.append(bundle)
        except BaseException as e:
            _keep_partial(folder, len(plan.schedule()), e)
            raise
        folder.commit(last=[REPORT_MD, REPORT_HTML])
    print("wrote " + ", ".join(str(out / p.relative_to(folder.staging)) for p in written))
    return code


REPORT_MD, REPORT_HTML = "report.md", "report.html"  # written last: they mark a whole bench
BUNDLE = "bundle.tar"  # rfw.bench.bundle
PARTIAL_NOTE = "PARTIAL.txt"


def _keep_partial(folder: OutputFolder, total: int, error: BaseException) -> None:
    """Move what an unfinished bench ran to ``OUT/partial-<time>/`` with ``PARTIAL.txt``
    saying how far it got (``rfw bench report`` reads it); the folder's earlier results stay
    as they were. An :class:`rfw.signals.Interrupted` gets a note saying so."""
    import contextlib
    import os

    from ..outdir import partial_name, signals_held
    from ..signals import Interrupted

    results = folder.staging / "results.jsonl"
    try:
        done = sum(1 for line in results.read_bytes().splitlines() if line.strip())
    except OSError:
        done = 0
    if done == 0:  # nothing worth keeping: the staging folder goes
        if isinstance(error, Interrupted):
            error.note = f"after 0 of {total} runs; earlier results untouched"
        return
    why = "interrupted" if isinstance(error, Interrupted) else \
        f"stopped by {type(error).__name__}: {error}"
    with signals_held(), contextlib.suppress(OSError):
        # an unfinished report would pass for a whole one: only the runs are kept
        for name in (REPORT_MD, REPORT_HTML, "results.csv", "attribution.csv", BUNDLE):
            (folder.staging / name).unlink(missing_ok=True)
        (folder.staging / PARTIAL_NOTE).write_text(
            f"rfw bench {why} after {done} of {total} runs: these are its results so far "
            f"('rfw bench report' on this folder reports them); the results beside this "
            "folder are the previous complete bench's\n", encoding="utf-8")
        target = partial_name(folder.out)
        os.replace(folder.staging, target)
        if isinstance(error, Interrupted):
            error.note = (f"after {done} of {total} runs (kept in {target}; earlier results "
                          "untouched)")


def _out_dir(text: str) -> Path:
    """``--out`` from the working directory, as an absolute path (runs use it elsewhere)."""
    out = Path(text).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise RfwError("not a folder", file=text, element="--out")
    return out


def _check_peer_camera(peers: list[str], sets: list[str] | None,
                       vary: list[str] | None) -> None:
    # peers render their own default camera: a camera.* setting would make their numbers and
    # images those of another view while the report claims the same one
    if not peers:
        return
    for flag, items in (("--set", sets or []), ("--vary", vary or [])):
        for item in items:
            key = item.partition("=")[0].strip()
            if key == "camera" or key.startswith("camera."):
                raise RfwError(f"peers render their default camera, not {flag} {key}: drop "
                               "--peers or the camera setting", element="--peers")


def _check_config_camera(plan) -> None:
    from .runner import _check

    for job in plan.jobs:
        if job.kind == "rfw" and _check(Path(job.config), list(job.sets)).camera:
            raise RfwError("peers render their default camera, not this config's [camera]: "
                           "drop --peers or the camera table", file=job.config,
                           element="--peers")


def _check_reference(reference: str | None, labels: list[str]) -> None:
    # checked before the runs: a typo must not cost the whole benchmark
    if reference is None or reference in labels:
        return
    if reference.isdigit():
        check_number(int(reference), "--reference", kind=int, lo=0, hi=len(labels) - 1,
                     element="--reference")
        return
    raise RfwError(f"no such variant ({', '.join(labels)})",
                   element=f"--reference '{reference}'", suggest=(reference, labels))


def _finish(out: Path, results: Path, reference: str | None,
            diff_scale: str = "own") -> tuple[int, list[Path]]:
    """Write the report of the runs that worked; list the failed runs, one line each.
    Returns the exit code and the files to name."""
    from .report import write_report
    from .runner import load_results

    records = load_results(results)
    failed = [r for r in records if r.get("error")]
    md, page = write_report(out, reference=reference, diff_scale=diff_scale)
    if not failed:
        return 0, [results, md, page]
    all_failed = len(failed) == len(records)
    print(f"rfw bench: {'all ' if all_failed else ''}{len(failed)} of {len(records)} runs "
          "failed:", file=sys.stderr)
    for r in failed:
        why = " ".join(str(r["error"]).split())
        print(f"  {r.get('variant')} #{int(r.get('repeat', 0)) + 1}: {why}", file=sys.stderr)
    return 1, [results, md, page]


def _peers(text: str) -> list[str]:
    from ..graph import GraphError
    from ..graph.errors import did_you_mean

    if text in ("", "none"):
        return []
    if text == "all":
        return list(PEER_NAMES)
    names = [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in PEER_NAMES:
            raise GraphError(f"unknown peer '{n}'" + did_you_mean(n, PEER_NAMES),
                             element="--peers")
    return names
