"""Does each compiled kernel earn its place? Compiled against the plain path, same inputs, one run.

For every kernel of :mod:`labauto.vision.kernels` the stage of ``detect`` it accelerates is timed
on both backends (``labauto.vision.kernels.use``) on the same 1280x1024 colour scenes
(``labauto.synthetic.shapes.make_scene``), the backends taking turns within each repeat so that
a slow spell of a shared machine hits both alike:

* ``gradient``: the colour gradient (eq. 2), ``color_gradient``;
* ``edges``: edge linking with sub-pixel refinement, ``edge_contours`` (on the same Canny map);
* ``shape``: the shape labels (Table 1 descriptors and the polar series, eq. 4);
* ``ellipse_fit``: the geometric ellipse fits of the DES;
* ``shape_angle`` (plain only: its kernel was removed): D_alpha (eq. 3).

Then the user-visible times on both backends: ``detect`` (labels and fits) per scene and
``analyze_plate`` per synthetic 1280x1024 plate. The last column is what the kernel earns: how many
times slower ``detect`` (kernels on) would be with this one stage on the plain path. The kernels run
on the threads the command line would use (``labauto.cli.process.configure``: one per CPU,
``OMP_WAIT_POLICY=PASSIVE``).

Run: ``python benchmarks/bench_kernels.py [--seeds N] [--plates N] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import cv2
import numpy as np

from labauto.cli import process
from labauto.synthetic.plates import generate_plate
from labauto.synthetic.shapes import make_scene
from labauto.vision import detector, edges, kernels
from labauto.vision.contours import Contours
from labauto.vision.detector import DetectorParams, detect
from labauto.vision.gradient import color_gradient
from labauto.vision.plate import analyze_plate
from labauto.vision.shape_angle import shape_angles


def stages(image: np.ndarray, params: DetectorParams) -> dict[str, Callable[[], object]]:
    """The kernel-backed stages of ``detect(image, params)`` on its own intermediate results."""
    gx, gy = color_gradient(image, params.blur_sigma)
    edge_map = edges.canny_edges(gx, gy, params.canny_low, params.canny_high)
    found = edges.edge_contours(
        edge_map, gx, gy, params.min_contour_length, params.max_contour_length, params.subpixel
    )
    contours = Contours(*found)
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    des = angles.is_des(params.des_threshold_deg, params.statistic, params.max_gap_fraction)
    d_alpha = angles.statistic(params.statistic)
    return {
        "gradient": lambda: color_gradient(image, params.blur_sigma),
        "edges": lambda: edges.edge_contours(
            edge_map, gx, gy, params.min_contour_length, params.max_contour_length, True
        ),
        "shape": lambda: detector._labels(
            contours, d_alpha, angles.centroid_inside, angles.centroid, params
        ),
        "ellipse_fit": lambda: detector._fits(contours, des, params),
        "shape_angle": lambda: shape_angles(
            contours.points, contours.gradients, contours.offsets, contours.closed
        ),
    }


def timed(fn: Callable[[], object], backend: str) -> float:
    kernels.use(backend)
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def race(fns: dict[str, Callable[[], object]], backends: tuple[str, ...], repeats: int):
    """Median seconds of each function on each backend, the runs interleaved."""
    samples = {(name, b): [] for name in fns for b in backends}
    for fn in fns.values():
        for b in backends:
            timed(fn, b)  # warm-up
    for _ in range(repeats):
        for name, fn in fns.items():
            for b in backends:
                samples[name, b].append(timed(fn, b))
    return {key: float(np.median(v)) for key, v in samples.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--plates", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    process.configure()
    if not kernels.built():
        raise SystemExit("no compiled kernels are built: nothing to compare")
    both = ("compiled", "plain")
    params = DetectorParams()
    per_stage: dict[tuple[str, str], list[float]] = {}
    per_detect: dict[str, list[float]] = {b: [] for b in both}
    for seed in range(args.seeds):
        image = make_scene(np.random.default_rng(seed), noise=4.0)[0]
        kernels.use("compiled")
        fns = stages(image, params)
        fns["detect"] = lambda image=image: detect(image, params)
        for key, seconds in race(fns, both, args.repeats).items():
            per_stage.setdefault(key, []).append(seconds)
    plates = [generate_plate(seed, agar="clear")[0] for seed in range(args.plates)]
    per_plate = {b: [] for b in both}
    for plate in plates:
        result = race({"plate": lambda plate=plate: analyze_plate(plate)}, both, args.repeats)
        for b in both:
            per_plate[b].append(result["plate", b])
    for b in both:
        per_detect[b] = per_stage.pop(("detect", b))

    def ms(values: list[float]) -> float:
        return 1e3 * float(np.median(values))

    print(
        f"{args.seeds} scenes and {args.plates} plates of 1280x1024, {args.repeats} repeats, "
        f"{kernels.threads()} kernel threads, cv2.getNumThreads() = {cv2.getNumThreads()}, "
        f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}"
    )
    kernels.use("compiled")
    print(kernels.describe())
    header = f"{'kernel':12s} {'compiled ms':>12s} {'plain ms':>10s} {'speed-up':>9s}"
    header += f" {'detect without it':>18s}"
    print(header)
    print("-" * len(header))
    detect_compiled = ms(per_detect["compiled"])
    for name in ("gradient", "edges", "shape", "ellipse_fit", "shape_angle"):
        plain = ms(per_stage[name, "plain"])
        if name in kernels.built():
            compiled = ms(per_stage[name, "compiled"])
            slower = (detect_compiled + plain - compiled) / detect_compiled
            speed_up = plain / compiled
            print(f"{name:12s} {compiled:12.2f} {plain:10.2f} {speed_up:8.1f}x {slower:17.2f}x")
        else:
            print(f"{name:12s} {'(removed)':>12s} {plain:10.2f}")
    print()
    for label, values in (("detect", per_detect), ("analyze_plate", per_plate)):
        compiled, plain = ms(values["compiled"]), ms(values["plain"])
        print(f"{label:14s} compiled {compiled:8.2f} ms   plain {plain:8.2f} ms   "
              f"({plain / compiled:.2f}x)")  # fmt: skip


if __name__ == "__main__":
    main()
