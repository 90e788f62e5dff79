"""Graph errors: one clear line naming the file, the pass and the slot."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def close_matches(word: str, choices: Iterable[str], n: int = 3) -> list[str]:
    return difflib.get_close_matches(word, list(choices), n=n, cutoff=0.6)


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    found = close_matches(word, choices)
    if not found:
        return ""
    return " (did you mean " + " or ".join(f"'{m}'" for m in found) + "?)"


class GraphError(ValueError):
    """A graph that cannot be loaded or compiled. ``str()`` is one line; ``more`` holds the
    other problems found in the same run."""

    def __init__(self, message: str, *, file: str | None = None,
                 suggest: tuple[str, Iterable[str]] | None = None,
                 more: Iterable[str] = ()):
        if suggest is not None:
            message += did_you_mean(*suggest)
        message = message.replace("\n", "\\n")  # one line, whatever names contain
        self.message = message
        self.file = file
        self.more = list(more)
        super().__init__(self.line())

    def line(self) -> str:
        extra = f" (and {len(self.more)} more problem{'s' * (len(self.more) > 1)})" \
            if self.more else ""
        return (f"{self.file}: " if self.file else "") + self.message + extra

    def in_file(self, file: str | None) -> GraphError:
        if file and not self.file:
            self.file = file
            self.args = (self.line(),)
        return self
