"""G-code words for the simulated gantry: comments, words, modal groups, GRBL's error codes."""

from __future__ import annotations

import re

__all__ = ["G_GROUPS", "GcodeError", "parse_words", "strip_comments"]

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))?")


class GcodeError(Exception):
    """A block GRBL rejects with ``error:code``."""

    def __init__(self, code: int) -> None:
        super().__init__(f"error:{code}")
        self.code = code


#: The G-codes the simulator knows, by modal group (two of one group in a block: error:21).
G_GROUPS: dict[float, str] = {
    0: "motion", 1: "motion", 80: "motion", 4: "nonmodal", 10: "nonmodal", 53: "nonmodal",
    17: "plane", 20: "units", 21: "units", 90: "distance", 91: "distance",
    94: "feedmode", 54: "wcs",
}  # fmt: skip


def strip_comments(line: str) -> str:
    """Drop ``;`` comments and ``(...)`` comments, as GRBL does."""
    line = line.split(";", 1)[0]
    return re.sub(r"\([^)]*\)", "", line).strip()


def parse_words(line: str) -> list[tuple[str, float]]:
    """Split an upper-case, space-free block into ``(letter, value)`` words.

    Raises
    ------
    GcodeError
        1 for a character that is not a letter, 2 for a letter without a number.
    """
    words: list[tuple[str, float]] = []
    position = 0
    while position < len(line):
        match = _WORD.match(line, position)
        if not match:
            raise GcodeError(1)
        if match.group(2) is None:
            raise GcodeError(2)
        words.append((match.group(1), float(match.group(2))))
        position = match.end()
    return words
