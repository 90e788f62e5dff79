"""``rfw bench --executor ray``: the matrix's runs as Ray tasks, one per GPU.

Each scheduled run becomes one task that asks Ray for one GPU (``num_gpus=1``) where the
cluster has GPUs, else for one CPU (a CPU-only machine with lavapipe, as the tests run it).
A task runs the usual worker process (:func:`rfw.bench.runner.run_one`) in a scratch folder of
its node and returns the record, image and log, which are written under ``--out`` here: the
nodes need the same rfw install and the same config and scene paths, not a shared disk.
Every record notes where it ran (``ray``: node, host, GPU ids), which the report's device
column and per-device tables read. Where Ray gives a task a GPU, the task finds that GPU's
UUID (:mod:`rfw.bench.gpus`) and the worker opens the device by it (``RFW_GPU=uuid:...``);
the record notes the UUID asked for and the one each backend rendered on, and a run on
another device is an error (docs/multi-gpu.md).

Without ``--ray-address`` a local Ray instance is started and stopped by rfw; with one, the
tasks go to that cluster (``auto``, ``ray://HOST:10001`` or ``HOST:6379``), which is left
running.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..backend import GPU_ENV, UUID_PREFIX
from ..errors import RfwError
from ..fileio import atomic_write, inside
from .gpus import uuid_of_gpu
from .runner import ROOT, Job, Plan, clear_run_files, run_one

INSTALL = "pip install 'rfw[scale]' (or: pip install ray)"


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise RfwError(f"--executor ray needs Ray, which is not installed: {INSTALL}",
                       element="--executor") from None
    return ray


CONNECT_TIMEOUT_S = 5.0  # Ray itself retries a dead address for minutes


def check_address(address: str) -> None:
    """Refuse an address nothing answers at, in seconds (``auto`` is left to Ray)."""
    if address == "auto":
        return
    hostport = address.removeprefix("ray://")
    host, colon, port = hostport.rpartition(":")
    if not colon or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise RfwError(f"expected auto, HOST:PORT or ray://HOST:PORT, not {address!r}",
                       element="--ray-address")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S
                                 ).close()
    except OSError as e:
        raise RfwError(f"nothing answers at {hostport} ({e.strerror or type(e).__name__})",
                       element="--ray-address") from None


def run_task(job: Job, plan: Plan, cwd: str) -> dict[str, Any]:
    """One run on whichever node Ray picked: the record, the image's bytes and the log."""
    import ray

    scratch = Path(tempfile.mkdtemp(prefix="rfw-bench-"))
    gpus = [str(g) for g in ray.get_gpu_ids()]
    where: dict[str, Any] = {"gpu_ids": gpus}
    env = None
    if gpus:  # the worker opens the GPU Ray gave this task, by its UUID
        uuid, source = uuid_of_gpu(gpus[0])
        where.update(uuid_asked=uuid, uuid_source=source)
        env = {GPU_ENV: f"{UUID_PREFIX}{uuid}"} if uuid else None
    try:
        if gpus and env is None:  # no guessing which Vulkan device Ray's GPU is
            record: dict[str, Any] = {"error": f"ray gave GPU {gpus[0]}, and {source}"}
        else:
            record = run_one(job, plan, scratch, cwd=cwd if os.path.isdir(cwd) else None,
                             env=env)
        image, log = scratch / "image.png", scratch / "log.txt"
        ctx = ray.get_runtime_context()
        record["executor"] = "ray"
        record["ray"] = {"node": ctx.get_node_id(), "host": socket.gethostname(), **where}
        if gpus and not record.get("error"):
            check_device(record)
        return {"record": record,
                "image": image.read_bytes() if image.is_file() else None,
                "log": log.read_text(errors="replace") if log.is_file() else ""}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def check_device(record: dict[str, Any]) -> None:
    """Note in ``record["ray"]`` the UUID each backend rendered on, and make a run whose
    device is not the GPU Ray gave it an error: a backend that reports no UUID (wgpu) is
    noted as unchecked, with the UUID it was picked by."""
    where = record["ray"]
    asked = where.get("uuid_asked")
    ids = record.get("device_ids") or {}
    where["uuid_rendered"] = {name: d.get("uuid") for name, d in ids.items()}
    unchecked = [name for name, d in ids.items() if d.get("uuid") is None]
    if unchecked:
        where["unchecked"] = {name: ids[name].get("uuid_note", "no UUID") for name in unchecked}
    wrong = {name: d["uuid"] for name, d in ids.items() if d.get("uuid") not in (None, asked)}
    if not ids:
        wrong = {"?": "nothing"}  # a worker that recorded no device ids proves nothing
    if wrong:
        got = ", ".join(f"{name} on {u}" for name, u in wrong.items())
        record["error"] = (f"rendered on another device than Ray's GPU "
                           f"{where['gpu_ids'][0]} (UUID {asked}): {got}")


def ray_runs(schedule: list[tuple[int, int, Job]], plan: Plan, out_dir: Path, *,
             address: str | None = None) -> Iterator[tuple[int, Path, dict[str, Any]]]:
    """Connect to (or start) Ray now, so a missing Ray or a bad address fails before any run;
    the returned iterator submits every run at once and yields ``(seq, run folder, record)``
    in schedule order as the runs finish, then disconnects (and stops a local instance).
    ``address`` is probed by the caller first (:func:`check_address`, as ``rfw bench`` does
    before its header): Ray itself retries a dead one for minutes."""
    ray = _import_ray()
    start_local = not address
    try:
        if start_local:
            # "local": a fresh instance even where RAY_ADDRESS names another
            ray.init(address="local", include_dashboard=False, log_to_driver=False,
                     logging_level="ERROR",
                     runtime_env={"env_vars": {"PYTHONPATH": str(ROOT)}})
        else:
            ray.init(address=address, log_to_driver=False, logging_level="ERROR")
    except Exception as e:  # ConnectionError, ValueError, RuntimeError: all mean the address
        message = " ".join(str(e).split())[:200] or type(e).__name__
        raise RfwError(f"could not {'start' if start_local else 'connect to'} Ray: {message}",
                       element=f"--ray-address {address}" if address else "--executor ray"
                       ) from None
    return _runs(ray, schedule, plan, out_dir)


def _runs(ray: Any, schedule: list[tuple[int, int, Job]], plan: Plan,
          out_dir: Path) -> Iterator[tuple[int, Path, dict[str, Any]]]:
    refs: list[Any] = []
    finished = 0
    try:
        gpus = ray.cluster_resources().get("GPU", 0)
        # one GPU per task where there are GPUs; on a CPU-only cluster one CPU per task
        resources = {"num_gpus": 1, "num_cpus": 0} if gpus else {"num_cpus": 1}
        task = ray.remote(max_retries=0, **resources)(run_task)
        cwd = os.getcwd()
        refs = [task.remote(job, plan, cwd) for _, _, job in schedule]
        # what the report's "How this was measured" says about the runs in flight
        cluster = {"gpus": gpus, "cpus": ray.cluster_resources().get("CPU", 0),
                   "submitted": len(refs)}
        for seq, ref in enumerate(refs):  # schedule order: the report's order stays the same
            r, _, job = schedule[seq]
            run_dir = inside(out_dir, Path("runs") / job.id / f"r{r}")
            run_dir.mkdir(parents=True, exist_ok=True)
            clear_run_files(run_dir)
            try:
                done = ray.get(ref)
            except Exception as e:  # the task itself died (node lost, worker killed)
                why = " ".join(str(e).split())[:300] or type(e).__name__
                yield seq, run_dir, {"error": f"ray task failed: {why}", "executor": "ray"}
                continue
            (run_dir / "log.txt").write_text(done["log"])
            if done["image"] is not None:
                data = done["image"]
                atomic_write(run_dir / "image.png", lambda f, data=data: f.write(data))
            done["record"]["ray_cluster"] = cluster
            yield seq, run_dir, done["record"]
            finished = seq + 1
    finally:
        # an interrupted bench: its tasks still queued or running on a cluster are ended too
        for ref in refs[finished:]:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        ray.shutdown()  # stops the instance rfw started; only disconnects from a cluster
