"""``labauto detect`` and ``labauto plate``: analyse one image and print the result."""

from __future__ import annotations

import json

import click

from labauto.cli.options import config_option
from labauto.config import Config, detector_params, plate_params
from labauto.plugin_manager import load_plugins


def _echo_json(document: dict) -> None:
    click.echo(json.dumps(document, indent=2))


@click.command("detect")
@click.argument("image", type=click.Path(dir_okay=False))
@click.option("--method", default=None, help="Segmenter: canny (default), color, or a plugin's.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@config_option
def detect_cmd(image: str, method: str | None, as_json: bool, config: Config) -> None:
    """Detect objects and deformed elliptic shapes (DES) in IMAGE."""
    from labauto.api import detect

    plugins = load_plugins(config.plugins.enabled, config.plugins.disabled)
    params = {k: v for k, v in vars(detector_params(config)).items() if k != "method"}
    result = detect(image, method or config.segmenter, plugins=plugins, **params)
    if as_json:
        _echo_json(result.to_dict())
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{image}: {len(result.objects)} objects, {result.timing_ms:.1f} ms")
    for column in ("id", "centroid", "points", "D_alpha med", "inside", "DES", "shape", "ellipse"):
        table.add_column(column)
    for obj in result.objects:
        ellipse = obj.ellipse
        table.add_row(
            str(obj.id),
            f"{obj.centroid[0]:.1f}, {obj.centroid[1]:.1f}",
            str(obj.n_points),
            f"{obj.d_alpha_median:.1f}",
            "yes" if obj.centroid_inside else "no",
            "yes" if obj.is_des else "no",
            obj.shape,
            ""
            if ellipse is None
            else f"a={ellipse.axes[0]:.1f} b={ellipse.axes[1]:.1f} {ellipse.angle:.0f} deg",
        )
    Console().print(table)


@click.command("plate")
@click.argument("image", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option(
    "--annotate",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write an annotated image (authentic, merged, mixed marked) to this file.",
)
@config_option
def plate_cmd(image: str, as_json: bool, annotate: str | None, config: Config) -> None:
    """Find and classify the colonies on the petri dish in IMAGE."""
    from labauto.api import analyze_plate
    from labauto.imageio import check_image_target, read_image, write_image

    if annotate:
        check_image_target(annotate)  # before the work, not after it
    plugins = load_plugins(config.plugins.enabled, config.plugins.disabled)
    pixels = read_image(image)
    result = analyze_plate(pixels, plugins=plugins, **vars(plate_params(config)))
    if annotate:
        from labauto.report import annotate_plate

        write_image(annotate, annotate_plate(pixels, result))
    if as_json:
        _echo_json(result.to_dict())
        return
    counts = result.counts
    click.echo(
        f"{image}: {counts['authentic']} authentic, {counts['merged']} merged, "
        f"{counts['mixed']} mixed; about {counts['colonies_estimate']} colonies "
        f"({result.timing_ms:.1f} ms)"
    )
