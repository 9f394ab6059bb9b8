"""Ellipse fitting: time per fit and accuracy on noisy arcs, against OpenCV in the same run.

Run: ``.venv/bin/python benchmarks/bench_ellipse_fit.py [--seeds N] [--quick]``

Tables printed:

1. time per fit (median of repeats, microseconds) for full noisy ellipses of 100-1000 points:
   our algebraic (Halir-Flusser), geometric (Ahn, seeded by the algebraic), robust (RANSAC and
   bootstrap), the batched algebraic per contour, and cv2.fitEllipse / fitEllipseAMS /
   fitEllipseDirect as the baseline;
2. the detector's budget case: 40 DES of 200 points each, geometric fits one by one, and the
   batched algebraic seeds; then the detector's real batches: the DES of ``make_scene`` scenes
   (about 100 contours, 10,000 points) with the detector's ``max_iter`` and ``tol``, fitted as
   ``detect`` does (``fit_selected_ellipses`` on the whole contour set) and gathered first;
3. accuracy on arcs (360, 180, 120 degrees) with Gaussian noise (sigma 0.5 and 1 px) for a
   1:1.7 and a 1:4 ellipse: mean centre error and mean largest semi-axis error over the seeds.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable

import cv2
import numpy as np

from labauto.synthetic.shapes import make_scene
from labauto.vision import detector
from labauto.vision.ellipse import Ellipse
from labauto.vision.ellipse_fit import (
    fit_ellipse_algebraic,
    fit_ellipse_geometric,
    fit_ellipse_robust,
    fit_ellipses_algebraic_batch,
    fit_ellipses_geometric_batch,
    fit_selected_ellipses,
)


def per_call_us(func: Callable[[], object], min_time: float = 0.05, repeats: int = 7) -> float:
    """Median over ``repeats`` of the mean time of a batch of calls lasting ~``min_time`` s."""
    func()
    n, elapsed = 1, 0.0
    while True:
        start = time.perf_counter()
        for _ in range(n):
            func()
        elapsed = time.perf_counter() - start
        if elapsed >= min_time:
            break
        n *= 2
    times = [elapsed / n]
    for _ in range(repeats - 1):
        start = time.perf_counter()
        for _ in range(n):
            func()
        times.append((time.perf_counter() - start) / n)
    return 1e6 * statistics.median(times)


def cv2_method(name: str) -> Callable[[np.ndarray], Ellipse]:
    fitter = getattr(cv2, name)

    def fit(points: np.ndarray) -> Ellipse:
        (cx, cy), (w, h), angle = fitter(points.astype(np.float32))
        return Ellipse.normalised(cx, cy, w / 2, h / 2, angle)

    return fit


METHODS: dict[str, Callable[[np.ndarray], Ellipse]] = {
    "algebraic": fit_ellipse_algebraic,
    "geometric": lambda p: fit_ellipse_geometric(p).ellipse,
    "cv2.fitEllipse": cv2_method("fitEllipse"),
    "cv2.fitEllipseAMS": cv2_method("fitEllipseAMS"),
    "cv2.fitEllipseDirect": cv2_method("fitEllipseDirect"),
}


def timing_table(quick: bool) -> None:
    truth = Ellipse((300.0, 200.0), (80.0, 50.0), 25.0)
    gen = np.random.default_rng(0)
    sizes = (100, 200) if quick else (100, 200, 500, 1000)
    print("\n1. Time per fit, microseconds (full ellipse 80x50 px, sigma 0.3 px; median of 7)")
    head = (
        "points",
        "algebraic",
        "geometric",
        "iters",
        "ransac",
        "bootstrap",
        "alg batch/contour",
        "geo batch/contour",
        "cv2.fitEllipse",
        "cv2 AMS",
        "cv2 Direct",
        "geo/cv2",
    )
    print(" | ".join(f"{h:>9s}" for h in head))
    for n in sizes:
        pts = truth.sample(n) + gen.normal(0, 0.3, (n, 2))
        f32 = pts.astype(np.float32)
        batch = np.concatenate([pts] * 40)
        offsets = np.arange(41) * n
        geo = per_call_us(lambda pts=pts: fit_ellipse_geometric(pts))
        cv = per_call_us(lambda f32=f32: cv2.fitEllipse(f32))
        ransac = per_call_us(lambda pts=pts: fit_ellipse_robust(pts), 0.2, 3)
        boot = per_call_us(lambda pts=pts: fit_ellipse_robust(pts, method="bootstrap"), 0.2, 3)
        alg_batch = per_call_us(lambda b=batch, o=offsets: fit_ellipses_algebraic_batch(b, o))
        geo_batch = per_call_us(lambda b=batch, o=offsets: fit_ellipses_geometric_batch(b, o))
        row = (
            f"{n:>9d}",
            f"{per_call_us(lambda pts=pts: fit_ellipse_algebraic(pts)):9.0f}",
            f"{geo:9.0f}",
            f"{fit_ellipse_geometric(pts).iterations:9d}",
            f"{ransac:9.0f}",
            f"{boot:9.0f}",
            f"{alg_batch / 40:9.1f}",
            f"{geo_batch / 40:9.1f}",
            f"{cv:9.1f}",
            f"{per_call_us(lambda f32=f32: cv2.fitEllipseAMS(f32)):9.1f}",
            f"{per_call_us(lambda f32=f32: cv2.fitEllipseDirect(f32)):9.1f}",
            f"{geo / cv:9.1f}",
        )
        print(" | ".join(row))


def budget_table() -> None:
    gen = np.random.default_rng(1)
    contours = []
    for _ in range(40):
        a = gen.uniform(15, 40)
        e = Ellipse(
            (gen.uniform(50, 1200), gen.uniform(50, 900)),
            (a, a * gen.uniform(0.5, 1)),
            gen.uniform(0, 180),
        )
        contours.append(e.sample(200) + gen.normal(0, 0.3, (200, 2)))
    allpts = np.concatenate(contours)
    offsets = np.arange(41) * 200
    seeds = [Ellipse.normalised(*row) for row in fit_ellipses_algebraic_batch(allpts, offsets)]

    def one_by_one() -> None:
        for c in contours:
            fit_ellipse_geometric(c)

    def batch_seeded() -> None:
        rows = fit_ellipses_algebraic_batch(allpts, offsets)
        for c, row in zip(contours, rows, strict=True):
            fit_ellipse_geometric(c, Ellipse.normalised(*row))

    def batch_geometric() -> None:
        fit_ellipses_geometric_batch(allpts, offsets)

    def cv2_all() -> None:
        for c in contours:
            cv2.fitEllipse(c.astype(np.float32))

    assert len(seeds) == 40
    print("\n2. Detector budget: 40 DES x 200 points (paper: ~40 objects per 1.3 Mpx image)")
    print(f"{'what':>46s} | {'ms':>8s}")
    for name, func in (
        ("40 geometric fits, algebraic seed each", one_by_one),
        ("batched algebraic seeds + 40 geometric fits", batch_seeded),
        ("fit_ellipses_geometric_batch (all 40 at once)", batch_geometric),
        ("40 batched algebraic fits only", lambda: fit_ellipses_algebraic_batch(allpts, offsets)),
        ("40 cv2.fitEllipse (baseline)", cv2_all),
    ):
        print(f"{name:>46s} | {per_call_us(func, 0.2, 5) / 1000:8.2f}")


def scene_batches(n_scenes: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The (points, offsets, DES mask) that ``detect`` passes to its fit, one per scene."""
    batches = []
    fit = detector.fit_selected_ellipses

    def capture(points: np.ndarray, offsets: np.ndarray, selected: np.ndarray, **kwargs) -> list:
        batches.append((np.array(points), np.array(offsets), np.array(selected)))
        return fit(points, offsets, selected, **kwargs)

    detector.fit_selected_ellipses = capture
    try:
        for seed in range(n_scenes):
            detector.detect(make_scene(np.random.default_rng(seed))[0])
    finally:
        detector.fit_selected_ellipses = fit
    return batches


def scene_table(n_scenes: int) -> None:
    batches = scene_batches(n_scenes)
    print(
        f"\n   detector batches: DES of {n_scenes} make_scene scenes, algebraic seeds and "
        f"max_iter={detector.FIT_MAX_ITER}, tol={detector.FIT_TOL}; fit_selected_ellipses on the "
        "whole contour set (as detect), and fit_ellipses_geometric_batch of the gathered DES"
    )
    print(
        f"{'contours':>9s} | {'points':>7s} | {'selected median ms':>18s} | {'min ms':>7s} | "
        f"{'gathered median ms':>18s} | {'min ms':>7s}"
    )
    kwargs = {"max_iter": detector.FIT_MAX_ITER, "tol": detector.FIT_TOL}
    for points, offsets, selected in batches:
        counts = np.diff(offsets)
        des_points = points[np.repeat(selected, counts)]
        des_offsets = np.concatenate(([0], np.cumsum(counts[selected])))
        times: dict[str, list[float]] = {"selected": [], "gathered": []}
        for _ in range(50):  # interleaved
            start = time.perf_counter()
            fit_selected_ellipses(points, offsets, selected, **kwargs)
            times["selected"].append(time.perf_counter() - start)
            start = time.perf_counter()
            fit_ellipses_geometric_batch(des_points, des_offsets, **kwargs)
            times["gathered"].append(time.perf_counter() - start)
        sel, gat = times["selected"], times["gathered"]
        print(
            f"{len(des_offsets) - 1:9d} | {len(des_points):7d} | "
            f"{1e3 * statistics.median(sel):18.3f} | {1e3 * min(sel):7.3f} | "
            f"{1e3 * statistics.median(gat):18.3f} | {1e3 * min(gat):7.3f}"
        )


def accuracy_table(seeds: int) -> None:
    print(
        f"\n3. Accuracy on arcs: mean centre error / mean max semi-axis error, px ({seeds} seeds,"
        " 150 points on a random arc)"
    )
    head = ("ellipse", "arc", "sigma", *METHODS, "geo iters")
    print(" | ".join(f"{h:>20s}" if i >= 3 else f"{h:>8s}" for i, h in enumerate(head)))
    for axes in ((60.0, 35.0), (80.0, 20.0)):
        truth = Ellipse((200.0, 150.0), axes, 20.0)
        for arc in (360.0, 180.0, 120.0):
            for sigma in (0.5, 1.0):
                gen = np.random.default_rng(int(arc * 10 + sigma * 100 + axes[1]))
                errs = {name: [] for name in METHODS}
                iters = []
                for _ in range(seeds):
                    start = gen.uniform(0, 2 * math.pi)
                    pts = truth.sample(150, start, start + math.radians(arc))
                    pts = pts + gen.normal(0, sigma, pts.shape)
                    for name, fit in METHODS.items():
                        e = fit(pts)
                        errs[name].append(
                            (
                                math.dist(e.center, truth.center),
                                max(abs(e.axes[0] - axes[0]), abs(e.axes[1] - axes[1])),
                            )
                        )
                    iters.append(fit_ellipse_geometric(pts).iterations)
                cells = []
                best = min(np.mean(v, axis=0)[0] for v in errs.values())
                for name in METHODS:
                    c, a = np.mean(errs[name], axis=0)
                    mark = "*" if c == best else " "
                    cells.append(f"{c:8.3f} / {a:8.3f}{mark}")
                label = f"{axes[0]:.0f}x{axes[1]:.0f}"
                print(
                    " | ".join(
                        (
                            f"{label:>8s}",
                            f"{arc:8.0f}",
                            f"{sigma:8.1f}",
                            *cells,
                            f"{np.mean(iters):20.1f}",
                        )
                    )
                )
    print("  (* lowest mean centre error in the row)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100, help="random arcs per accuracy row")
    parser.add_argument("--quick", action="store_true", help="fewer sizes and 20 seeds")
    args = parser.parse_args()
    print(f"numpy {np.__version__}, OpenCV {cv2.__version__}")
    timing_table(args.quick)
    budget_table()
    scene_table(2 if args.quick else 6)
    accuracy_table(20 if args.quick else args.seeds)


if __name__ == "__main__":
    main()
