"""``rfw scenes``: list the scenes or fetch them."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .cache import default_cache, fetch, list_scenes
from .download import FetchError


def cmd_scenes(args: argparse.Namespace) -> int:
    cache = Path(args.cache).expanduser() if args.cache else default_cache()
    if args.list:
        sys.stdout.write(list_scenes(cache))
        return 0

    def report(line: str) -> None:
        stream = sys.stderr if line.startswith("rfw: error:") else sys.stdout
        print(line, file=stream, flush=True)

    try:
        results = fetch(args.names, cache, force=args.force, report=report)
    except FetchError as e:
        print(f"rfw: error: {e}", file=sys.stderr)
        return 2
    return 2 if any(isinstance(r, FetchError) for r in results) else 0
