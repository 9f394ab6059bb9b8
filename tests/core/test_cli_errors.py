"""Every command ends in one line, ``labauto: error: ...``, whatever it raises (issue 12.10).

A throw-away subcommand raising each kind of exception is added to the real ``labauto`` group
for the test; ``main`` must turn each into one line and exit status 1 (``--debug`` re-raises).
"""

from __future__ import annotations

import click
import cv2
import numpy as np
import pytest

from labauto.cli.main import cli, main


def _cv2_error() -> BaseException:
    try:
        cv2.GaussianBlur(np.zeros((4, 4), np.uint8), (4, 4), 0)  # even kernel: cv2.error
    except cv2.error as exc:
        return exc
    raise AssertionError("OpenCV accepted an even kernel")


RAISED = {
    "cv2.error": (_cv2_error, "labauto: error: cv2.error: "),
    "RecursionError": (lambda: RecursionError("maximum recursion depth exceeded"),
                       "labauto: error: RecursionError: maximum recursion depth exceeded"),
    "MemoryError": (lambda: MemoryError(), "labauto: error: MemoryError: (no message)"),
    "OverflowError": (lambda: OverflowError("Python int too large to convert to SQLite INTEGER"),
                      "labauto: error: OverflowError: Python int too large"),
    "KeyError": (lambda: KeyError("x"), "labauto: error: KeyError: 'x'"),
}  # fmt: skip


@pytest.fixture()
def raising_command():
    holder: dict[str, BaseException] = {}

    @click.command("raise-for-test")
    def command() -> None:
        raise holder["exc"]

    cli.add_command(command)
    try:
        yield holder
    finally:
        cli.commands.pop("raise-for-test", None)


@pytest.mark.parametrize("name", list(RAISED))
def test_any_exception_ends_in_one_line(raising_command, capsys, name):
    make, expected = RAISED[name]
    raising_command["exc"] = make()
    assert main(["raise-for-test"]) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith(expected), lines[0]
    assert lines[0].endswith("(labauto --debug shows the traceback)")


def test_debug_shows_the_traceback_instead(raising_command):
    raising_command["exc"] = OverflowError("too big")
    with pytest.raises(OverflowError, match="too big"):
        main(["--debug", "raise-for-test"])
