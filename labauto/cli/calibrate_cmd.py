"""``labauto calibrate camera|deck|export|list``: automated calibration (paper, 4.2)."""

from __future__ import annotations

import json

import click

from labauto.cli.options import config_option
from labauto.config import Config


@click.group("calibrate")
def calibrate_group() -> None:
    """Calibrate the camera (intrinsics, distortion) and the deck (pose, pixel-to-deck map)."""


def _store(config: Config):
    from labauto.store import Store

    return Store.open(config.database.url, migrate=True)


@calibrate_group.command("camera")
@click.option(
    "--board",
    "board_path",
    type=click.Path(dir_okay=False),
    required=True,
    help="Board description (STEM.yaml from 'labauto markers board', or a grid's YAML).",
)
@click.argument("images", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option("--save", "save_as", default=None, help="Store it in the database under NAME.")
@click.option(
    "--out",
    "out",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write it as OpenCV FileStorage YAML.",
)
@config_option
def camera_cmd(
    board_path: str,
    images: tuple[str, ...],
    as_json: bool,
    save_as: str | None,
    out: str | None,
    config: Config,
) -> None:
    """Intrinsics and distortion from IMAGES of a calibration board."""
    from labauto.calibration.camera import calibrate_camera

    result = calibrate_camera(board_path, list(images))
    doc = result.to_dict()
    if out:
        from labauto.calibration.files import write_opencv_yaml

        write_opencv_yaml(out, doc)
    if save_as:
        with _store(config) as store:
            store.save_calibration(save_as, "camera", doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2))
        return
    k = result.camera_matrix
    used = sum(v.used for v in result.views)
    click.echo(
        f"{used} of {len(result.views)} views used, RMS {result.rms_px:.4f} px; "
        f"fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} cx {k[0, 2]:.2f} cy {k[1, 2]:.2f}"
        + (f"; saved as {save_as!r}" if save_as else "")
    )
    for v in result.views:
        if not v.used:
            click.echo(f"  {v.image}: not used: {v.reason}")


@calibrate_group.command("export")
@click.argument("name")
@click.option("--out", "out", type=click.Path(dir_okay=False), required=True)
@config_option
def export_cmd(name: str, out: str, config: Config) -> None:
    """Write the stored calibration NAME as OpenCV FileStorage YAML."""
    from labauto.calibration.files import write_opencv_yaml
    from labauto.errors import CalibrationError

    with _store(config) as store:
        stored = store.latest_calibration(name)
    if stored is None:
        raise CalibrationError(f"no stored calibration named {name!r} (see labauto calibrate list)")
    write_opencv_yaml(out, {**stored.data, "residual_mm": stored.residual_mm})
    click.echo(f"{out}: calibration {name!r} ({stored.kind}, {stored.created_at:%Y-%m-%d %H:%M})")


@calibrate_group.command("list")
@config_option
def list_cmd(config: Config) -> None:
    """The stored calibrations."""
    with _store(config) as store:
        rows = store.list_calibrations()
    for r in rows:
        extra = f", residual {r.residual_mm:.3f} mm" if r.residual_mm is not None else ""
        rms = f"RMS {r.rms_px:.4f} px" if r.rms_px is not None else "no RMS"
        click.echo(
            f"{r.id:4d}  {r.name}  {r.kind}  {r.image_size[0]}x{r.image_size[1]}  {rms}{extra}  "
            f"{r.created_at:%Y-%m-%d %H:%M}"
        )


@calibrate_group.command("deck")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option("--no-save", is_flag=True, help="Do not store it (runs would not use it).")
@config_option
def deck_cmd(as_json: bool, no_save: bool, config: Config) -> None:
    """The camera's pose over the deck and the pixel-to-deck map (calibration.deck)."""
    from labauto.calibration.deck import calibrate_deck

    with _store(config) as store:
        cal, report = calibrate_deck(config, store)
        doc = {**cal.to_dict(), "camera": report["camera"], "source": report["source"]}
        if "positions" in report:
            doc["positions"] = report["positions"]
        name = config.calibration.deck.name
        if not no_save:
            store.save_calibration(name, "deck", doc, residual_mm=cal.residual_mm)
    if as_json:
        click.echo(json.dumps(doc, indent=2))
        return
    x, y, z = cal.camera_position()
    click.echo(
        f"deck calibration: residual {cal.residual_mm:.4f} mm (worst {cal.max_error_mm:.4f} mm) "
        f"over {cal.n_points} points ({report['summary']}); camera at ({x:.1f}, {y:.1f}, "
        f"{z:.1f}) mm" + ("" if no_save else f"; saved as {name!r}, runs will use it")
    )


@calibrate_group.command("simulate-views")
@click.option("--board", "board_path", type=click.Path(dir_okay=False), required=True)
@click.option("--out", "out", type=click.Path(file_okay=False), required=True)
@click.option("--views", type=click.IntRange(min=1), default=12, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@config_option
def simulate_views_cmd(board_path: str, out: str, views: int, seed: int, config: Config) -> None:
    """Write views of a board held before the simulated deck camera (for a simulated workcell).

    The camera is calibration.deck.simulated_camera; the board is tilted up to 50 degrees.
    """
    from pathlib import Path

    import numpy as np

    from labauto.calibration.boards_io import read_board
    from labauto.imageio import write_image
    from labauto.synthetic.board_views import board_poses, render_board_view

    board = read_board(board_path)
    sim = config.calibration.deck.simulated_camera
    k, d = np.array(sim.camera_matrix), np.array(sim.dist_coeffs)
    rng = np.random.default_rng(seed)
    folder = Path(out)
    for i, (rvec, tvec) in enumerate(
        board_poses(rng, views, board, k, d, sim.image_size, max_tilt_deg=50.0)
    ):
        image, _ = render_board_view(board, k, d, rvec, tvec, sim.image_size, rng=rng)
        write_image(folder / f"view{i:02d}.png", image)
    click.echo(f"{out}: {views} views of {board_path} by the simulated deck camera")
