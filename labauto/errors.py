"""Errors that labauto reports to its users.

Each carries a one-line message that names what was wrong (the file, the key, the value); the CLI
prints it as ``labauto: error: <message>`` and exits non-zero.
"""

from __future__ import annotations


class LabautoError(Exception):
    """Base class of the errors labauto reports to the operator."""


class ConfigError(LabautoError):
    """A config file or environment override is invalid."""


class ImageError(LabautoError, ValueError):
    """An image is missing, unreadable, empty or of the wrong shape."""


class PluginError(LabautoError):
    """A plugin or a registered component is missing or invalid."""


class CalibrationError(LabautoError):
    """A pixel-to-deck calibration cannot be computed or is not precise enough."""


class RunError(LabautoError):
    """A run cannot be started, resumed or continued."""
