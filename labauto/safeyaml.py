"""Reading small YAML files that a user hands to labauto (configs, register maps), safely.

``yaml.safe_load`` is safe against code execution but not against a file that is too big (or
never ends, like ``/dev/zero``), alias bombs (a few hundred bytes that expand to gigabytes), or
nesting deep enough to exhaust the interpreter's stack. :func:`read_yaml_file` refuses each of
them with one line naming the file and the problem:

* only regular files are read (not devices, FIFOs or folders), at most ``max_bytes``;
* aliases (``*name``) are refused, so nothing can expand;
* nesting deeper than ``max_depth`` is refused.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

MAX_BYTES = 1 << 20
"""Largest file read (1 MiB: a config or register map is a few kilobytes)."""

MAX_DEPTH = 32
"""Deepest nesting of mappings and lists accepted."""


class YamlRefused(ValueError):
    """A YAML file that is not read: its message names the file and what is wrong."""


class _GuardedLoader(yaml.SafeLoader):
    """A SafeLoader that refuses aliases and deep nesting while it composes the document."""

    max_depth = MAX_DEPTH

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise YamlRefused(
                f"line {mark.line + 1}: YAML aliases (*name) are not accepted; write the value out"
            )
        self._depth += 1
        try:
            if self._depth > self.max_depth:
                mark = self.peek_event().start_mark
                raise YamlRefused(
                    f"line {mark.line + 1}: nested deeper than {self.max_depth} levels"
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def read_text_limited(path: str | Path, max_bytes: int = MAX_BYTES, what: str = "file") -> str:
    """Read a regular UTF-8 text file of at most ``max_bytes``.

    Raises
    ------
    FileNotFoundError
        No such file.
    YamlRefused
        Not a regular file, too large, or not UTF-8.
    OSError
        Any other read error.
    """
    path = Path(path)
    info = os.stat(path)
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "a device, FIFO or socket"
        raise YamlRefused(f"{path}: is {kind}, expected a regular {what}")
    with open(path, "rb") as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise YamlRefused(f"{path}: {what} is larger than {max_bytes // 1024} KiB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlRefused(f"{path}: {what} is not UTF-8 text (byte {exc.start})") from None


def load_yaml(text: str, source: str = "<yaml>") -> Any:
    """Parse YAML text with the guards of this module.

    Raises
    ------
    YamlRefused
        Aliases or too deep nesting (the message names ``source`` and the line).
    yaml.YAMLError
        Not valid YAML.
    """
    loader = _GuardedLoader(text)
    try:
        return loader.get_single_data()
    except YamlRefused as exc:
        raise YamlRefused(f"{source}: {exc}") from None
    except RecursionError:
        raise YamlRefused(f"{source}: nested too deeply") from None
    finally:
        loader.dispose()


def read_yaml_file(path: str | Path, max_bytes: int = MAX_BYTES, what: str = "file") -> Any:
    """Read and parse a YAML file with every guard of this module (see its docstring)."""
    return load_yaml(read_text_limited(path, max_bytes, what), str(path))
