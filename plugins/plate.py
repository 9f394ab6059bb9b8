"""Built-in plugin: the colony-picking plate analysis (paper, section 4.1) as an application."""

from __future__ import annotations

from typing import Any

from labauto.hookspecs import hookimpl


def plate_application(image: Any, params: Any) -> Any:
    """Analyse a plate image: authentic, merged and mixed colonies."""
    from labauto.vision.plate import analyze_plate

    return analyze_plate(image, params)


@hookimpl
def labauto_register_applications(register: Any) -> None:
    register("plate", plate_application)
