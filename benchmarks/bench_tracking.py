"""Marker tracking: speed beside OpenCV's ArUco detector, and accuracy on rendered sequences.

Scenes (``labauto.synthetic.marker_sequences``): a board of 35 coded markers (7 x 5, centre
circles of about 10 px) moving in front of a 1280 x 1024 (1.3 Mpixel) camera with lens
distortion, tilting up to 30 degrees, with motion blur, drifting uneven light and noise
(sigma 2 grey levels).

Speed (median ms per frame over the sequence, best of ``--repeats`` passes; the pipelines take
turns within each repeat, so a slow spell of the shared machine hits them alike):

* ``MarkerTracker`` with windowed search (``full_interval`` 10): frames searched in windows
  (``roi``), the full-frame searches among them, and the mean over all frames;
* ``MarkerTracker`` searching every frame whole (``full_interval`` 1);
* ``detect_markers`` on every frame (the whole detector: fits, code reads, bias correction);
* OpenCV's ArUco detector (``cv2.aruco.ArucoDetector``, DICT_4X4_1000) on the same sequence
  with an ArUco square (6 centre radii wide) in each coded marker's place.

Accuracy on a harder sequence (the board swinging partly out of the view and back, an
occluding bar crossing it): id swaps, share of visible markers reported (all misses, and
excusing markers that came into view after the last full-frame search), re-entry latency
(frames after the first full-frame search), centre errors (DES centroids; fitted centres with
``fit=True``), and the pose of the board (``solvePnP``) against the truth beside the error
its reprojection residual predicts; the centre errors again by the frame's smear (motion blur
length: the board's mean motion during the exposure, which the renderer blurs the frame with).

Run: ``python benchmarks/bench_tracking.py [--frames N] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

from labauto.synthetic.marker_sequences import (
    SequenceSpec,
    board_points,
    mean_motion,
    render_sequence,
)
from labauto.synthetic.tracking_score import score_tracking
from labauto.vision.markers import detect_markers
from labauto.vision.pose import estimate_pose, rotation_error_deg
from labauto.vision.tracking import MarkerTracker

ARUCO = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_1000)
SPEED = SequenceSpec(motion_blur=True, exposure=0.25, amplitude_mm=(60.0, 30.0))
HARD = SequenceSpec(motion_blur=True, exposure=0.25, amplitude_mm=(200.0, 80.0), occluder=True)


def aruco_painter(image, marker_id, center, radius, to_image, ink) -> None:
    """An ArUco square 6 centre radii wide in the coded marker's place (homography warp)."""
    side_px = 60
    bitmap = cv2.aruco.generateImageMarker(ARUCO, marker_id, side_px, borderBits=1)
    half = 3.0 * radius
    corners_mm = np.array(center) + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    corners_px = to_image(corners_mm).astype(np.float32)
    source = np.array([[0, 0], [side_px, 0], [side_px, side_px], [0, side_px]], np.float32) - 0.5
    h = cv2.getPerspectiveTransform(source, corners_px)
    size = (image.shape[1], image.shape[0])
    warped = cv2.warpPerspective(bitmap.astype(np.float32), h, size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.ones_like(bitmap, np.float32), h, size, flags=cv2.INTER_LINEAR)
    level = ink + (warped / 255.0) * (image - ink)
    image[:] = image * (1 - mask) + level * mask


def timed(frames: list[np.ndarray], step) -> list[float]:
    out = []
    for image in frames:
        started = time.perf_counter()
        step(image)
        out.append((time.perf_counter() - started) * 1e3)
    return out


def speed(frames, aruco_frames, repeats: int) -> dict[str, object]:
    best: dict[str, list[float]] = {}
    modes: list[str] = []
    found: dict[str, int] = {}

    def keep(name: str, times: list[float]) -> None:
        if name not in best or np.median(times) < np.median(best[name]):
            best[name] = times

    aruco = cv2.aruco.ArucoDetector(ARUCO, cv2.aruco.DetectorParameters())

    def run(name: str, images: list[np.ndarray], count) -> list:
        outputs: list = []
        keep(name, timed(images, lambda im: outputs.append(count(im))))
        return outputs

    for _ in range(repeats):
        windowed = MarkerTracker(full_interval=10)
        results = run("windowed", frames, windowed.update)
        modes = [r.mode for r in results]
        found["windowed"] = int(np.median([len(r.markers) for r in results]))
        whole = MarkerTracker(full_interval=1)
        found["full"] = int(np.median([len(r.markers) for r in run("full", frames, whole.update)]))
        found["detector"] = int(
            np.median(run("detector", frames, lambda im: len(detect_markers(im))))
        )
        found["aruco"] = int(
            np.median(run("aruco", aruco_frames, lambda im: len(aruco.detectMarkers(im)[0])))
        )
    return {"times": best, "modes": modes, "found": found}


def accuracy(frames, spec: SequenceSpec) -> dict[str, object]:
    rows = {}
    points = board_points(spec)
    for fit in (False, True):
        tracker = MarkerTracker(fit=fit)
        results = [tracker.update(f.image) for f in frames]
        score = score_tracking(results, frames)
        pose_rows = []
        for result, frame in zip(results, frames, strict=True):
            pose = estimate_pose(result.centers(), points, spec.camera_matrix, spec.dist_coeffs)
            if pose is not None:
                pose_rows.append(
                    (
                        float(np.linalg.norm(pose.tvec - frame.tvec)),
                        rotation_error_deg(pose.rvec, frame.rvec),
                        pose.std_translation_mm,
                        pose.std_rotation_deg,
                        pose.rms_px,
                    )
                )
        rows["fitted" if fit else "DES centroid"] = (
            score,
            np.array(pose_rows),
            tracker.stats,
            errors_by_smear(results, frames, spec),
        )
    return rows


def errors_by_smear(results, frames, spec: SequenceSpec) -> list[tuple[str, np.ndarray]]:
    """Centre errors of visible markers grouped by their frame's smear (motion blur) length.

    The smear is the one the renderer blurs the frame with: the board's mean image motion
    during the exposure (:func:`labauto.synthetic.marker_sequences.mean_motion`).
    """
    points = board_points(spec)
    rows: list[tuple[float, float]] = []
    for result, frame in zip(results, frames, strict=True):
        motion = mean_motion(spec, points, frame.index) if spec.motion_blur else (0.0, 0.0)
        smear = float(np.hypot(*motion))
        for mid, (x, y) in result.centers().items():
            if mid in frame.visible:
                tx, ty = frame.centers[mid]
                rows.append((smear, float(np.hypot(x - tx, y - ty))))
    table = np.array(rows).reshape(-1, 2)
    bins = [("< 2 px", 0.0, 2.0), ("2-4 px", 2.0, 4.0), (">= 4 px", 4.0, np.inf)]
    return [(name, table[(table[:, 0] >= lo) & (table[:, 0] < hi), 1]) for name, lo, hi in bins]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=60, help="frames of the speed sequence")
    parser.add_argument("--hard-frames", type=int, default=120, help="frames of the hard one")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"# bench_tracking: {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f} (1 min)")
    started = time.perf_counter()
    sequence = list(render_sequence(SPEED, args.frames, np.random.default_rng(1)))
    frames = [f.image for f in sequence]
    aruco_frames = [
        f.image
        for f in render_sequence(
            SPEED, args.frames, np.random.default_rng(1), painter=aruco_painter
        )
    ]
    hard = list(render_sequence(HARD, args.hard_frames, np.random.default_rng(2)))
    print(f"# rendered in {time.perf_counter() - started:.1f} s")

    measured = speed(frames, aruco_frames, args.repeats)
    times, modes, found = measured["times"], measured["modes"], measured["found"]
    windowed = np.array(times["windowed"])
    roi = windowed[[m == "roi" for m in modes]]
    full_in_windowed = windowed[[m == "full" for m in modes]]
    visible = int(np.median([len(f.visible) for f in sequence]))
    print(
        f"\n## Speed: {len(frames)} frames of 1280x1024, {visible} of 35 markers in view "
        "(median), best of the repeats"
    )
    print("| pipeline | median ms/frame | fps | markers per frame |")
    print("|---|---|---|---|")

    def row(name: str, values: np.ndarray, count: int | str) -> None:
        median = float(np.median(values))
        print(f"| {name} | {median:.2f} | {1000 / median:.0f} | {count} |")

    row(f"tracker, windowed frames ({len(roi)} of {len(modes)})", roi, found["windowed"])
    row(
        f"tracker, its full-frame searches ({len(full_in_windowed)})",
        full_in_windowed,
        found["windowed"],
    )
    print(
        f"| tracker, all frames (mean) | {windowed.mean():.2f} | {1000 / windowed.mean():.0f} "
        f"| {found['windowed']} |"
    )
    row("tracker, every frame searched whole", np.array(times["full"]), found["full"])
    row("detect_markers on every frame", np.array(times["detector"]), found["detector"])
    row("OpenCV ArUco (DICT_4X4_1000), same motion", np.array(times["aruco"]), found["aruco"])

    print(f"\n## Accuracy: {len(hard)} frames, board leaving/entering the view, occluder")
    print(
        "| centres | id swaps | visible reported | excusing entries | max re-entry latency "
        "| centre error median / p99 / max px | pose error median / max mm | deg "
        "| predicted (median) mm / deg | within 3 predicted sigma (t / r) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    measured_accuracy = accuracy(hard, HARD)
    for name, (score, poses, _stats, _smear) in measured_accuracy.items():
        t, r, ts, rs, _rms = poses.T
        latency = max(score.latencies) if score.latencies else "-"
        print(
            f"| {name} | {score.swaps} | {100 * score.reported_rate:.2f} % "
            f"| {100 * score.tracked_rate:.2f} % | {latency} "
            f"| {score.error(50):.3f} / {score.error(99):.3f} / {score.error(100):.3f} "
            f"| {np.median(t):.3f} / {t.max():.3f} | {np.median(r):.3f} / {r.max():.3f} "
            f"| {np.median(ts):.3f} / {np.median(rs):.3f} "
            f"| {100 * np.mean(t <= 3 * ts):.0f} % / {100 * np.mean(r <= 3 * rs):.0f} % |"
        )

    print("\n## Centre error by the frame's motion blur (the board's mean smear in the exposure)")
    print("| centres | smear | markers | median px | p99 px | max px |")
    print("|---|---|---|---|---|---|")
    for name, (*_, by_smear) in measured_accuracy.items():
        for smear, errors in by_smear:
            if len(errors):
                print(
                    f"| {name} | {smear} | {len(errors)} | {np.median(errors):.3f} "
                    f"| {np.percentile(errors, 99):.3f} | {errors.max():.3f} |"
                )


if __name__ == "__main__":
    main()
