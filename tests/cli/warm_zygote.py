"""The process that tests/cli/warm.py forks ``python -m rfw.cli`` children from.

Started once per test process, it imports what every ``rfw`` process imports first (numpy,
wgpu's native backend, whose cffi header parse is a quarter of a second, and rfw's command
line) and then waits. Each request (one JSON line on stdin: argv, cwd, env, two file names,
safe_path) is served by a forked child that becomes what ``python -m rfw.cli ARGV`` would
be there: that working folder, that environment, that folder first on ``sys.path`` (not
with ``safe_path``: ``python -P``) and the environment's PYTHONPATH after it, stdin from
/dev/null, stdout and stderr into the two files; then it runs ``rfw.cli`` as ``__main__``
and exits as such a process does (its exit code, a traceback and exit 1 for an uncaught
exception, atexit handlers run). The zygote answers with the child's pid at once and, when
it has ended, its exit status.

Not for tests of what happens at start-up (signals during imports, import errors): only
what ``main()`` does differs in nothing.
"""

import contextlib
import json
import os
import sys

# the zygote's sys.path after its own folder (its PYTHONPATH: this tree; the standard
# library, site-packages): a child's after its working folder and its own PYTHONPATH
BASE = sys.path[1:]


def preload() -> None:
    import numpy  # noqa: F401

    # a child that needs it and cannot import it fails as a fresh process would
    with contextlib.suppress(Exception):
        import wgpu.backends.wgpu_native  # noqa: F401
    import rfw
    import rfw.cli

    # what rfw.cli imported stays; the module itself runs as __main__, as under ``-m``
    # (where nothing imported it before)
    del sys.modules["rfw.cli"], rfw.cli


def become(req: dict) -> None:
    """Turn this (forked) process into ``python -m rfw.cli ARGV`` as ``req`` describes."""
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    for fd, path in ((1, req["stdout"]), (2, req["stderr"])):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(f, fd)
        os.close(f)
    os.close(null)
    os.chdir(req["cwd"])
    os.environ.clear()
    os.environ.update(req["env"])
    sys.dont_write_bytecode = bool(req["env"].get("PYTHONDONTWRITEBYTECODE"))
    extra = [p for p in req["env"].get("PYTHONPATH", "").split(os.pathsep) if p]
    # ``python -P`` (a console script's start) puts no working folder first
    sys.path[:] = [*([] if req.get("safe_path") else [os.getcwd()]), *extra, *BASE]
    sys.argv = ["-m", *req["argv"]]


def serve() -> dict:
    """Answer requests until stdin closes (then exit); in a child, return its request."""
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    while line := sys.stdin.readline():  # one request at a time: nothing is read ahead
        req = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            reply.close()
            return req
        reply.write(json.dumps({"pid": pid}) + "\n")
        _, status = os.waitpid(pid, 0)
        reply.write(json.dumps({"status": os.waitstatus_to_exitcode(status)}) + "\n")
    sys.exit(0)


if __name__ == "__main__":
    preload()
    print('"ready"', flush=True)
    become(serve())
    import runpy

    runpy.run_module("rfw.cli", run_name="__main__", alter_sys=True)
