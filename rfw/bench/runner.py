"""Run a benchmark matrix: every run in its own process, repeats interleaved across variants.

Order: for each repeat, every job (rfw variants, then peers) once, the order rotated by one
each repeat, so slow drift of the machine (thermal, other load) lands on all jobs alike and no
job always runs first after a cold start.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import platform
import random
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import RfwError, check_identifier, check_number
from ..fileio import inside
from ..graph import GraphError
from .stats import summarize

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
MAX_FRAMES = 100_000  # per run: more is a typo, not a benchmark
MAX_REPEAT = 1_000
MAX_TIMEOUT = 1e6  # seconds per run: 11 days
PEERS_RUN = ROOT / "benchmarks" / "peers" / "run.py"


@dataclass(frozen=True)
class Job:
    """One thing to measure repeatedly: an rfw variant or a peer."""

    kind: str  # "rfw" | "peer"
    label: str
    id: str  # file-system safe
    config: str = ""  # rfw: config path
    sets: tuple[str, ...] = ()  # rfw: every --set of the variant (fixed and varied)
    varied: tuple[str, ...] = ()  # rfw: the --vary choices that name this variant
    scene: str | None = None
    backend: str = "wgpu"
    peer: str = ""


@dataclass
class Plan:
    jobs: list[Job]
    size: tuple[int, int]
    frames: int
    warmup: int
    repeat: int
    order: str = "rotate"
    seed: int = 0
    timeout: float = 600.0
    notes: list[str] = field(default_factory=list)
    peer_frames: int | None = None  # frames of a peer run (default: frames)
    truth: Any = None  # rfw.bench.truth.TruthSpec: first runs write their linear image too

    def schedule(self) -> list[tuple[int, int, Job]]:
        """``(repeat, position, job)`` in run order."""
        out = []
        rng = random.Random(self.seed)
        n = len(self.jobs)
        for r in range(self.repeat):
            if self.order == "shuffle":
                jobs = list(self.jobs)
                rng.shuffle(jobs)
            else:
                k = r % n if n else 0
                jobs = self.jobs[k:] + self.jobs[:k]
            out.extend((r, i, j) for i, j in enumerate(jobs))
        return out


def resolve_config(name: str) -> Path:
    """A config file (relative to the working directory) or a bare name of
    ``configs/<name>.toml``, as an absolute path: the runs happen in other processes."""
    p = Path(name).expanduser()
    if p.is_file():
        return p.resolve()
    candidate = CONFIGS / f"{name}.toml"
    if not p.suffix and candidate.is_file():
        return candidate
    if p.exists():
        raise GraphError("not a file", file=name, element="config")
    known = sorted(c.stem for c in CONFIGS.glob("*.toml"))
    raise GraphError(f"not found (neither a file nor configs/{p.stem}.toml)",
                     file=name, element="config", suggest=(p.stem, known))


def resolve_scene(scene: str | None, *, fetch: bool = False) -> str | None:
    """``None``/``default`` as they are, a scene file as an absolute path (from the working
    directory), a fetched scene's name as its cached GLB (``rfw.scene.names``; fetched first
    with ``fetch``); a missing file or an unknown or unfetched name fails here, before any
    run."""
    if scene is None or scene == "default":
        return scene
    from ..scene import is_builtin, stress_count  # numpy and the loaders: when one is named
    from ..scene.names import resolve_scene as by_name

    scene = by_name(scene, fetch=fetch, element="--scene")  # a fetched scene: its GLB
    if is_builtin(scene) and not Path(scene).exists():  # stress, stress:COUNT, cornell ...
        if scene.startswith("stress"):
            stress_count(scene)  # a bad count fails here, before any run
        return scene
    p = Path(scene).expanduser()
    if not p.is_file():
        raise GraphError("scene file not found" if not p.exists() else "not a scene file",
                       file=scene, element="--scene")
    return str(p.resolve())


def _slug(text: str) -> str:
    """A run folder name (an identifier: no separators, no '..', no leading digit)."""
    keep = "".join(c if c.isalnum() or c in "-_." else "_" for c in text)
    while ".." in keep:
        keep = keep.replace("..", "_")
    keep = keep.strip("_.-")[:80] or "job"
    return check_identifier("run", keep if keep[0].isalpha() else f"v_{keep}")


def _parse_vary(items: list[str]) -> list[tuple[str, list[str]]]:
    axes = []
    for item in items:
        key, eq, values = item.partition("=")
        options = [v.strip() for v in values.split(",") if v.strip()]
        if not eq or not key.strip() or not options:
            raise GraphError(f"expected KEY=V1,V2,..., not '{item}'", element="--vary")
        axes.append((key.strip(), options))
    return axes


def _check(path: Path, sets: list[str]) -> Any:
    """Load ``path`` and apply ``sets`` as a worker will; bad input fails here, naming the
    file, before any process starts."""
    from ..config import apply_overrides, build, load_config

    cfg = apply_overrides(load_config(path), sets)
    build(cfg)
    return cfg


def _accepts(path: Path, key: str, value: str) -> bool:
    try:
        _check(path, [f"{key}={value}"])
    except RfwError:
        return False
    return True


def _inert(cfg: Any, combo: tuple[str, ...]) -> list[str]:
    """The ``--vary`` choices of ``combo`` that set a pass ``cfg`` (the config with the whole
    combo applied) leaves disabled: ``ssao.samples=8`` beside ``ao=off``."""
    disabled = {p.name for p in cfg.passes if not p.enabled}
    return [c for c in combo if "." in c.partition("=")[0]
            and c.partition("=")[0].partition(".")[0] in disabled
            and c.partition("=")[0].split(".")[1] != "enabled"]


def make_plan(configs: list[str], *, scenes: list[str] | None = None,
              size: tuple[int, int] | None = None, frames: int = 10, warmup: int = 2,
              repeat: int = 3, backends: list[str] | None = None, sets: list[str] | None = None,
              vary: list[str] | None = None, peers: list[str] | None = None,
              order: str = "rotate", seed: int = 0, timeout: float = 600.0,
              peer_frames: int | None = None, fetch: bool = False) -> Plan:
    """The jobs of a matrix: configs x scenes x backends x the ``--vary`` axes, then peers.
    ``fetch``: a named scene not cached yet is fetched first (``--fetch``).

    ``CONFIG@BACKEND`` (e.g. ``meshlet@vk``) runs that config on that backend only, whatever
    ``backends`` says (a config may name several: ``deferred@wgpu deferred@vk``).

    A ``--vary`` axis applies to the configs that know its key (``ao=on,off`` to configs with
    an ``ao`` variant); an axis no config knows is an error."""
    if not configs:
        raise GraphError("name at least one config", element="rfw bench")
    frames = check_number(frames, "--frames", kind=int, lo=1, hi=MAX_FRAMES, element="--frames")
    warmup = check_number(warmup, "--warmup", kind=int, lo=0, hi=MAX_FRAMES, element="--warmup")
    repeat = check_number(repeat, "--repeat", kind=int, lo=1, hi=MAX_REPEAT, element="--repeat")
    # a timeout past MAX_TIMEOUT overflows the wait of subprocess.run
    timeout = check_number(timeout, "--timeout", kind=float, lo=1e-3, hi=MAX_TIMEOUT,
                           element="--timeout")
    from ..options import RunOptions
    RunOptions.from_env()  # a bad RFW_* run option: refused once here, not by every run
    if peer_frames is not None:
        peer_frames = check_number(peer_frames, "--peer-frames", kind=int, lo=1, hi=MAX_FRAMES,
                                   element="--peer-frames")
    scenes = list(dict.fromkeys(resolve_scene(s, fetch=fetch) for s in scenes)) \
        if scenes else [None]
    backends = backends or ["wgpu"]
    sets = list(sets or [])
    axes = _parse_vary(list(vary or []))
    # per config the union of its mentions: CONFIG on every --backend, CONFIG@BACKEND on one
    on: dict[Path, list[str]] = {}
    for c in configs:
        name, at, backend = c.rpartition("@") if "@" in c else (c, "", "")
        if at and backend not in ("wgpu", "vk"):
            raise GraphError(f"expected CONFIG@wgpu or CONFIG@vk, not '{c}'", element="config")
        mine = on.setdefault(resolve_config(name), [])
        mine.extend(b for b in ([backend] if at else backends) if b not in mine)
    paths = list(on)
    base = {p: _check(p, sets) for p in paths}  # file errors name the file
    if size is None:
        size = tuple(base[paths[0]].size)  # type: ignore[assignment]
    notes = []
    used = {key: [p for p in paths if _accepts(p, key, opts[0])] for key, opts in axes}
    for key, opts in axes:
        if not used[key]:
            # fail the way --set would, naming the first config's file
            _check(paths[0], [*sets, f"{key}={opts[0]}"])
            raise GraphError(f"no config knows '{key}'", element=f"--vary {key}")
        skipped = [p.stem for p in paths if p not in used[key]]
        if skipped:
            notes.append(f"--vary {key} applies to {', '.join(p.stem for p in used[key])} "
                         f"only ({', '.join(skipped)} have no '{key}')")
    jobs: list[Job] = []
    dropped = 0
    multi_scene = len(scenes) > 1
    for path in paths:
        mine = [(k, opts) for k, opts in axes if path in used[k]]
        for scene, backend in itertools.product(scenes, on[path]):
            for combo in itertools.product(*[[f"{k}={o}" for o in opts] for k, opts in mine]):
                run_sets = [*sets, *combo]
                inert: list[str] = []
                if combo:
                    # a choice setting a pass the others disable changes nothing: that
                    # variant is the one without it (ao=off with any ssao.samples)
                    inert = _inert(_check(path, run_sets), combo)
                    if inert:
                        combo = tuple(c for c in combo if c not in inert)
                        run_sets = [*sets, *combo]
                label = path.stem + (f"[{','.join(combo)}]" if combo else "") + f"@{backend}"
                if multi_scene:
                    label += f" {Path(scene).stem if scene else 'default'}"
                if inert and any(j.label == label for j in jobs):
                    dropped += 1  # the same run as one listed already
                    continue
                jobs.append(Job("rfw", label, _slug(label), str(path), tuple(run_sets),
                                tuple(combo), scene, backend))
    if dropped:
        notes.append(f"{dropped} combination(s) of --vary set a pass their other choices "
                     "disable: each runs once, as the variant without that setting")
    for peer in peers or []:
        jobs.append(Job("peer", f"peer:{peer}", _slug(f"peer_{peer}"), peer=peer,
                        scene=scenes[0]))
    ids = [j.id for j in jobs]
    if len(set(ids)) != len(ids):
        raise GraphError("two jobs of the matrix are the same (repeated config?)",
                         element="rfw bench")
    return Plan(jobs, size, frames, warmup, repeat, order, seed, timeout,  # type: ignore[arg-type]
                notes, peer_frames)


def environment() -> dict[str, Any]:
    """The rfw commit, the host's CPU and the GPU clocks before any run; the device comes
    per run.

    The commit is ``RFW_COMMIT`` when set (a copy without git metadata, or with stale
    metadata, as on a GPU machine the sources were carried to), else git's ``HEAD`` with a
    ``+dirty`` mark; ``rfw_commit_source`` says which."""
    commit, source = _commit()
    clocks = gpu_clocks()
    return {"rfw_commit": commit, "rfw_commit_source": source,
            "host": platform.node(), "machine": platform.machine(),
            "cpu": _cpu_name(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "gpu_clocks_start": clocks,
            **({} if clocks else {"gpu_clocks_note": NO_CLOCKS})}


NO_CLOCKS = "not reported: no nvidia-smi on this machine (a CPU driver such as lavapipe " \
            "has no GPU clocks)"


def _commit() -> tuple[str, str]:
    """``(commit, where it came from)``: ``RFW_COMMIT``, ``git`` or ``none``."""
    from ..env import get

    given = get("RFW_COMMIT")  # one word, as a hash or a describe string is (rfw.env)
    if given is not None:
        return given, "RFW_COMMIT"

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  check=False, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    commit = git("rev-parse", "HEAD")
    if not commit:
        return "unknown", "none"
    dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    return commit + ("+dirty" if dirty else ""), "git"


CLOCK_FIELDS = ("index", "name", "clocks.sm", "clocks.mem", "clocks.max.sm", "clocks.max.mem")


def gpu_clocks(*, smi: str = "nvidia-smi") -> list[dict[str, Any]] | None:
    """The current and maximum SM and memory clocks (MHz) of every GPU nvidia-smi lists, or
    None where there is no nvidia-smi (lavapipe, other vendors) or it answers nothing usable.
    """
    exe = shutil.which(smi)
    if exe is None:
        return None
    try:
        done = subprocess.run([exe, f"--query-gpu={','.join(CLOCK_FIELDS)}",
                               "--format=csv,noheader,nounits"], capture_output=True,
                              text=True, check=False, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    return parse_clocks(done.stdout) if done.returncode == 0 else None


def parse_clocks(text: str) -> list[dict[str, Any]] | None:
    """nvidia-smi's ``csv,noheader,nounits`` answer to ``CLOCK_FIELDS`` as one dict per GPU
    (MHz as int; ``[N/A]`` as None); None when a line does not have those fields."""
    gpus = []
    for line in text.strip().splitlines():
        cells = [c.strip() for c in line.split(",")]
        if len(cells) != len(CLOCK_FIELDS) or not cells[0].isdigit():
            return None
        mhz = [int(c) if c.isdigit() else None for c in cells[2:]]
        gpus.append({"index": int(cells[0]), "name": cells[1], "sm_mhz": mhz[0],
                     "mem_mhz": mhz[1], "max_sm_mhz": mhz[2], "max_mem_mhz": mhz[3]})
    return gpus or None


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _command(job: Job, plan: Plan, out: Path, *, truth: str | None = None) -> list[str]:
    w, h = plan.size
    if job.kind == "peer":
        return [sys.executable, str(PEERS_RUN), job.peer, "--scene", job.scene or "default",
                "--size", f"{w}x{h}", "--frames", str(plan.peer_frames or plan.frames),
                "--warmup", str(plan.warmup), "--out", str(out)]
    # -P: the working directory is the user's, and a folder there named rfw must not win
    cmd = [sys.executable, "-P", "-m", "rfw.bench.worker", "--config", job.config, "--size",
           f"{w}x{h}", "--frames", str(plan.frames), "--warmup", str(max(1, plan.warmup)),
           "--backend", job.backend, "--out", str(out)]
    if job.scene:
        cmd += ["--scene", job.scene]
    for s in job.sets:
        cmd += ["--set", s]
    if truth:
        cmd += ["--truth", truth]
    return cmd


def clear_run_files(folder: Path) -> None:
    """Delete a run folder's record, image and log, so a failed run shows no old image."""
    for stale in ("record.json", "image.png", "log.txt", "hdr.exr", "display.png"):
        (folder / stale).unlink(missing_ok=True)


def run_one(job: Job, plan: Plan, out: Path, *, cwd: str | None = None,
            env: dict[str, str] | None = None, truth: str | None = None) -> dict[str, Any]:
    """Run one job in a fresh process, in the caller's working directory (relative paths in
    ``--set`` mean what they mean to ``rfw run``) or ``cwd``, with this process's environment
    plus ``env``; its record (``error`` set when it failed). ``truth``: the run also writes
    the image that component of ``--reference pathtrace`` judges (``hdr.exr``)."""
    out.mkdir(parents=True, exist_ok=True)
    clear_run_files(out)
    t = time.perf_counter()
    env = worker_env(env)
    try:
        done = _worker(_command(job, plan, out, truth=truth), timeout=plan.timeout, env=env,
                       cwd=cwd)
    except subprocess.TimeoutExpired:
        (out / "image.png").unlink(missing_ok=True)
        return {"error": f"timed out after {plan.timeout:g} s",
                "elapsed_s": time.perf_counter() - t}
    elapsed = time.perf_counter() - t
    (out / "log.txt").write_text(done.stdout + done.stderr)
    record = _read_record(out / "record.json")
    if record is None:
        tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
        record = {"error": f"exit {done.returncode}: {tail}"}
    elif done.returncode and not record.get("error"):
        record = {"error": f"exit {done.returncode} after writing its record"}
    record["elapsed_s"] = elapsed
    return record


def worker_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The environment a worker process starts with: this process's, plus ``extra``, with
    this tree first on PYTHONPATH (the worker imports the rfw that started it)."""
    return {**os.environ, **(extra or {}), "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])])}


def _worker(cmd: list[str], *, timeout: float, env: dict[str, str],
            cwd: str | None) -> subprocess.CompletedProcess:
    """``subprocess.run`` for a bench worker that a signal cannot orphan: SIGINT and SIGTERM
    wait while it is started (CPython does not end a child whose ``Popen`` a signal broke
    off after the fork), and anything that stops the wait, a signal too, kills it."""
    from ..outdir import signals_held

    def unblock() -> None:  # the worker itself takes signals again
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})

    with signals_held():
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env, cwd=cwd, preexec_fn=unblock)
    with proc:
        try:
            stdout, stderr = proc.communicate(timeout=timeout)
        except BaseException:
            proc.kill()
            proc.wait()
            raise
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)


def _read_record(path: Path) -> dict[str, Any] | None:
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # missing or cut short: the process output says why
    return record if isinstance(record, dict) else None


def pass_stats(record: dict[str, Any]) -> None:
    """Add per-pass and per-frame summaries of this one run to ``record`` (in place)."""
    for p in record.get("passes", []):
        p["stats"] = {"gpu_ms": summarize(p["gpu_ms"]), "cpu_ms": summarize(p["cpu_ms"])}
    frame = record.get("frame")
    if frame:
        record["frame_stats"] = {k: summarize(v) for k, v in frame.items()}
    if "frame_ms" in record:  # peers
        record["frame_stats"] = {"frame_ms": summarize(record["frame_ms"])}
        if record.get("gpu_ms"):
            record["frame_stats"]["gpu_ms"] = summarize(record["gpu_ms"])




def _local_runs(schedule: list[tuple[int, int, Job]], plan: Plan, out_dir: Path):
    """``(seq, run folder, record)`` of each scheduled run, one process after another."""
    for seq, (r, _, job) in enumerate(schedule):
        run_dir = inside(out_dir, Path("runs") / job.id / f"r{r}")
        # against the truth: each rfw variant's first run writes its linear image too
        truth = plan.truth.component if plan.truth is not None and job.kind == "rfw" \
            and r == 0 else None
        yield seq, run_dir, run_one(job, plan, run_dir, truth=truth)


def run_plan(plan: Plan, out_dir: Path, *, progress: bool = True,
             executor: Callable[..., Iterator[tuple[int, Path, dict]]] | None = None) -> Path:
    """Run every job of ``plan``; appends one JSON line per run to ``out_dir/results.jsonl``
    (written afresh) and returns its path.

    ``executor(schedule, plan, out_dir)`` yields ``(seq, run folder, record)`` per run;
    None runs one process after another here. ``rfw bench --executor ray`` passes
    :func:`rfw.bench.ray_executor.ray_runs` (Ray tasks, one per GPU). Records are written
    in schedule order either way."""
    env = environment()  # a bad RFW_COMMIT fails here, before any folder or run
    schedule = plan.schedule()
    # Ray connects (or starts) now: a bad address fails before any folder or run
    runs = (executor or _local_runs)(schedule, plan, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = out_dir / "results.jsonl"
    meta = {"size": list(plan.size), "frames": plan.frames, "warmup": plan.warmup,
            "peer_frames": plan.peer_frames or plan.frames,
            "repeats": plan.repeat, "order": plan.order, "notes": plan.notes}
    bar = None
    if progress and sys.stderr.isatty():  # a log (CI) gets one line per run instead
        try:
            from tqdm import tqdm

            bar = tqdm(total=len(schedule), unit="run", desc="rfw bench", file=sys.stderr,
                       dynamic_ncols=True)
        except ImportError:
            bar = None
    with open(results, "wb") as f, contextlib.closing(runs):  # an executor's finally runs
        for seq, run_dir, record in runs:
            r, pos, job = schedule[seq]
            if bar is not None:
                bar.set_postfix_str(f"{job.label} #{r + 1}", refresh=True)
            pass_stats(record)
            if job.kind == "peer":
                record["peer_kind"] = record.get("kind")
            image = run_dir / "image.png"
            if record.get("error"):
                image.unlink(missing_ok=True)
            record.update({
                "kind": job.kind, "variant": job.label, "variant_id": job.id, "repeat": r,
                "sequence": seq, "position": pos, **env, **meta,
                "config_path": job.config or None, "settings": list(job.sets),
                "varied": list(job.varied), "scene_arg": job.scene,
                "requested_backend": job.backend
                if job.kind == "rfw" else None,
                "image": str(image.relative_to(out_dir)) if image.exists() else None,
                "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
            if job.kind == "peer":
                record["peer"] = job.peer
            judged = record.get("hdr")
            if isinstance(judged, dict):  # --reference pathtrace: the files, from out_dir
                for key in ("file", "display"):
                    path = run_dir / str(judged.get(key, ""))
                    if key in judged:
                        judged[key] = str(path.relative_to(out_dir)) if path.is_file() else None
            _write_line(f, json.dumps(record) + "\n")
            if bar is not None:
                bar.update(1)
            elif progress:
                print(f"[{seq + 1}/{len(schedule)}] {job.label} #{r + 1}: "
                      f"{record.get('error') or 'ok'}", file=sys.stderr)
    if bar is not None:
        bar.close()
    return results


def _write_line(f: Any, line: str) -> None:
    # a record is one write of its whole line, past Python's buffer: a reader (or an
    # interrupted bench) never sees half of it
    data = memoryview(line.encode("utf-8"))
    f.flush()
    while data:
        data = data[os.write(f.fileno(), data):]


def load_results(path: Path) -> list[dict[str, Any]]:
    """The records of a ``results.jsonl`` (or of the one in a folder), each checked by
    :func:`rfw.bench.records.read_results`: a line cut short, not JSON, or holding a time
    that is not a finite number of ms fails naming the file, the line and the field."""
    from .records import read_results

    path = Path(path)
    if path.is_dir():
        path = path / "results.jsonl"
    if not path.exists():
        raise GraphError("no results.jsonl here (run rfw bench first)", file=str(path))
    if not path.is_file():  # a FIFO would block the read, a device never end
        raise RfwError("not a regular file", file=str(path))
    return read_results(path)
