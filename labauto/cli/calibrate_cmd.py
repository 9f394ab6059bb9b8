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
    from labauto.calibrate import calibrate_camera

    result = calibrate_camera(board_path, list(images))
    doc = result.to_dict()
    if out:
        from labauto.calibration_files import write_opencv_yaml

        write_opencv_yaml(out, doc)
    if save_as:
        from labauto.store.calibrations import save_calibration

        with _store(config) as store:
            save_calibration(store.engine, save_as, "camera", doc)
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
    from labauto.calibration_files import write_opencv_yaml
    from labauto.errors import CalibrationError
    from labauto.store.calibrations import load_calibration

    with _store(config) as store:
        stored = load_calibration(store.engine, name)
    if stored is None:
        raise CalibrationError(f"no stored calibration named {name!r} (see labauto calibrate list)")
    write_opencv_yaml(out, {**stored.data, "residual_mm": stored.residual_mm})
    click.echo(f"{out}: calibration {name!r} ({stored.kind}, {stored.created_at:%Y-%m-%d %H:%M})")


@calibrate_group.command("list")
@config_option
def list_cmd(config: Config) -> None:
    """The stored calibrations."""
    from labauto.store.calibrations import list_calibrations

    with _store(config) as store:
        rows = list_calibrations(store.engine)
    for r in rows:
        extra = f", residual {r.residual_mm:.3f} mm" if r.residual_mm is not None else ""
        rms = f"RMS {r.rms_px:.4f} px" if r.rms_px is not None else "no RMS"
        click.echo(
            f"{r.id:4d}  {r.name}  {r.kind}  {r.image_size[0]}x{r.image_size[1]}  {rms}{extra}  "
            f"{r.created_at:%Y-%m-%d %H:%M}"
        )
