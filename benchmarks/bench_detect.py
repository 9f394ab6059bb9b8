"""Detector speed and ellipse precision/recall on synthetic 1280x1024 colour scenes.

Each scene (``labauto.synthetic.shapes.make_scene``) holds about 40 ellipses among 90 rectangles,
lines, stars, triangles and crescents, with Gaussian noise. For several seeds we time (median of
repeats, the pipelines taking turns within each repeat so that a slow spell of a shared machine
hits them alike) and score, in the same run:

* ``detect`` of labauto (``labauto.detect`` with ``--api`` when it exists, else
  ``labauto.vision.detector.detect``): core (no shape label, no fit), with shape labels, and with
  labels and ellipse fitting;
* a plain OpenCV pipeline: grey, ``cv2.Canny``, ``cv2.findContours``, ``cv2.fitEllipse`` on every
  contour with >= 5 points (every fit counts as an ellipse);
* ``cv2.ximgproc`` EdgeDrawing ellipses, when opencv-contrib is installed.

Ellipse detections: for ``detect`` the DES whose shape label is circle/ellipse (rows without labels:
every DES); a detection matches a true ellipse when its centre is within 2 px and, when the row
gives axes, both semi-axes are within 10 % (+0.5 px). For matched ellipses the mean centre error
and the mean semi-axis error (px) are shown too. A line then gives the default ``detect``'s time
as a multiple of the plain pipeline's (median over scenes of the per-scene ratio).

A second table splits the default ``detect`` (labels + fit) into its stages (median ms per image):
colour gradient (eq. 2), Canny hysteresis, edge linking with sub-pixel refinement (one kernel
pass: thinning, tracing, ordered chains, gradients), shape angle D_alpha (eq. 3), shape labels
(harmonics), ellipse fits, and the rest (validation, building the objects).
Run: ``python benchmarks/bench_detect.py``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import cv2
import numpy as np

from labauto.cli import process
from labauto.synthetic.shapes import make_scene
from labauto.vision import detector, edges
from labauto.vision.contours import Contours
from labauto.vision.detector import DetectorParams
from labauto.vision.detector import detect as vision_detect
from labauto.vision.gradient import color_gradient
from labauto.vision.image import as_image
from labauto.vision.shape_angle import shape_angles

Detection = tuple[float, float, float | None, float | None]  # cx, cy, a, b


def _detect_fn(api: bool) -> tuple[str, Callable]:
    if api:
        try:
            from labauto import detect as api_detect  # the public API

            return "labauto.detect", lambda img, p: api_detect(img, **p.__dict__)
        except ImportError:
            pass
    return "vision.detect", vision_detect


def detections_from_result(result, use_labels: bool) -> list[Detection]:
    out = []
    for obj in result.objects:
        if not obj.is_des:
            continue
        if use_labels and obj.shape not in ("circle", "ellipse"):
            continue
        if obj.ellipse is not None:
            (cx, cy), (a, b) = obj.ellipse.center, obj.ellipse.axes
            out.append((cx, cy, a, b))
        else:
            out.append((obj.centroid[0], obj.centroid[1], None, None))
    return out


def plain_opencv(image: np.ndarray) -> list[Detection]:
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    edges = cv2.Canny(grey, 50, 150)
    contours, _ = cv2.findContours(edges, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        if len(c) >= 5:
            (cx, cy), (w, h), _ = cv2.fitEllipse(c)
            out.append((cx, cy, max(w, h) / 2, min(w, h) / 2))
    return out


def edge_drawing() -> Callable | None:
    if not hasattr(cv2, "ximgproc"):
        return None
    ed = cv2.ximgproc.createEdgeDrawing()

    def run(image: np.ndarray) -> list[Detection]:
        ed.detectEdges(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
        found = ed.detectEllipses()
        out = []
        for row in [] if found is None else found.reshape(-1, found.shape[-1]):
            cx, cy, r, a, b = row[:5]
            if r > 0:
                out.append((cx, cy, r, r))
            else:
                out.append((cx, cy, max(a, b), min(a, b)))
        return out

    return run


def score(found: list[Detection], truth: list[dict]) -> tuple[int, int, int, list, list]:
    """(true positives, detections, true ellipses, centre errors, semi-axis errors) with
    one-to-one greedy matching."""
    ellipses = [t["ellipse"] for t in truth if t["kind"] == "ellipse"]
    used = set()
    tp = 0
    centre_err, axis_err = [], []
    for e in ellipses:
        (tx, ty), (ta, tb) = e["center"], e["axes"]
        best, best_d = None, 2.0
        for i, (cx, cy, a, b) in enumerate(found):
            if i in used:
                continue
            d = float(np.hypot(cx - tx, cy - ty))
            if d > best_d:
                continue
            if a is not None and (abs(a - ta) > 0.1 * ta + 0.5 or abs(b - tb) > 0.1 * tb + 0.5):
                continue
            best, best_d = i, d
        if best is not None:
            used.add(best)
            tp += 1
            centre_err.append(best_d)
            _, _, a, b = found[best]
            if a is not None:
                axis_err += [abs(a - ta), abs(b - tb)]
    return tp, len(found), len(ellipses), centre_err, axis_err


STAGES = (
    "gradient (eq. 2)",
    "canny hysteresis",
    "edge linking + sub-pixel",
    "shape angle (eq. 3)",
    "shape labels",
    "ellipse fits",
    "rest",
)


def stage_times(image: np.ndarray, params: DetectorParams) -> list[float]:
    """Seconds per stage of ``detect(image, params)`` (Canny method), same calls in order."""
    t = [time.perf_counter()]
    img = as_image(image)
    gx, gy = color_gradient(img, params.blur_sigma)
    t.append(time.perf_counter())
    edge_map = edges.canny_edges(gx, gy, params.canny_low, params.canny_high)
    t.append(time.perf_counter())
    points, offsets, grads, closed = edges.edge_contours(
        edge_map, gx, gy, params.min_contour_length, params.max_contour_length, params.subpixel
    )
    contours = Contours(points, offsets, grads, closed)
    t.append(time.perf_counter())
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    des = angles.is_des(params.des_threshold_deg, params.statistic, params.max_gap_fraction)
    t.append(time.perf_counter())
    d_alpha = angles.statistic(params.statistic)
    detector._labels(contours, d_alpha, angles.centroid_inside, angles.centroid, params)
    t.append(time.perf_counter())
    detector._fits(contours, des, params)
    t.append(time.perf_counter())
    total = time.perf_counter()
    vision_detect(image, params)
    whole = time.perf_counter() - total
    stages = list(np.diff(t))
    return [*stages, max(whole - sum(stages), 0.0)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2, help="cv2.setNumThreads")
    parser.add_argument("--noise", type=float, default=4.0)
    parser.add_argument("--api", action="store_true", help="time labauto.detect if it exists")
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)
    process.configure()  # the kernels' threads and OpenMP's wait policy, as the CLI sets them

    name, detect = _detect_fn(args.api)
    rows: list[tuple[str, Callable[[np.ndarray], list[Detection]]]] = []
    for label, params, labels in [
        ("core: no label, no fit", DetectorParams(classify=False, fit_ellipses=False), False),
        ("+ shape labels", DetectorParams(fit_ellipses=False), True),
        ("+ labels + ellipse fit", DetectorParams(), True),
    ]:
        rows.append(
            (
                f"{name} {label}",
                lambda img, p=params, u=labels: detections_from_result(detect(img, p), u),
            )
        )
    rows.append(("plain OpenCV (grey Canny + fitEllipse)", plain_opencv))
    ed = edge_drawing()
    if ed is not None:
        rows.append(("cv2.ximgproc EdgeDrawing ellipses", ed))

    scenes = [
        make_scene(np.random.default_rng(seed), noise=args.noise) for seed in range(args.seeds)
    ]
    print(
        f"{args.seeds} scenes 1280x1024 BGR, noise sigma {args.noise}, cv2.setNumThreads("
        f"{args.threads}) (cv2.getNumThreads() = {cv2.getNumThreads()}, "
        f"{os.cpu_count()} CPUs), {args.repeats} repeats, cv2 {cv2.__version__}, "
        f"numpy {np.__version__}"
    )
    if ed is None:
        print(
            "cv2.ximgproc not installed: EdgeDrawing row skipped (opencv-contrib-python-headless)"
        )
    columns = ("ms/image", "min ms", "found", "prec", "recall", "ctr err", "axis err")
    header = f"{'pipeline':48s} " + " ".join(f"{c:>9s}" for c in columns)
    print(header)
    print("-" * len(header))
    # Repeats are interleaved (each repeat runs every pipeline in turn on the same scene), so a
    # slow spell of this shared machine hits all rows alike and the ratios stay fair.
    per_scene_ms: list[list[float]] = [[] for _ in rows]
    found_by_row: list[list[list[Detection]]] = [[] for _ in rows]
    for image, _ in scenes:
        for r, (_, fn) in enumerate(rows):
            found_by_row[r].append(fn(image))  # warm-up, and the detections scored below
        samples: list[list[float]] = [[] for _ in rows]
        for _ in range(args.repeats):
            for r, (_, fn) in enumerate(rows):
                t0 = time.perf_counter()
                fn(image)
                samples[r].append(time.perf_counter() - t0)
        for r in range(len(rows)):
            per_scene_ms[r].append(1e3 * float(np.median(samples[r])))
    for r, (label, _) in enumerate(rows):
        tp, n_found, n_true, centre_err, axis_err = 0, 0, 0, [], []
        for found, (_, truth) in zip(found_by_row[r], scenes, strict=True):
            a, b, c, errs, axes = score(found, truth)
            tp, n_found, n_true = tp + a, n_found + b, n_true + c
            centre_err += errs
            axis_err += axes
        precision = tp / n_found if n_found else float("nan")
        recall = tp / n_true if n_true else float("nan")
        ctr = np.mean(centre_err) if centre_err else float("nan")
        axis = np.mean(axis_err) if axis_err else float("nan")
        print(
            f"{label:48s} {np.median(per_scene_ms[r]):9.2f} {np.min(per_scene_ms[r]):9.2f} "
            f"{n_found / len(scenes):9.1f} {precision:9.3f} {recall:9.3f} {ctr:9.4f} {axis:9.4f}"
        )
    ours, plain = np.array(per_scene_ms[2]), np.array(per_scene_ms[3])
    print(
        f"\n{name} + labels + ellipse fit takes {np.median(ours / plain):.2f}x the time of the "
        f"plain OpenCV pipeline (median over scenes; {np.min(ours / plain):.2f}x-"
        f"{np.max(ours / plain):.2f}x)"
    )
    print(f"\nstages of {name} + labels + ellipse fit (median ms per image over the scenes)")
    params = DetectorParams()
    per_scene = []
    for image, _ in scenes:
        stage_times(image, params)  # warm-up
        per_scene.append(np.median([stage_times(image, params) for _ in range(args.repeats)], 0))
    stage_ms = 1e3 * np.median(per_scene, axis=0)
    for stage, ms in zip(STAGES, stage_ms, strict=True):
        print(f"  {stage:28s} {ms:7.2f}")
    print(f"  {'sum':28s} {stage_ms.sum():7.2f}")


if __name__ == "__main__":
    main()
