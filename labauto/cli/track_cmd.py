"""``labauto track SOURCE``: coded markers tracked through a video, a folder or a camera.

With ``--json-lines`` each frame is one JSON object on its own line, printed (and flushed) as
soon as the frame is done::

    {"frame": 0, "timing_ms": 31.2, "mode": "full", "markers": [{"id": 3, "center": [x, y]}],
     "lost": [], "appeared": [3]}

``--board FILE.yaml`` keeps only the board's markers (a code read as an id not on the board is
dropped); with ``--calibration FILE`` as well, each line gets ``"pose"``: the board's pose in the
camera frame (``rvec``, ``tvec_mm``, ``markers``, ``reprojection_rms_px``, predicted standard
errors; ``null`` when fewer than 4 of its markers are seen). ``--stereo SOURCE2`` with
``--calibration`` and ``--calibration2`` (each with the camera's pose ``rvec``, ``tvec`` in a
common world frame) tracks a second camera's frames beside the first, pairs them in order, and
adds ``"points_3d"``: ``[{"id", "position_mm": [x, y, z], "reprojection_px": [a, b]}]`` for the
markers both see (the lines are the first camera's otherwise). Without ``--json-lines`` a summary
is printed at the end. A source that fails part way (an unreadable file, a camera that stops)
ends the command with one ``labauto: error:`` line; the frames already printed stay printed.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import click

from labauto.cli.options import config_option
from labauto.config import Config


@click.command("track")
@click.argument("source")
@click.option(
    "--board",
    "board_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Rigid marker set (board YAML or id -> [x, y, z] mm): keep only its ids.",
)
@click.option(
    "--calibration",
    "calibration_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Camera calibration (OpenCV FileStorage or JSON): with --board, "
    "the board's pose per frame.",
)
@click.option(
    "--stereo",
    "stereo_source",
    default=None,
    help="A second camera's SOURCE: triangulated 3D positions (needs --calibration2).",
)
@click.option(
    "--calibration2",
    "calibration2_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="The second camera's calibration (with rvec, tvec; --calibration then too).",
)
@click.option("--json-lines", "json_lines", is_flag=True, help="One JSON object per frame.")
@click.option(
    "--fit", is_flag=True, help="Fitted, bias-corrected centres (default: DES centroids)."
)
@click.option(
    "--full-interval",
    type=click.IntRange(min=1),
    default=10,
    show_default=True,
    help="A full-frame search every N frames.",
)
@click.option(
    "--frame-timeout",
    type=click.FloatRange(min=0, min_open=True),
    default=10.0,
    show_default=True,
    help="Longest wait (s) for a camera plugin's next frame.",
)
@config_option
def track_cmd(
    source: str,
    board_path: str | None,
    calibration_path: str | None,
    stereo_source: str | None,
    calibration2_path: str | None,
    json_lines: bool,
    fit: bool,
    full_interval: int,
    frame_timeout: float,
    config: Config,
) -> None:
    """Track coded markers through SOURCE: a video file, a folder of images (name order), or
    camera:NAME (a camera plugin)."""
    from labauto.cli.track_inputs import read_camera, read_camera_view, read_rigid_set
    from labauto.cli.track_sources import open_source
    from labauto.vision.pose import estimate_pose, triangulate
    from labauto.vision.tracking import MarkerTracker

    board = read_rigid_set(board_path) if board_path else None
    views = None
    if stereo_source is not None:
        if not (calibration_path and calibration2_path):
            raise click.UsageError("--stereo needs --calibration and --calibration2")
        views = (read_camera_view(calibration_path), read_camera_view(calibration2_path))
    elif calibration2_path:
        raise click.UsageError("--calibration2 is for --stereo")
    camera = read_camera(calibration_path) if calibration_path else None
    if camera is not None and board is None and views is None:
        raise click.UsageError("--calibration needs --board (the rigid set whose pose to give)")

    def cameras(name: str) -> Any:
        from labauto.plugin_manager import load_plugins

        plugins = load_plugins(config.plugins.enabled, config.plugins.disabled)
        return plugins.registry.driver("camera", name)(config.camera)

    frames = open_source(source, camera_factory=cameras, frame_timeout_s=frame_timeout)
    tracker = MarkerTracker(fit=fit, full_interval=full_interval)
    second = MarkerTracker(fit=fit, full_interval=full_interval)
    pairs: Iterator[tuple[Any, Any]] = ((image, None) for _name, image in frames)
    if stereo_source is not None:
        others = open_source(stereo_source, camera_factory=cameras, frame_timeout_s=frame_timeout)
        pairs = ((a[1], b[1]) for a, b in zip(frames, others, strict=False))
    summary = _Summary()
    try:
        for image, image2 in pairs:
            result = tracker.update(image)
            document = result.to_dict()
            if image2 is not None and views is not None:
                points = triangulate(result.centers(), second.update(image2).centers(), *views)
                if board is not None:
                    points = [p for p in points if p.id in board]
                document["points_3d"] = [p.to_dict() for p in points]
            if board is not None:
                document["markers"] = [m for m in document["markers"] if m["id"] in board]
                document["lost"] = [i for i in document["lost"] if i in board]
                document["appeared"] = [i for i in document["appeared"] if i in board]
            if camera is not None and board is not None and views is None:
                centers = {m["id"]: tuple(m["center"]) for m in document["markers"]}
                pose = estimate_pose(centers, board, *camera)
                document["pose"] = None if pose is None else pose.to_dict()
            summary.add(document)
            if json_lines:
                click.echo(json.dumps(document), nl=True)
    finally:
        if not json_lines and summary.frames:
            click.echo(summary.text(source))


class _Summary:
    """What the command prints at the end without ``--json-lines``."""

    def __init__(self) -> None:
        self.frames = 0
        self.ids: set[int] = set()
        self.roi_ms: list[float] = []
        self.full_ms: list[float] = []
        self.started = time.perf_counter()

    def add(self, document: dict[str, Any]) -> None:
        self.frames += 1
        self.ids.update(m["id"] for m in document["markers"])
        (self.roi_ms if document["mode"] == "roi" else self.full_ms).append(document["timing_ms"])

    def text(self, source: str) -> str:
        def median(values: list[float]) -> str:
            return f"{sorted(values)[len(values) // 2]:.1f} ms" if values else "-"

        return (
            f"{source}: {self.frames} frames, {len(self.ids)} markers seen "
            f"({', '.join(map(str, sorted(self.ids))) or 'none'}); windowed search "
            f"{len(self.roi_ms)} frames (median {median(self.roi_ms)}), full-frame "
            f"{len(self.full_ms)} (median {median(self.full_ms)})"
        )
