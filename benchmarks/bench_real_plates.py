"""Plate analysis on real photographs with ground truth (``../shared/realplates``).

Two sets, scored as ``realplates/README.md`` says:

* ``agar-boxes``: AGAR photographs with a box per colony (YOLO labels). A reported body of
  estimated count k matches up to k unmatched truth boxes whose centres lie inside its contour
  (2 px tolerance) or whose box holds its centroid, nearest first (one greedy pass over all
  body-box pairs of a plate, nearest first). Precision = matched / reported colonies, recall =
  matched / truth colonies, F1 from both, summed over all plates. ``1399.jpg`` has no labels
  and is left out. Picking: of the colonies classed ``authentic`` (the ones offered for
  picking), how many hold the centres of two or more truth boxes inside their contour (a pick
  would take a mix) and how many hold none (not a boxed colony). The boxes not matched are
  given by cause, with the plates that have most: the dish was not found, the centre lies
  beyond the dish found, inside a body counted short, or in no reported body (by the box's
  size: 4 mm and over, 2-4 mm, under 2 mm); and the recall by how far inside the dish's edge
  the boxes lie (within 2 mm, 2-4 mm, farther): the colonies at the meniscus.
* ``phone-counts``: phone photographs counted by hand; the count error of a plate is
  ``|colonies_estimate - truth| / truth``. Six plates carry a note that smaller colonies were
  not counted (their truth is short by an unknown amount): the totals are given over all
  plates and again over those counted whole.

For both sets the table gives every plate and the totals: median count error over the plates and
how many are over 15 %. The images are read by ``cv2.imread`` (EXIF orientation applied). Run:
``python benchmarks/bench_real_plates.py [--data DIR] [--set agar-boxes|phone-counts] [--only ID
...] [--camera-scale PX_PER_MM] [--param NAME=VALUE ...] [--perturb NAME[:VALUE]] [--shifts N]``.
``--camera-scale`` first resamples every photo (area averaging, or bilinear up) so that its dish is
at that scale, as a webcam would see it; ``--param`` sets a ``PlateParams`` field for the run (its
value read as YAML), to measure a change of a default. ``--shifts N`` scores the sets N times, the
k-th time with every photo cut by k pixels at its top and left (the boxes moved with it): a plate
does not lie at the same pixel twice, and the spread of the totals over these runs is how much of a
difference between two versions is the analysis's own jitter (the per-plate tables are printed for
the first run only). The data are development data, not part of labauto; without them the script
says where it looked and stops (exit status 2 when ``--data`` named the folder, 0 when the default
place is simply absent, so ``make bench`` goes on).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from photo_perturb import Perturbation, parse

from labauto.vision.dish import find_dish
from labauto.vision.plate import PlateParams, PlateResult, analyze_plate

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "realplates"


@dataclass
class BoxScore:
    """Per-plate matching result of the agar-boxes scoring."""

    reported: int
    truth: int
    matched: int
    offered: int = 0  # colonies classed authentic
    offered_multi: int = 0  # of them, holding two or more truth centres
    offered_empty: int = 0  # of them, holding none
    missed: dict[str, int] = field(default_factory=dict)  # unmatched truth boxes by cause
    # truth boxes and those matched, by how far their centre lies inside the dish's edge
    by_edge: dict[str, tuple[int, int]] = field(default_factory=dict)


@dataclass(frozen=True)
class RunOptions:
    """How the photos are analysed: ``params`` (None: the defaults), resampled to
    ``camera_scale`` px/mm first when given, changed by ``perturb`` when given, and cut by
    ``shift`` pixels at the top and left."""

    params: PlateParams | None = None
    camera_scale: float | None = None
    perturb: Perturbation | None = None
    shift: int = 0  # pixels cut at the photo's top and left (after the perturbation)
    rows: bool = True  # print a row per plate


def read_boxes(label_file: Path, width: int, height: int) -> np.ndarray:
    """YOLO boxes of a label file as ``(x0, y0, x1, y1)`` rows in image pixels."""
    rows = []
    for line in label_file.read_text().split("\n"):
        parts = line.split()
        if len(parts) != 5:
            continue
        _, xc, yc, bw, bh = map(float, parts)
        rows.append(
            ((xc - bw / 2) * width, (yc - bh / 2) * height,
             (xc + bw / 2) * width, (yc + bh / 2) * height)
        )  # fmt: skip
    return np.asarray(rows, float).reshape(-1, 4)


def score_boxes(result: PlateResult, boxes: np.ndarray, tolerance_px: float = 2.0) -> BoxScore:
    """Match a plate's reported colonies to its truth boxes (module docstring)."""
    centres = np.column_stack(((boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2))
    pairs: list[tuple[float, int, int]] = []
    held = np.zeros(len(result.colonies), int)  # truth centres inside each contour
    for b, colony in enumerate(result.colonies):
        cx, cy = colony.centroid
        contour = np.asarray(colony.contour, np.float32).reshape(-1, 1, 2)
        x0, y0 = contour[:, 0].min(axis=0) - tolerance_px
        x1, y1 = contour[:, 0].max(axis=0) + tolerance_px
        holds_centroid = (
            (boxes[:, 0] <= cx) & (cx <= boxes[:, 2]) & (boxes[:, 1] <= cy) & (cy <= boxes[:, 3])
        )
        near = (centres[:, 0] >= x0) & (centres[:, 0] <= x1)
        near &= (centres[:, 1] >= y0) & (centres[:, 1] <= y1)
        for t in np.flatnonzero(near | holds_centroid):
            inside = cv2.pointPolygonTest(contour, tuple(map(float, centres[t])), True)
            held[b] += inside >= 0
            if inside >= -tolerance_px or holds_centroid[t]:
                pairs.append((float(np.hypot(*(centres[t] - (cx, cy)))), b, int(t)))
    pairs.sort()
    capacity = [c.estimated_count for c in result.colonies]
    taken = np.zeros(len(boxes), bool)
    matched = 0
    for _, b, t in pairs:
        if capacity[b] > 0 and not taken[t]:
            capacity[b] -= 1
            taken[t] = True
            matched += 1
    offered = held[[c.klass == "authentic" for c in result.colonies]]
    inside_mm = _inside_edge_mm(result, boxes)
    return BoxScore(
        result.counts["colonies_estimate"],
        len(boxes),
        matched,
        len(offered),
        int(np.sum(offered >= 2)),
        int(np.sum(offered == 0)),
        missed_causes(result, boxes, ~taken, inside_mm),
        recall_by_edge(inside_mm, taken),
    )


MISSED = (
    "plate not analysed",
    "beyond the dish found",
    "inside a body counted short",
    "in no body, 4 mm and over",
    "in no body, 2-4 mm",
    "in no body, under 2 mm",
)


EDGE_BANDS = ((2.0, "within 2 mm"), (4.0, "2-4 mm"), (math.inf, "farther"))


def _px_per_mm(result: PlateResult) -> float:
    """The scale read from the dish found (its diameter is ``dish_diameter_mm``)."""
    return 2.0 * result.dish.radius / PlateParams().dish_diameter_mm


def _inside_edge_mm(result: PlateResult, boxes: np.ndarray) -> np.ndarray:
    """How far inside the dish's edge found each box's centre lies, in mm (negative beyond)."""
    (cx, cy), r = result.dish.center, result.dish.radius
    x, y = (boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2
    return (r - np.hypot(x - cx, y - cy)) / _px_per_mm(result)


def recall_by_edge(inside_mm: np.ndarray, matched: np.ndarray) -> dict[str, tuple[int, int]]:
    """``(truth boxes, matched)`` by how far inside the dish's edge found a box's centre lies
    (``inside_mm``, :func:`_inside_edge_mm`; ``EDGE_BANDS``, beyond the edge counting as
    within 2 mm): colonies at the meniscus are the rim model's and the usable area's business."""
    limits = [limit for limit, _ in EDGE_BANDS]
    band = np.searchsorted(limits, inside_mm, side="right")
    return {
        name: (int(np.sum(band == i)), int(np.sum(matched[band == i])))
        for i, (_, name) in enumerate(EDGE_BANDS)
    }


def missed_causes(
    result: PlateResult, boxes: np.ndarray, missed: np.ndarray, inside_mm: np.ndarray
) -> dict[str, int]:
    """The unmatched truth boxes (``missed``) by cause (``MISSED[1:]``): where the box's centre
    lies (``inside_mm``: how far inside the dish's edge, :func:`_inside_edge_mm`), and for one
    in no reported body, the box's size (the root of its area) in mm at the scale read from the
    dish found."""
    px_per_mm = _px_per_mm(result)
    contours = [np.asarray(c.contour, np.float32).reshape(-1, 1, 2) for c in result.colonies]
    causes: Counter[str] = Counter()
    for (x0, y0, x1, y1), inside in zip(boxes[missed], inside_mm[missed], strict=True):
        x, y = (x0 + x1) / 2, (y0 + y1) / 2
        size_mm = float(np.sqrt((x1 - x0) * (y1 - y0))) / px_per_mm
        if inside < 0:
            cause = MISSED[1]
        elif any(cv2.pointPolygonTest(c, (float(x), float(y)), False) >= 0 for c in contours):
            cause = MISSED[2]
        else:
            cause = MISSED[3] if size_mm >= 4.0 else MISSED[4] if size_mm >= 2.0 else MISSED[5]
        causes[cause] += 1
    return dict(causes)


def _f1(p: float, r: float) -> float:
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def _read(path: Path, camera_scale: float | None) -> np.ndarray | None:
    """The photo, resampled so that its dish is at ``camera_scale`` px/mm when one is given."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None or not camera_scale:
        return image
    try:
        px_per_mm = 2.0 * find_dish(image).radius / PlateParams().dish_diameter_mm
    except ValueError:
        return image  # no dish: the analysis reports it
    f = camera_scale / px_per_mm
    return cv2.resize(
        image, None, fx=f, fy=f, interpolation=cv2.INTER_AREA if f < 1 else cv2.INTER_LINEAR
    )


def shifted(image: np.ndarray, boxes: np.ndarray, shift: int) -> tuple[np.ndarray, np.ndarray]:
    """The photo without its top and left ``shift`` pixels (the plate moved up and left), and
    its boxes ``(x0, y0, x1, y1)`` moved with it."""
    if shift <= 0:
        return image, boxes
    return image[shift:, shift:], boxes - shift


def _analyze(
    image: np.ndarray | None, params: PlateParams | None
) -> tuple[PlateResult | None, float, str]:
    if image is None:
        return None, 0.0, "unreadable"
    t0 = time.perf_counter()
    try:
        result = analyze_plate(image, params)
    except ValueError as exc:
        return None, (time.perf_counter() - t0) * 1000, str(exc)
    return result, (time.perf_counter() - t0) * 1000, ""


def run_agar_boxes(folder: Path, only: set[str], options: RunOptions) -> dict[str, Any]:
    """Score the agar-boxes set; print one row per plate and the totals, and return them
    (with ``counts``: the colonies reported per plate)."""
    print(f"agar-boxes ({folder})" + (f", shifted {options.shift} px" if options.shift else ""))
    header = f"{'plate':>8s} {'size':>10s} {'truth':>6s} {'found':>6s} {'matched':>8s} "
    header += f"{'P':>5s} {'R':>5s} {'count err':>9s} {'picks':>5s} {'2+':>3s} {'ms':>7s}"
    if options.rows:
        print(header)
        print("-" * len(header))
    totals = [0, 0, 0, 0, 0, 0]
    errors, times = [], []
    counts: dict[str, int] = {}  # colonies reported per plate
    missed: dict[str, Counter[str]] = {cause: Counter() for cause in MISSED}
    by_edge: dict[str, list[int]] = {name: [0, 0] for _, name in EDGE_BANDS}
    for image_path in sorted((folder / "images").glob("*.jpg"), key=lambda p: int(p.stem)):
        label = folder / "labels" / f"{image_path.stem}.txt"
        if not label.exists() or (only and image_path.stem not in only):
            continue
        image = _read(image_path, options.camera_scale)
        h, w = image.shape[:2]
        boxes = read_boxes(label, w, h)
        if options.perturb is not None:
            image = options.perturb.image(image)
            boxes = options.perturb.boxes(boxes, w, h)
        image, boxes = shifted(image, boxes, options.shift)
        result, ms, why = _analyze(image, options.params)
        if result is None:
            score = BoxScore(0, len(boxes), 0, missed={MISSED[0]: len(boxes)})
        else:
            score = score_boxes(result, boxes)
        err = abs(score.reported - score.truth) / score.truth
        errors.append(err)
        counts[image_path.stem] = score.reported
        times.append(ms)
        row = (score.reported, score.truth, score.matched)
        for i, v in enumerate((*row, score.offered, score.offered_multi, score.offered_empty)):
            totals[i] += v
        for cause, n in score.missed.items():
            missed[cause][image_path.stem] += n
        for name, (n_truth, n_matched) in score.by_edge.items():
            by_edge[name][0] += n_truth
            by_edge[name][1] += n_matched
        p = score.matched / score.reported if score.reported else 0.0
        r = score.matched / score.truth
        if not options.rows:
            continue
        print(
            f"{image_path.stem:>8s} {w:>4d}x{h:<5d} {score.truth:6d} {score.reported:6d} "
            f"{score.matched:8d} {p:5.2f} {r:5.2f} {100 * err:8.1f}% {score.offered:5d} "
            f"{score.offered_multi:3d} {ms:7.0f}" + (f"  ({why})" if why else "")
        )
    reported, truth, matched, offered, multi, empty = totals
    p = matched / reported if reported else 0.0
    r = matched / truth if truth else 0.0
    summary = {"precision": p, "recall": r, "f1": _f1(p, r), **_count_summary(errors, times)}
    summary["counts"] = counts
    print(
        f"total: {summary['plates']} plates, {truth} colonies, {reported} reported, {matched} "
        f"matched: precision {p:.3f}, recall {r:.3f}, F1 {summary['f1']:.3f}; "
        + _count_line(summary)
    )
    print(
        f"picking: {offered} colonies offered (authentic), {multi} holding two or more boxed "
        f"colonies, {empty} holding none"
    )
    print(f"not matched: {truth - matched} boxed colonies")
    for cause, plates in missed.items():
        if plates:
            worst = ", ".join(f"{stem} {n}" for stem, n in plates.most_common(6))
            print(f"  {cause}: {sum(plates.values())} ({worst})")
    bands = ", ".join(
        f"{name} {n_matched}/{n_truth} ({n_matched / max(n_truth, 1):.2f})"
        for name, (n_truth, n_matched) in by_edge.items()
    )
    print(f"recall by distance inside the dish's edge: {bands}")
    return summary


def _count_summary(errors: list[float], times: list[float]) -> dict[str, float]:
    return {
        "plates": len(errors),
        "median_count_error": float(np.median(errors)) if errors else float("nan"),
        "over_15": sum(e > 0.15 for e in errors),
        "max_ms": max(times, default=0.0),
    }


def _count_line(summary: dict[str, float]) -> str:
    return (
        f"median count error {100 * summary['median_count_error']:.1f} %, "
        f"{summary['over_15']} plates over 15 %; slowest {summary['max_ms']:.0f} ms"
    )


def run_phone_counts(folder: Path, only: set[str], options: RunOptions) -> dict[str, Any]:
    """Score the phone-counts set; print one row per plate and the totals, and return them
    (with ``counts``: the colonies reported per plate)."""
    print(f"phone-counts ({folder})" + (f", shifted {options.shift} px" if options.shift else ""))
    header = f"{'plate':>9s} {'size':>10s} {'truth':>6s} {'found':>6s} {'count err':>9s} {'ms':>7s}"
    if options.rows:
        print(header)
        print("-" * len(header))
    errors, times, complete = [], [], []
    counts: dict[str, int] = {}  # colonies reported per plate
    with open(folder / "counts.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:
        stem = Path(row["image"]).stem
        if only and stem not in only:
            continue
        truth = int(row["human_count_total_CFU"])
        image = _read(folder / "images" / row["image"], options.camera_scale)
        if image is not None and options.perturb is not None:
            image = options.perturb.image(image)
        if image is not None:
            image, _ = shifted(image, np.zeros((0, 4)), options.shift)
        result, ms, why = _analyze(image, options.params)
        found = result.counts["colonies_estimate"] if result is not None else 0
        err = abs(found - truth) / truth
        errors.append(err)
        counts[stem] = found
        times.append(ms)
        complete.append("not counted" not in row.get("note", ""))
        if not options.rows:
            continue
        size = f"{result.width}x{result.height}" if result is not None else "-"
        note = f"  [{row['note']}]" if row.get("note") else ""
        print(
            f"{stem:>9s} {size:>10s} {truth:6d} {found:6d} {100 * err:8.1f}% {ms:7.0f}"
            + (f"  ({why})" if why else "")
            + note
        )
    summary = {**_count_summary(errors, times), "counts": counts}
    print(f"total: {summary['plates']} plates: " + _count_line(summary))
    # a note that smaller colonies were not counted makes the truth short by an unknown amount
    counted = _count_summary([e for e, c in zip(errors, complete, strict=True) if c], times)
    print(
        f"of them counted whole (no note that smaller colonies were left out): "
        f"{counted['plates']} plates: " + _count_line(counted).split(";")[0]
    )
    return summary


def plate_params(settings: list[str]) -> PlateParams | None:
    """``PlateParams`` with the ``NAME=VALUE`` settings (values read as YAML); None for none."""
    if not settings:
        return None
    fields = {}
    for setting in settings:
        name, sep, value = setting.partition("=")
        if not sep or not name:
            raise ValueError(f"--param takes NAME=VALUE, got {setting!r}")
        fields[name.strip()] = yaml.safe_load(value)
    try:
        return PlateParams(**fields)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--param {' '.join(settings)}: {exc}") from None


def main() -> int:
    """Score the sets found under ``--data``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None, help=f"default: {DEFAULT_DATA}")
    ap.add_argument("--set", choices=("agar-boxes", "phone-counts"), action="append")
    ap.add_argument("--only", nargs="*", default=[], help="image stems to score")
    ap.add_argument(
        "--camera-scale",
        type=float,
        default=None,
        metavar="PX_PER_MM",
        help="resample every photo so that its dish is at this scale (a webcam: 4-8)",
    )
    ap.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a PlateParams field to set (a YAML value), e.g. --param rim_margin_mm=0",
    )
    ap.add_argument(
        "--perturb",
        default=None,
        metavar="NAME[:VALUE]",
        help="change every photo first: rot90, flip, gain:K, gamma:G, wb:B,G,R, jpeg:Q, noise:S",
    )
    ap.add_argument(
        "--shifts",
        type=int,
        default=1,
        metavar="N",
        help="score N times, the k-th with every photo cut by k px at its top and left",
    )
    args = ap.parse_args()
    if args.shifts < 1:
        ap.error(f"--shifts takes a count of 1 or more, got {args.shifts}")
    try:
        options = RunOptions(
            plate_params(args.param),
            args.camera_scale,
            parse(args.perturb) if args.perturb else None,
        )
    except (TypeError, ValueError) as exc:
        ap.error(str(exc))
    sets = args.set or ["agar-boxes", "phone-counts"]
    data = args.data or DEFAULT_DATA
    missing = [s for s in sets if not (data / s).is_dir()]
    if missing:
        print(
            f"bench_real_plates: no real plate data at {data} (missing {', '.join(missing)}); "
            "pass --data DIR pointing at a folder with agar-boxes/ and phone-counts/",
            file=sys.stderr,
        )
        return 2 if args.data else 0  # the default place may simply not exist on this machine
    args.data = data
    only = set(args.only)
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in sets}
    for shift in range(args.shifts):
        run = replace(options, shift=shift, rows=shift == 0)
        for name in sets:
            score = run_agar_boxes if name == "agar-boxes" else run_phone_counts
            runs[name].append(score(args.data / name, only, run))
            print()
    if args.shifts > 1:
        print_spread(runs)
    return 0


def print_spread(runs: dict[str, list[dict[str, Any]]]) -> None:
    """Mean, least and largest of each set's totals over the shifted runs."""
    keys = {  # summary key: label, scale, digits
        "precision": ("precision", 1.0, 3),
        "recall": ("recall", 1.0, 3),
        "f1": ("F1", 1.0, 3),
        "median_count_error": ("median count error %", 100.0, 1),
        "over_15": ("plates over 15 %", 1.0, 1),
    }
    print(f"over {len(next(iter(runs.values())))} shifts (mean, least - largest):")
    for name, summaries in runs.items():
        parts = []
        for key, (label, scale, digits) in keys.items():
            if key not in summaries[0]:
                continue
            values = np.array([summary[key] for summary in summaries]) * scale
            parts.append(
                f"{label} {values.mean():.{digits}f} ({values.min():.{digits}f} - "
                f"{values.max():.{digits}f})"
            )
        print(f"  {name}: " + "; ".join(parts))
        # how far each plate's count moves between the runs
        plates = summaries[0]["counts"]
        spread = {stem: [summary["counts"][stem] for summary in summaries] for stem in plates}
        moved = sorted(spread.items(), key=lambda item: max(item[1]) - min(item[1]), reverse=True)
        worst = ", ".join(f"{stem} {min(c)}-{max(c)}" for stem, c in moved[:5])
        total = sum(max(c) - min(c) for c in spread.values())
        changed = sum(max(c) > min(c) for c in spread.values())
        print(
            f"    counts moved on {changed} of {len(spread)} plates, by {total} colonies "
            f"(largest count less least, summed); most: {worst}"
        )


if __name__ == "__main__":
    sys.exit(main())
