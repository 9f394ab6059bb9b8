"""``labauto markers board`` and ``labauto markers detect``: coded markers (paper, 4.2)."""

from __future__ import annotations

import json

import click


@click.group("markers")
def markers_group() -> None:
    """Coded circular markers: print boards, find markers in images."""


@markers_group.command("board")
@click.option("--rows", type=click.IntRange(min=1), required=True, help="Rows of markers.")
@click.option("--cols", type=click.IntRange(min=1), required=True, help="Markers per row.")
@click.option("--pitch-mm", type=float, required=True, help="Distance between marker centres.")
@click.option("--first-id", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--dpi", type=float, default=300.0, show_default=True, help="For PNG output.")
@click.option(
    "--polarity",
    type=click.Choice(["dark-on-light", "light-on-dark"]),
    default="dark-on-light",
    show_default=True,
)
@click.option(
    "--out", "out", type=click.Path(dir_okay=False), required=True, help="FILE.svg|.pdf|.png"
)
def board_cmd(
    rows: int, cols: int, pitch_mm: float, first_id: int, dpi: float, polarity: str, out: str
) -> None:
    """Write a printable board of coded markers and, beside it, STEM.yaml describing it."""
    from labauto.calibration.boards_io import write_board
    from labauto.vision.boards import coded_board

    board = coded_board(rows, cols, pitch_mm, first_id, polarity)
    page, description = write_board(board, out, dpi)
    click.echo(
        f"{page}: {rows * cols} markers (ids {first_id}..{first_id + rows * cols - 1}), "
        f"{board.width_mm:g} x {board.height_mm:g} mm, centre circles of "
        f"{2 * board.marker_radius_mm:.3g} mm; description in {description}"
    )


@markers_group.command("detect")
@click.argument("image", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
def detect_cmd(image: str, as_json: bool) -> None:
    """Find the coded markers in IMAGE (ids, bias-corrected centres, ellipses)."""
    from labauto.imageio import read_image
    from labauto.vision.markers import find_markers

    result = find_markers(read_image(image))
    if as_json:
        doc = result.to_dict()
        click.echo(json.dumps(doc, indent=2))
        return
    click.echo(f"{image}: {len(result.markers)} markers ({result.timing_ms:.1f} ms)")
    for m in result.markers:
        a, b = m.ellipse.axes
        click.echo(
            f"  id {m.id:3d}  centre {m.center[0]:9.3f} {m.center[1]:9.3f}  "
            f"axes {a:.2f} {b:.2f}  score {m.score:.2f}"
        )
