"""``python -m rfw.meshlet_view ARGS``: ``rfw meshlets show ARGS``. The entry sits on top of
:mod:`rfw.cli`, where the arguments live with the other commands (it imports no numpy), so
the viewer itself never imports the CLI back."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from rfw.cli import main as rfw_main


def main(argv: Sequence[str] | None = None) -> int:
    return rfw_main(["meshlets", "show", *(argv if argv is not None else sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
