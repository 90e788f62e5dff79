"""``rfw bench replay BUNDLE [--out DIR]`` and ``rfw bench report BUNDLE [--out DIR]``.

Replay runs the bench a bundle (:mod:`rfw.bench.bundle`) describes again, from the bundle's
config bytes (unpacked to ``DIR/inputs/<sha12>/``, named by their content, so a second
replay writes the same bytes there) and scenes, with its size, frames, warm-up, repeats,
order and backends, into ``DIR`` as a bench of its own (``results.jsonl``, ``runs/``, its
report and ``bundle.tar``), the original unpacked beside it in ``DIR/original/``. Then:

- images, run by run (:func:`rule_for`): on the same adapter (device, driver and backend as
  the bundle's run recorded them, and the CPU for llvmpipe) they must be bit-identical, and
  where they are not the pixels that differ are named (how many, where, the first one's
  values); llvmpipe on another processor must agree within the golden scheme
  (:data:`rfw.golden.BOUNDS`, the bounds of the test suite's goldens across CPUs); another
  device or driver within the bounds measured between vendors
  (:data:`rfw.golden.VENDOR_BOUNDS`, which catch only coarse changes);
- graphs and SPIR-V: each variant's graph built again against the bundle's, each SPIR-V
  module's hash against the bundle's (what changed, when an image did);
- timings: ``rfw bench compare DIR/original DIR`` (written to ``DIR/compare/``).

``DIR/replay.json`` holds the verdicts. Exit code: 0 when every image agrees, 1 when one
does not (or a run failed), 2 for bad input (a damaged bundle: one line). Nothing is written
outside ``DIR``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RfwError
from ..fileio import atomic_write, inside
from .bundle import REPORT_FILES, RESULTS, Bundle, read_bundle
from .inputs import sha256

ORIGINAL = "original"
VERDICTS = "replay.json"


def replay(bundle_path: Path, out: Path, *, progress: bool = True) -> int:
    from ..outdir import OutputFolder
    from .bundle import write_bundle
    from .compare import compare
    from .records import parse_results
    from .report import write_report
    from .runner import load_results, run_plan

    bundle = read_bundle(bundle_path)
    folder = OutputFolder(out)
    for name in (RESULTS, VERDICTS, *REPORT_FILES):
        folder.target(name)
    with folder:
        plan = _plan(bundle, folder.out)
        p = bundle.plan
        print(f"rfw bench replay: {bundle.path} ({len(plan.jobs)} variant(s) x {plan.repeat} "
              f"repeat(s) at {plan.size[0]}x{plan.size[1]}, {plan.frames} frames) -> "
              f"{folder.out}")
        stage = folder.staging
        bundle.extract(stage / ORIGINAL)
        (stage / ORIGINAL / "manifest.json").write_text(
            json.dumps(bundle.manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")
        results = run_plan(plan, stage, progress=progress)
        reference = p.get("reference")
        from .truth import parse as parse_truth

        if parse_truth(reference) is not None:  # the references are not rendered again
            reference = None
        write_report(stage, reference=reference, diff_scale=p.get("diff_scale") or "own")
        _, manifest = write_bundle(stage, plan, reference=reference,
                                   diff_scale=p.get("diff_scale") or "own")
        old = parse_results(bundle.members[RESULTS], stage / ORIGINAL / RESULTS)
        new = load_results(results)
        verdict = judge(old, new, stage / ORIGINAL, stage)
        verdict["graphs"] = _graphs(bundle, plan, manifest)
        verdict["spirv"] = _spirv(old, new)
        verdict["rfw"] = {"bundle": bundle.manifest.get("rfw"),
                          "now": {"commit": (new[0] if new else {}).get("rfw_commit")}}
        atomic_write(stage / VERDICTS,
                     lambda f: f.write((json.dumps(verdict, indent=1) + "\n").encode()))
        folder.commit(last=list(REPORT_FILES))
        _say(verdict)
        print("timings (rfw bench compare):")
        sys.stdout.flush()
        try:
            compare(folder.out / ORIGINAL, folder.out, allow_mismatch=True,
                    out=folder.out / "compare", show_all=False)
        except RfwError as e:  # e.g. every run failed: the images said so already
            print(f"  not compared: {e}")
    return 0 if verdict["agree"] else 1


def _plan(bundle: Bundle, out: Path) -> Any:
    """The bench's plan with its configs and scenes unpacked under ``out/inputs``."""
    from ..errors import check_number
    from .runner import MAX_FRAMES, MAX_REPEAT, MAX_TIMEOUT, Job, Plan

    p = bundle.plan
    where = str(bundle.path)
    size = p["size"]
    if not (isinstance(size, list) and len(size) == 2 and all(
            isinstance(x, int) and not isinstance(x, bool) and 0 < x <= 16384 for x in size)):
        raise RfwError(f"damaged: plan.size {size!r}", file=where)
    frames = check_number(p["frames"], "frames", kind=int, lo=1, hi=MAX_FRAMES, file=where)
    warmup = check_number(p["warmup"], "warmup", kind=int, lo=0, hi=MAX_FRAMES, file=where)
    repeat = check_number(p["repeat"], "repeat", kind=int, lo=1, hi=MAX_REPEAT, file=where)
    timeout = check_number(p["timeout"], "timeout", lo=1e-3, hi=MAX_TIMEOUT, file=where)
    seed = check_number(p["seed"], "seed", kind=int, file=where)
    if p["order"] not in ("rotate", "shuffle"):
        raise RfwError(f"damaged: plan.order {p['order']!r}", file=where)
    jobs = []
    for j in bundle.manifest["jobs"]:
        scene = _scene(bundle, j.get("scene") or {}, j.get("scene_arg"), out)
        if j["kind"] == "peer":
            jobs.append(Job("peer", j["label"], j["id"], peer=j.get("peer", ""), scene=scene))
            continue
        config = _unpack(bundle, out, [j["config"]["member"]])
        jobs.append(Job("rfw", j["label"], j["id"], str(config),
                        tuple(map(str, j.get("sets") or [])),
                        tuple(map(str, j.get("varied") or [])), scene,
                        j.get("backend") or "wgpu"))
    return Plan(jobs, (size[0], size[1]), frames, warmup, repeat, p["order"], seed, timeout,
                list(p.get("notes") or []), p.get("peer_frames"))


def _scene(bundle: Bundle, s: dict[str, Any], arg: str | None, out: Path) -> str | None:
    """The scene a replayed job runs: a built-in as the bench named it; a file from the
    bundle, or (not embedded) from its path when its sha256 is the same."""
    if s.get("kind") != "file":
        return arg
    from .inputs import scene_hash

    if s.get("embedded"):
        base = s["embedded"].rpartition("/")[0] + "/"
        files = [s["embedded"], *(n for n in bundle.members
                                  if n.startswith(base) and n != s["embedded"])]
        return str(_unpack(bundle, out, files))
    path = Path(str(s.get("path")))
    if not path.is_file():
        raise RfwError(f"the scene is not in the bundle ({s.get('why', 'not embedded')}) and "
                       "not at its path", file=str(path), element="scene")
    if scene_hash(str(path)) != s.get("sha256"):
        raise RfwError("the scene is not in the bundle and this file is not the one the "
                       f"bench ran (sha256 {str(s.get('sha256'))[:12]})", file=str(path),
                       element="scene")
    return str(path)


def _unpack(bundle: Bundle, out: Path, names: list[str]) -> Path:
    """Write the members ``names`` (one folder of the bundle's ``inputs/``) to
    ``out/inputs/<sha12 of their bytes>/``, keeping their names in that folder; returns the
    first one's path. Named by content: a second replay writes the same bytes there, an
    edited bundle another folder."""
    if not all(n in bundle.members for n in names):
        raise RfwError(f"damaged: {names[0]} is not in the bundle", file=str(bundle.path))
    base = names[0].rpartition("/")[0] + "/"
    digest = sha256(b"".join(n.removeprefix(base).encode() + b"\0" + bundle.members[n]
                             + b"\0" for n in sorted(names)))
    folder = inside(out, f"inputs/{digest[:12]}")
    bundle.extract(folder, names, strip=base)
    return inside(folder, names[0].removeprefix(base))


def _adapter(r: dict[str, Any]) -> tuple[Any, Any, Any]:
    return r.get("device"), r.get("driver"), r.get("backend")


def _cpu_driver(r: dict[str, Any]) -> bool:
    # llvmpipe/lavapipe compile shaders for the host CPU: the same device name renders
    # differently on another processor
    return "llvmpipe" in str(r.get("device", "")).lower()


def rule_for(old: dict[str, Any], new: dict[str, Any]) -> str:
    """How a replayed image is judged against the original: ``bit-identical`` on the same
    adapter (device, driver, backend, and the CPU for a CPU driver), ``golden`` (the
    suite's bounds, :data:`rfw.golden.BOUNDS`) for the same CPU driver on another
    processor, ``vendor`` (:data:`rfw.golden.VENDOR_BOUNDS`) for another device or
    driver."""
    if _adapter(old) != _adapter(new):
        return "vendor"
    if _cpu_driver(old) and old.get("cpu") != new.get("cpu"):
        return "golden"
    return "bit-identical"


def judge(old: list[dict[str, Any]], new: list[dict[str, Any]], old_dir: Path,
          new_dir: Path) -> dict[str, Any]:
    """Each original run's image against the replay's run of the same variant and repeat:
    bit-identical on the same adapter, within the golden scheme on another."""
    from ..golden import BOUNDS, VENDOR_BOUNDS, mismatch

    now = {(r.get("variant_id"), r.get("repeat")): r for r in new}
    images = []
    for r in old:
        if not r.get("image"):
            continue
        key = (r.get("variant_id"), r.get("repeat"))
        row: dict[str, Any] = {"variant": r.get("variant"), "repeat": r.get("repeat"),
                               "image": r["image"], "adapter": list(_adapter(r))}
        again = now.get(key)
        if again is None or not again.get("image"):
            why = (again or {}).get("error") or "no such run"
            row.update(agree=False, rule="-", detail=f"no image in the replay ({why})")
            images.append(row)
            continue
        a = _rgba(inside(old_dir, r["image"]))
        b = _rgba(inside(new_dir, again["image"]))
        rule = rule_for(r, again)
        row["replay_adapter"] = list(_adapter(again))
        if a.shape != b.shape:
            row.update(agree=False, rule=rule, detail=f"shapes differ: {a.shape} vs {b.shape}")
        elif rule == "bit-identical":
            row.update(rule=rule, **pixels_differ(a, b))
        else:
            bounds = BOUNDS if rule == "golden" else VENDOR_BOUNDS
            why = mismatch(b, a, bounds)
            row.update(rule=rule, agree=not why, detail=why or (
                "within the golden scheme (another CPU)" if rule == "golden"
                else "within the bounds between vendors"))
        images.append(row)
    failed = [f"{r.get('variant')} #{int(r.get('repeat', 0)) + 1}: {r['error']}"
              for r in new if r.get("error")]
    return {"agree": bool(images) and all(i["agree"] for i in images) and not failed,
            "images": images, "failed": failed}


def pixels_differ(was: np.ndarray, now: np.ndarray) -> dict[str, Any]:
    """``agree`` when the two RGBA images are bit-identical; else which pixels differ: how
    many, their bounding box, the largest channel difference and the first one's values."""
    d = np.abs(was.astype(np.int16) - now.astype(np.int16)).max(axis=-1)
    ys, xs = np.nonzero(d)
    if not len(ys):
        return {"agree": True, "detail": "bit-identical"}
    y, x = int(ys[0]), int(xs[0])
    box = [int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())]
    return {"agree": False, "pixels": len(ys), "of": int(d.size), "box": box,
            "largest": int(d.max()), "first": [x, y],
            "detail": f"{len(ys)} of {d.size} pixels differ (largest {int(d.max())} levels; "
                      f"x {box[0]}-{box[2]}, y {box[1]}-{box[3]}; first at ({x}, {y}): "
                      f"RGBA {tuple(int(v) for v in was[y, x])} -> "
                      f"{tuple(int(v) for v in now[y, x])})"}


def _rgba(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGBA"))


def _graphs(bundle: Bundle, plan: Any, manifest: dict[str, Any]) -> list[str]:
    """The variants whose graph, built again from the bundle's config and settings by this
    rfw (``manifest``: the replay's own bundle, :func:`rfw.bench.bundle.write_bundle`), is
    not the bundle's (a pass's defaults or slots changed since)."""
    out = []
    for j, job, now in zip(bundle.manifest["jobs"], plan.jobs, manifest["jobs"], strict=True):
        g = j.get("graph") or {}
        if job.kind != "rfw" or not g.get("sha256"):
            continue
        if (now.get("graph") or {}).get("sha256") != g["sha256"]:
            out.append(f"{job.label}: the graph differs from the bundle's ({g.get('member')})")
    return out


def _spirv(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[str]:
    """Per variant, the SPIR-V modules whose hash differs (or that one side has only)."""
    def of(records: list[dict[str, Any]]) -> dict[str, dict[str, str]]:
        out: dict[str, dict[str, str]] = {}
        for r in records:
            if not r.get("error") and isinstance(r.get("spirv"), dict):
                out.setdefault(r["variant"], r["spirv"])
        return out

    a, b = of(old), of(new)
    lines = []
    for label in [k for k in a if k in b]:
        changed = sorted(n for n in a[label].keys() | b[label].keys()
                         if a[label].get(n) != b[label].get(n))
        if changed:
            lines.append(f"{label}: {len(changed)} SPIR-V module(s) differ: "
                         + ", ".join(changed[:4]) + (" ..." if len(changed) > 4 else ""))
    return lines


def _say(verdict: dict[str, Any]) -> None:
    print("images:")
    for i in verdict["images"]:
        mark = "ok  " if i["agree"] else "DIFF"
        print(f"  {mark} {i['variant']} #{int(i['repeat']) + 1} ({i['rule']}): {i['detail']}")
    for line in verdict["failed"]:
        print(f"  FAIL {line}")
    for line in verdict["graphs"]:
        print(f"  graph: {line}")
    for line in verdict["spirv"]:
        print(f"  spirv: {line}")
    was, now = (verdict["rfw"]["bundle"] or {}).get("commit"), verdict["rfw"]["now"]["commit"]
    if was != now:
        print(f"  rfw commit: bundle {was}, replay {now}")
    n = len(verdict["images"])
    bad = sum(1 for i in verdict["images"] if not i["agree"])
    print(f"rfw bench replay: {n - bad} of {n} image(s) agree"
          + (f"; {len(verdict['failed'])} run(s) failed" if verdict["failed"] else ""))


def report(bundle_path: Path, out: Path) -> int:
    """``rfw bench report BUNDLE``: the report written again from the bundle alone, into
    ``out``; 0 when it is byte for byte the bench's (the manifest's sha256), 1 when not."""
    from ..outdir import OutputFolder
    from .report import write_report

    bundle = read_bundle(bundle_path)
    p = bundle.plan
    folder = OutputFolder(out)
    for name in (RESULTS, *REPORT_FILES):
        folder.target(name)
    with folder:
        bundle.extract(folder.staging)
        write_report(folder.staging, reference=p.get("reference"),
                     diff_scale=p.get("diff_scale") or "own")
        digests = {n: sha256((folder.staging / n).read_bytes()) for n in REPORT_FILES}
        folder.commit(last=list(REPORT_FILES))
    recorded = bundle.manifest.get("reports") or {}
    same = True
    for name in REPORT_FILES:
        if name not in recorded:
            verdict = "the bundle records no sha256 of the bench's"
            same = False
        elif recorded[name] == digests[name]:
            verdict = f"byte-identical to the bench's (sha256 {digests[name][:12]})"
        else:
            verdict = (f"DIFFERS from the bench's (sha256 {recorded[name][:12]} -> "
                       f"{digests[name][:12]})")
            same = False
        print(f"wrote {folder.out / name}: {verdict}")
    if not same:
        from .runner import _commit

        then, now = (bundle.manifest.get("rfw") or {}).get("commit"), _commit()[0]
        if then and now and then != now:
            print(f"  the bundle was written by rfw {then[:12]}, this is {now[:12]}: the "
                  "report's code may differ (check out that commit for the same bytes)")
    return 0 if same else 1
