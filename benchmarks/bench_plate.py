"""Plate analysis speed and accuracy on synthetic 1280x1024 (1.3 Mpixel) petri dishes.

A second table times the same plates as 16-Mpixel photos (upscaled 3.5x to 4480x3584): plate
analysis then works on a copy resampled to ``analysis_px_per_mm`` (see
``labauto.vision.plate_scale``), the plain baseline on the full image.

Each plate (``labauto.synthetic.plates.generate_plate``) holds 20 authentic, 6 merged (pairs and
triples) and 4 mixed colonies among dust, scratches, pen marks, labels and glare, on one of six
agars. For every plate we time (median over repeats; the table gives the median and 90th
percentile over all plates x repeats) and score, in the same run:

* ``analyze_plate``: the default pipeline (dish detection, eq. 1 segmentation, D_alpha, waist,
  mixed-colony test, merged counts);
* ``analyze_plate (region)``: the same with the dish given (no dish detection);
* ``analyze_plate (generic detector)``: objects from ``labauto.vision.detector.detect``
  (method "color") instead;
* a plain OpenCV baseline: the dish by ``cv2.HoughCircles`` on a subsampled grey image, grey
  deviation from the dish's median grey, Otsu threshold, ``cv2.findContours``, an area filter,
  ``cv2.fitEllipse``; a body whose area is at least 90 % of its fitted ellipse's is authentic,
  else merged (aspect > 3.5: dropped as an artefact); it has no mixed class and counts a merged
  body as 2.

Scores: a reported colony matches the truth colony whose outline holds its centroid
(``score_plate``); "correct" is matched with the right class; FP are reported colonies matching
none. A second table splits ``analyze_plate``'s time into its stages (``PlateResult.stage_ms``:
dish, objects, measures, classes). Run:
``python benchmarks/bench_plate.py [--plates N] [--repeats R] [--threads T]`` (``--threads``
sets ``cv2.setNumThreads``; OpenCV's default otherwise).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.cli import process
from labauto.synthetic.plates import PlateTruth, generate_plate, score_plate
from labauto.vision.detector import DetectorParams
from labauto.vision.dish import hough_dish
from labauto.vision.plate import PlateParams, analyze_plate

AGARS = ("amber", "red_blood", "chocolate", "clear", "macconkey", "chromogenic")


@dataclass
class _Reported:
    centroid: tuple[float, float]
    klass: str
    estimated_count: int


def baseline(image: np.ndarray) -> list[_Reported]:
    """The plain OpenCV pipeline described in the module docstring."""
    h, w = image.shape[:2]
    guess = hough_dish(image)
    if guess is None:
        return []
    cx, cy, r = guess
    r -= 45.0  # the wall and a margin (the Hough circle tends to sit on the outer rim)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    mask = np.zeros((h, w), np.uint8)
    cv2.circle(mask, (round(cx), round(cy)), round(r), 255, -1)
    median = float(np.median(grey[mask > 0]))
    dev = cv2.absdiff(grey, np.full_like(grey, round(median)))
    dev = cv2.bitwise_and(cv2.GaussianBlur(dev, (3, 3), 0), mask)
    _, fg = cv2.threshold(dev, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        area = cv2.contourArea(c)
        if area < 60 or len(c) < 5:
            continue
        (ex, ey), (d1, d2), _ = cv2.fitEllipse(c)
        big, small_axis = max(d1, d2), max(min(d1, d2), 1e-6)
        if big / small_axis > 3.5:
            continue
        m = cv2.moments(c)
        centroid = (m["m10"] / m["m00"], m["m01"] / m["m00"]) if m["m00"] else (ex, ey)
        ellipse_area = math.pi * d1 * d2 / 4.0
        if area >= 0.9 * ellipse_area:
            out.append(_Reported(centroid, "authentic", 1))
        else:
            out.append(_Reported(centroid, "merged", 2))
    return out


def _time(fn: Callable[[], object], repeats: int) -> tuple[list[float], object]:
    out = fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0) * 1000.0)
    return times, out


def _photo_table(plates: list[tuple[np.ndarray, PlateTruth]], repeats: int) -> None:
    """The same plates as 16-Mpixel photos (4480x3584, upscaled 3.5x): time and score."""
    header = f"{'16-Mpixel photo (4480x3584)':30s} {'median ms':>10s} {'p90 ms':>8s} {'found':>8s} "
    header += f"{'correct':>8s} {'FP':>4s}"
    print(header)
    print("-" * len(header))
    f = 3.5
    photos = [cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_CUBIC) for img, _ in plates]
    methods: list[tuple[str, Callable[[np.ndarray], list]]] = [
        ("analyze_plate", lambda img: analyze_plate(img).colonies),
        ("OpenCV baseline", baseline),
    ]
    for name, fn in methods:
        all_times: list[float] = []
        n = found = correct = fp = 0
        for photo, (_, truth) in zip(photos, plates, strict=True):
            times, colonies = _time(lambda photo=photo, fn=fn: fn(photo), repeats)
            all_times.extend(times)
            back = [  # positions back in the generated plate's pixels for scoring
                _Reported(((c.centroid[0] + 0.5) / f - 0.5, (c.centroid[1] + 0.5) / f - 0.5),
                          c.klass, c.estimated_count)
                for c in colonies  # type: ignore[attr-defined]
            ]  # fmt: skip
            score = score_plate(truth, back)  # type: ignore[arg-type]
            n, found, correct = n + score.n_truth, found + score.found, correct + score.correct
            fp += score.false_positives
        print(
            f"{name:30s} {np.median(all_times):10.2f} {np.percentile(all_times, 90):8.2f} "
            f"{100 * found / n:7.1f}% {100 * correct / n:7.1f}% {fp:4d}"
        )


def main() -> None:
    """Generate the plates, run every method and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plates", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=None, help="cv2.setNumThreads")
    args = ap.parse_args()
    process.configure()  # the kernels' threads and OpenMP's wait policy, as the CLI sets them
    if args.threads is not None:
        cv2.setNumThreads(args.threads)

    plates: list[tuple[np.ndarray, PlateTruth]] = [
        generate_plate(args.seed + i, agar=AGARS[i % len(AGARS)]) for i in range(args.plates)
    ]

    stages: dict[str, list[dict[str, float]]] = {}  # per method: stage_ms of every run

    def timed(name: str, img: np.ndarray, params: PlateParams | None) -> list:
        result = analyze_plate(img, params)
        stages.setdefault(name, []).append(result.stage_ms)
        return result.colonies

    def ours(
        name: str, params: PlateParams | None = None
    ) -> Callable[[np.ndarray, PlateTruth], list]:
        return lambda img, truth: timed(name, img, params)

    def ours_region(img: np.ndarray, truth: PlateTruth) -> list:
        (cx, cy), r = truth.dish.center, truth.dish.radius
        return timed("analyze_plate (region)", img, PlateParams(region=(cx, cy, r)))

    methods: list[tuple[str, Callable, int]] = [
        ("analyze_plate", ours("analyze_plate"), args.repeats),
        ("analyze_plate (region)", ours_region, args.repeats),
        (
            "analyze_plate (generic detector)",
            ours(
                "analyze_plate (generic detector)",
                PlateParams(method="detector", detector=DetectorParams(method="color")),
            ),
            max(args.repeats // 5, 1),
        ),
        ("OpenCV baseline", lambda img, truth: baseline(img), args.repeats),
    ]
    print(
        f"{len(plates)} plates of 1280x1024, {cv2.getNumThreads()} OpenCV threads, "
        f"{args.repeats} repeats (generic detector row: fewer)"
    )
    header = (
        f"{'method':30s} {'median ms':>10s} {'p90 ms':>8s} {'found':>8s} {'correct':>8s} "
        f"{'FP':>4s} {'merged n ok':>12s}"
    )
    print(header)
    print("-" * len(header))
    for name, fn, repeats in methods:
        all_times: list[float] = []
        n = found = correct = fp = count_ok = merged = 0
        for img, truth in plates:
            times, colonies = _time(lambda img=img, truth=truth, fn=fn: fn(img, truth), repeats)
            all_times.extend(times)
            score = score_plate(truth, colonies)  # type: ignore[arg-type]
            n += score.n_truth
            found += score.found
            correct += score.correct
            fp += score.false_positives
            count_ok += score.count_correct
            merged += score.n_merged_found
        print(
            f"{name:30s} {np.median(all_times):10.2f} {np.percentile(all_times, 90):8.2f} "
            f"{100 * found / n:7.1f}% {100 * correct / n:7.1f}% {fp:4d} "
            f"{count_ok:5d}/{merged:<6d}"
        )
    print("paper (Pentium IV 2 GHz, 1.3 Mpixel colour): 230 ms, ~98 % detection/classification")
    print()
    _photo_table(plates, max(args.repeats // 3, 2))
    print()
    names = list(next(iter(stages.values()))[0])
    header = f"{'stage medians, ms':30s} " + " ".join(f"{n:>9s}" for n in names)
    print(header)
    print("-" * len(header))
    for name, runs in stages.items():
        cells = " ".join(f"{np.median([r[n] for r in runs]):9.2f}" for n in names)
        print(f"{name:30s} {cells}")


if __name__ == "__main__":
    main()
