"""Coded markers: ids, false ids, centre accuracy and speed, beside ArUco and findCirclesGrid.

The paper's test (section 4.2): 40 markers among 130 objects (40 markers, 40 rectangles and
artefacts) per 1.3-Mpixel image. Each scene (``labauto.synthetic.marker_scenes.marker_scene``)
has 40 coded markers of 10-14 px centre radius, each on its own plane tilted up to 60 degrees
to the line of sight (perspective, not just an ellipse), 40 rectangles and 50 artefacts (plain
dots, triangles, stars, lines, crescents), uneven light (gain 0.7-1.0) and a Gaussian blur.

Accuracy (issue 14.6), over ``--scenes`` scenes, twice: noise-free (blur 1 px, even light) and
with noise sigma 2 grey levels (blur 1 px, uneven light). For each: ids found / true, false ids
(ids returned that are not in the scene), and the distance of each centre from the true image
of the marker's centre: ``center`` (bias-corrected), the centre circle's fitted ellipse centre
(what a plain ellipse fit gives, perspective bias included) and the DES centroid.

Speed (issue 14.8): median, best and p90 time per scene, the pipelines taking turns on each
repeat (on a shared machine the best is the least disturbed by other load):

* ``detect_markers`` (DES prefilter, fits, code read, bias correction);
* the same with ``correct_bias=False`` (ids and the geometric fits of the DES contours only);
* OpenCV ArUco (``cv2.aruco.ArucoDetector``, DICT_4X4_1000) on the same scenes with each coded
  marker replaced by an ArUco marker of 6 x 6 centre radii under the same homography;
* ``cv2.findCirclesGrid`` on an 8 x 5 grid of 40 circles (a view of a circle-grid board).

Run: ``python benchmarks/bench_markers.py [--scenes 50] [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import time

import cv2
import numpy as np

from labauto.synthetic.board_views import board_poses, render_board_view
from labauto.synthetic.marker_scenes import marker_scene
from labauto.synthetic.markers import homography_map
from labauto.vision.board_points import opencv_circle_grid
from labauto.vision.boards import board_from_dict
from labauto.vision.markers import detect_markers

ARUCO = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_1000)


def aruco_painter(img: np.ndarray, marker_id: int, hom: np.ndarray, ink: float):
    """Draw ArUco ``marker_id`` (6 x 6 cells of one centre radius) under ``hom``."""
    cells = 6
    side = 60  # bitmap px
    bitmap = cv2.aruco.generateImageMarker(ARUCO, marker_id, side, borderBits=1)
    scale = cells / side
    to_plane = np.array([[scale, 0, -cells / 2], [0, scale, -cells / 2], [0, 0, 1.0]])
    h = hom @ to_plane
    size = (img.shape[1], img.shape[0])
    warped = cv2.warpPerspective(bitmap.astype(np.float32), h, size, flags=cv2.INTER_AREA)
    mask = cv2.warpPerspective(np.ones_like(bitmap, np.float32), h, size, flags=cv2.INTER_AREA)
    paper = img.copy()
    level = ink + (warped / 255.0) * (paper - ink)
    img[:] = paper * (1 - mask) + level * mask
    cx, cy = homography_map(hom)(np.zeros((1, 2)))[0]
    return float(cx), float(cy)


def accuracy(scenes: int, noisy: bool) -> dict:
    found = total = false = 0
    errors = {"center": [], "ellipse": [], "centroid": []}
    for seed in range(scenes):
        kw = {} if noisy else {"noise_sigma": 0.0, "light_gain": (1.0, 1.0)}
        image, truth = marker_scene(np.random.default_rng(1000 + seed), **kw)
        where = {t.id: np.array(t.center) for t in truth}
        markers = detect_markers(image)
        total += len(truth)
        for m in markers:
            if m.id not in where:
                false += 1
                continue
            found += 1
            for key, pos in (("center", m.center), ("ellipse", m.ellipse.center),
                             ("centroid", m.centroid)):  # fmt: skip
                errors[key].append(float(np.hypot(*(np.array(pos) - where[m.id]))))
    return {"found": found, "total": total, "false": false,
            **{k: np.array(v) for k, v in errors.items()}}  # fmt: skip


def speed(repeats: int, n_scenes: int) -> dict:
    rng = np.random.default_rng(7)
    ours = [marker_scene(np.random.default_rng(2000 + s))[0] for s in range(n_scenes)]
    aruco_scenes = [
        marker_scene(np.random.default_rng(2000 + s), painter=aruco_painter)
        for s in range(n_scenes)
    ]
    board = board_from_dict(
        {"type": "circle-grid", "cols": 8, "rows": 5, "spacing_mm": 25.0, "diameter_mm": 10.0}
    )
    k = np.array([[1400.0, 0, 640], [0, 1400.0, 512], [0, 0, 1]])
    poses = board_poses(rng, n_scenes, board, k, np.zeros(5), (1280, 1024), max_tilt_deg=40)
    grids = [render_board_view(board, k, np.zeros(5), r, t, (1280, 1024), rng=rng)[0]
             for r, t in poses]  # fmt: skip
    detector = cv2.aruco.ArucoDetector(ARUCO, cv2.aruco.DetectorParameters())
    runs = {
        "detect_markers (fits, ids, bias correction)": (ours, lambda im: len(detect_markers(im))),
        "detect_markers, correct_bias=False": (
            ours, lambda im: len(detect_markers(im, correct_bias=False))
        ),
        "OpenCV ArUco detectMarkers (4x4)": (
            [s[0] for s in aruco_scenes], lambda im: len(detector.detectMarkers(im)[0])
        ),
        "OpenCV findCirclesGrid (8x5 circles)": (
            grids, lambda im: 0 if opencv_circle_grid(im, board) is None else 40
        ),
    }  # fmt: skip
    times: dict[str, list[float]] = {name: [] for name in runs}
    counts: dict[str, list[int]] = {name: [] for name in runs}
    for images, fn in runs.values():
        fn(images[0])  # warm up
    for _ in range(repeats):
        for i in range(n_scenes):
            for name, (images, fn) in runs.items():
                t = time.perf_counter()
                n = fn(images[i])
                times[name].append((time.perf_counter() - t) * 1e3)
                counts[name].append(n)
    aruco_truth = [len(s[1]) for s in aruco_scenes]
    return {"times": times, "counts": counts, "aruco_truth": aruco_truth}


def stage_times(image: np.ndarray) -> list[float]:
    """ms of: contours, DES prefilter + algebraic fits, code read, circles re-measured + bias
    correction, and the whole of ``find_markers`` (run after the stages)."""
    from labauto.vision import markers as mk
    from labauto.vision.detector import extract_contours

    params = mk.MarkerParams()
    t = [time.perf_counter()]
    contours = extract_contours(image, params.detector_params())
    t.append(time.perf_counter())
    _centroids, _index, rows = mk._candidates(image, contours, params)
    t.append(time.perf_counter())
    ids, score, _bit0, bits, start = mk._read_codes(image, rows, params)
    picked = [j for _, j in mk._best_reads(ids, score)]
    t.append(time.perf_counter())
    mk.refine_circles(image.astype(np.float32), rows[picked], bits[picked], start[picked],
                      params.min_contrast)  # fmt: skip
    t.append(time.perf_counter())
    stages = [(b - a) * 1e3 for a, b in itertools.pairwise(t)]
    return [*stages, mk.find_markers(image, params).timing_ms]


def _row(name: str, acc: dict) -> str:
    def stat(e: np.ndarray) -> str:
        return f"{e.mean():.4f} / {np.percentile(e, 95):.4f} / {e.max():.4f}"

    return (
        f"| {name} | {acc['found']}/{acc['total']} | {acc['false']} | {stat(acc['center'])} | "
        f"{stat(acc['ellipse'])} | {stat(acc['centroid'])} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=50, help="accuracy scenes per condition")
    parser.add_argument("--repeats", type=int, default=5, help="speed repeats")
    parser.add_argument("--speed-scenes", type=int, default=5, help="scenes timed")
    args = parser.parse_args()
    print(f"# coded markers ({os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.2f})")
    print()
    print(f"Accuracy over {args.scenes} scenes of 40 markers among 130 objects (1280x1024):")
    print()
    print("| scenes | ids found | false ids | centre error px, mean / p95 / max | "
          "ellipse centre (no correction) | DES centroid |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    print(_row("noise-free (blur 1 px)", accuracy(args.scenes, noisy=False)))
    print(_row("noise 2 grey levels, blur 1 px, uneven light", accuracy(args.scenes, noisy=True)))
    print()
    result = speed(args.repeats, args.speed_scenes)
    print(f"Speed, median ms per 1.3-Mpixel image over {args.speed_scenes} scenes x "
          f"{args.repeats} repeats (load average {os.getloadavg()[0]:.2f}):")  # fmt: skip
    print()
    print("| pipeline | median ms | best ms | p90 ms | markers found per image (median) |")
    print("|---|---|---|---|---|")
    for name, times in result["times"].items():
        t = np.array(times)
        n = int(np.median(result["counts"][name]))
        print(f"| {name} | {np.median(t):.1f} | {t.min():.1f} | {np.percentile(t, 90):.1f} | "
              f"{n} of 40 |")  # fmt: skip
    image = marker_scene(np.random.default_rng(2000))[0]
    stages = np.median([stage_times(image) for _ in range(args.repeats * 2)], axis=0)
    names = ("contours (gradient, Canny, linking, sub-pixel)", "DES prefilter + algebraic fits",
             "code read", "circles re-measured + bias correction", "whole")  # fmt: skip
    print()
    print(f"Stages of detect_markers, median ms (load average {os.getloadavg()[0]:.2f}): "
          + "; ".join(f"{n} {v:.1f}" for n, v in zip(names, stages, strict=True)))  # fmt: skip


if __name__ == "__main__":
    main()
