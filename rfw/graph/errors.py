"""Graph errors: one clear line naming the file, the pass and the slot."""

from __future__ import annotations

from ..errors import RfwError, close_matches, did_you_mean

__all__ = ["GraphError", "close_matches", "did_you_mean"]


class GraphError(RfwError):
    """A graph or config that cannot be loaded or compiled (see ``rfw.errors.RfwError``)."""
