"""The vectorised per-object stages of plate analysis against plain per-body references.

``analyze_plate`` measures all bodies on one shared canvas and computes mixed-colony scores and
merged counts for all bodies at once. These tests keep the straightforward per-body versions
(one crop per body, one body at a time) as references and require the same numbers, exactly.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from labauto.vision import dish as dish_module
from labauto.vision import (
    plate_area,
    plate_bodies,
    plate_canvas,
    plate_cores,
    plate_counts,
    plate_mixed,
    plate_objects,
)
from labauto.vision.plate import PlateParams, analyze_plate
from labauto.vision.plate_background import deviation

PAD = plate_bodies.PAD
DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


def _reference_body(contour: np.ndarray, fg: np.ndarray, params: PlateParams) -> dict | None:
    """Mask, distance transform and waist of one body in its own crop (None if a stroke)."""
    x, y, bw, bh = cv2.boundingRect(contour)
    shift = np.array([x - PAD, y - PAD], np.int32)
    filled = np.zeros((bh + 2 * PAD, bw + 2 * PAD), np.uint8)
    cv2.drawContours(filled, [contour - shift], -1, 1, -1)
    mask = filled & (fg[y - PAD : y + bh + PAD, x - PAD : x + bw + PAD] > 0)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, DISC5)
    # holes under HOLE_SHARE of the filled contour are part of the body
    n, holes = cv2.connectedComponents((filled > mask).astype(np.uint8), connectivity=4)
    for label in range(1, n):
        if np.count_nonzero(holes == label) < plate_bodies.HOLE_SHARE * filled.sum():
            mask[holes == label] = 1
    dt = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    r_in = float(dt.max())
    area = float(np.count_nonzero(mask))
    if area > params.max_fill_ratio * math.pi * r_in * r_in:
        return None
    hull = np.zeros_like(mask)
    cv2.fillConvexPoly(hull, cv2.convexHull(contour) - shift, 1)
    pocket = hull > mask
    depth = float(cv2.distanceTransform(hull, cv2.DIST_L2, 3)[pocket].max()) if pocket.any() else 0
    return {
        "bbox": (x, y, bw, bh),
        "mask": mask,
        "dt": dt,
        "area": area,
        "r_in": r_in,
        "concavity": depth / max(r_in, 1.0),
    }


def _reference_count_dt(ref: dict, round_outline: bool) -> np.ndarray:
    """The distance transform step 5 counts on: of the mask with every hole filled when the
    outline is a DES (holes: background not 4-connected to the crop's border)."""
    if not round_outline:
        return ref["dt"]
    mask = ref["mask"].copy()
    n, background = cv2.connectedComponents((mask == 0).astype(np.uint8), connectivity=4)
    edges = (background[0], background[-1], background[:, 0], background[:, -1])
    border = set(np.unique(np.concatenate(edges)).tolist())
    for label in range(1, n):
        if label not in border:
            mask[background == label] = 1
    return cv2.distanceTransform(mask, cv2.DIST_L2, 3)


def _reference_merged_count(dt: np.ndarray, valley_ratio: float, least_peak: float = 0.0) -> int:
    """Step 5 on one body's crop, peak after peak."""
    peak_max = float(dt.max())
    dil = cv2.dilate(dt, DISC5)
    cand = ((dt >= dil) & (dt >= max(2.0, least_peak, 0.3 * peak_max))).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(cand, connectivity=8)
    peaks = []
    for i in range(1, n):
        x, y, bw, bh = stats[i, :4]
        sub = np.where(labels[y : y + bh, x : x + bw] == i, dt[y : y + bh, x : x + bw], -1.0)
        j = int(np.argmax(sub))
        peaks.append((x + j % bw, y + j // bw, float(sub.flat[j])))
    peaks.sort(key=lambda p: -p[2])
    kept: list[tuple[int, int, float]] = []
    for px, py, pv in peaks:
        separate = True
        for qx, qy, qv in kept:
            m = int(math.hypot(px - qx, py - qy)) + 2
            lx = np.linspace(px, qx, m).round().astype(np.intp)
            ly = np.linspace(py, qy, m).round().astype(np.intp)
            if dt[ly, lx].min() >= valley_ratio * min(pv, qv):
                separate = False
                break
        if separate:
            kept.append((px, py, pv))
    return max(plate_counts.MIN_MERGED_COUNT, len(kept))


def _reference_mix_score(roi: np.ndarray, body: dict, params: PlateParams) -> float:
    """Step 4's mixed-colony score of one body on its own."""
    x, y, bw, bh = body["bbox"]
    dt = body["dt"][::2, ::2]
    inner = dt >= params.edge_skip_px
    c = roi[y - PAD : y + bh + PAD : 2, x - PAD : x + bw + PAD : 2][inner].astype(np.float32)
    if len(c) < 8:
        return 0.0
    s = dt[inner] * np.float32(1.0 / max(body["r_in"], 1e-6))
    s2 = s * s
    feats = (np.ones_like(s), s, s2, s2 * s, s2 * s2)
    sums = [float(np.sum(f.astype(np.float64))) for f in feats]
    gram = np.array([sums[i : i + 3] for i in range(3)]) + np.eye(3) * 1e-6
    rhs = np.array([[np.sum((feats[i] * c[:, ch]).astype(np.float64)) for ch in range(3)]
                    for i in range(3)])  # fmt: skip
    coef = np.linalg.solve(gram, rhs).astype(np.float32)
    resid = c - (coef[0] + s[:, None] * coef[1] + s2[:, None] * coef[2])
    return float(np.mean(np.einsum("ij,ij->i", resid, resid) > params.mix_residual**2))


def _with_translucent_centres(img: np.ndarray, truth: object) -> np.ndarray:
    """``img`` with an agar-coloured centre painted into every authentic colony: a radius of
    0.25 of the colony's (a hole of ~6 %, filled by the analysis) or, every third, 0.6 (~36 %,
    left open; a ring, dropped as a stroke), or, every third but one, 0.4 a tenth of the
    radius off the centre (~16 %; where neither the ring pass nor the line opening closes or
    opens it, a DES-shaped body whose count is taken with its hole filled)."""
    out = img.copy()
    agar = tuple(int(v) for v in np.median(img[img.shape[0] // 2 - 40 : img.shape[0] // 2 + 40,
                                               img.shape[1] // 2 - 40 : img.shape[1] // 2 + 40]
                                           .reshape(-1, 3), axis=0))  # fmt: skip
    authentic = [c for c in truth.colonies if c.kind == "authentic"]  # type: ignore[attr-defined]
    for i, colony in enumerate(authentic):
        r = np.sqrt(colony.area_px / np.pi)
        share, off = ((0.25, 0.0), (0.4, 0.1), (0.6, 0.0))[i % 3]
        centre = (round(colony.center[0] + off * r), round(colony.center[1]))
        cv2.circle(out, centre, max(round(share * r), 2), agar, -1)
    return out


@pytest.fixture(scope="module")
def stages(plates: list) -> list[tuple]:
    """For three plates, and the first with translucent centres (holes): the ROI, contours,
    foreground, D_alpha test and measured bodies."""
    out = []
    images = [img for img, _ in plates[:3]] + [_with_translucent_centres(*plates[0])]
    for img in images:
        # bodies at the usable border dropped: the crops then fit without the analysis' margin
        _, copy, params, (x0, y0), usable, _ = plate_area.prepare_plate(
            img, PlateParams(drop_at_border=True)
        )
        roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
        found = plate_objects.objects_by_segmentation(
            roi, usable, params, plate_objects.agar_background(roi, usable, params)
        )
        contours, fg = found.contours, found.foreground
        des_shape = found.inside & (found.d_alpha < params.des_threshold_deg)
        bodies = plate_bodies.measure_bodies(contours, fg, des_shape, params, found.rejected)
        out.append((roi, contours, fg, des_shape, bodies, params))
    return out


def test_canvas_measures_equal_per_crop_measures(stages: list) -> None:
    for _, contours, fg, des_shape, bodies, params in stages:
        assert len(bodies.index) > 20
        for b, k in enumerate(bodies.index):
            ref = _reference_body(contours[k], fg, params)
            assert bodies.stroke[b] == (ref is None)
            if ref is None:
                continue
            rows = slice(bodies.row[b], bodies.row[b] + bodies.height[b])
            cols = slice(0, bodies.width[b])
            np.testing.assert_array_equal(bodies.mask[rows, cols], ref["mask"])
            np.testing.assert_array_equal(bodies.dt[rows, cols], ref["dt"])
            assert bodies.area[b] == ref["area"] and bodies.r_in[b] == ref["r_in"]
            if des_shape[k]:
                assert bodies.concavity[b] == ref["concavity"]
            else:
                assert bodies.concavity[b] == math.inf  # not needed: never a DES


def test_bodies_measured_band_by_band_equal_one_band(
    stages: list, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a band for nearly every crop, against one band for the whole canvas: the same bodies
    for _, contours, fg, des_shape, _, params in stages:
        measured = []
        for waste in (0, 10**12):
            monkeypatch.setattr(plate_canvas, "_BAND_WASTE", waste)
            measured.append(plate_bodies.measure_bodies(contours, fg, des_shape, params, {}))
        banded, whole = measured
        monkeypatch.setattr(plate_canvas, "_BAND_WASTE", 0)
        slot = banded.slot
        assert len(plate_canvas.bands_of(banded.row, slot, banded.width, slot.sum())) > 10
        for name in ("mask", "dt", "area", "r_in", "stroke", "concavity"):
            np.testing.assert_array_equal(getattr(banded, name), getattr(whole, name))


@pytest.mark.parametrize(("least_peak", "widest"), [(0.0, True), (6.0, True), (0.0, False)])
def test_vectorised_mix_scores_and_merged_counts_equal_per_body(
    stages: list, least_peak: float, widest: bool
) -> None:
    # without the widest body the two stages work on a canvas cut to the others' width
    floored = 0  # bodies whose count the floor changed: the floor must be exercised
    filled = 0  # DES-shaped bodies with holes, counted filled: the path must be exercised
    for roi, contours, fg, des_shape, bodies, params in stages:
        everyone = ~bodies.stroke
        if not widest:
            everyone &= bodies.width < bodies.width[everyone].max()
        round_outline = des_shape[bodies.index]
        scores, _ = plate_mixed.mix_scores(roi, bodies, everyone, params)
        counts = plate_counts.merged_counts(
            bodies, everyone, params.valley_ratio, least_peak, round_outline
        )
        for b, k in enumerate(bodies.index):
            if not everyone[b]:
                assert scores[b] == 0.0 and counts[b] == 1
                continue
            ref = _reference_body(contours[k], fg, params)
            assert scores[b] == pytest.approx(_reference_mix_score(roi, ref, params), abs=1e-12)
            dt = _reference_count_dt(ref, bool(round_outline[b]))
            expected = _reference_merged_count(dt, params.valley_ratio, least_peak)
            assert counts[b] == expected
            floored += expected != _reference_merged_count(dt, params.valley_ratio)
            filled += bool(np.any(dt != ref["dt"]))
    assert (floored > 0) == (least_peak > 0)
    assert filled > 0


def _reference_cores(departure: np.ndarray, ref: dict, single_r: float, least_range: float) -> int:
    """The most round cores over the levels of one body, in its own crop (plate_cores)."""
    mask, (x, y, _, _) = ref["mask"], ref["bbox"]
    left, top = x - PAD, y - PAD
    h, w = mask.shape
    sigma = max(plate_cores._SIGMA_RATIO * single_r, 0.5)
    distance = cv2.GaussianBlur(cv2.sqrt(departure), (0, 0), sigma)[top : top + h, left : left + w]
    values = np.sort(distance[mask > 0])
    picks = np.floor(np.linspace(0.05, 0.95, plate_cores._LEVELS) * (values.size - 1))
    levels = values[picks.astype(np.intp)]
    if levels[-1] - levels[0] < least_range:
        return 0
    least_area = math.pi * (plate_cores._CORE_RADIUS_RATIO * single_r) ** 2
    best = 0
    for level in levels:
        above = ((distance > level) & (mask > 0)).astype(np.uint8)
        stats = cv2.connectedComponentsWithStats(above, connectivity=8)[2]
        cores = 0
        for _, _, cw, ch, area in stats[1:]:
            fills = area >= plate_cores._CORE_FILL * math.pi / 4 * cw * ch
            squat = min(cw, ch) >= plate_cores._CORE_ASPECT * max(cw, ch)
            cores += bool(area >= least_area and fills and squat)
        best = max(best, cores)
    return best


@pytest.mark.parametrize("band_waste", [None, 0])
def test_core_counts_on_the_canvas_equal_per_body(
    plates: list, band_waste: int | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # with the bands as they come, and with a band for every crop (labelled one by one)
    if band_waste is not None:
        monkeypatch.setattr(plate_canvas, "_BAND_WASTE", band_waste)
    split = 0  # bodies with two or more cores: the counting must be exercised
    for img, _ in plates[:3]:
        _, copy, params, (x0, y0), usable, _ = plate_area.prepare_plate(
            img, PlateParams(drop_at_border=True)
        )
        roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
        found = plate_objects.objects_by_segmentation(
            roi, usable, params, plate_objects.agar_background(roi, usable, params)
        )
        des_shape = found.inside & (found.d_alpha < params.des_threshold_deg)
        bodies = plate_bodies.measure_bodies(
            found.contours, found.foreground, des_shape, params, found.rejected
        )
        assert found.departure is not None
        single_r = float(np.median(bodies.r_in[des_shape[bodies.index] & ~bodies.stroke]))
        everyone = ~bodies.stroke
        for least_range in (0.0, 12.0):
            counts = plate_cores.core_counts(
                bodies, found.departure, everyone, single_r, least_range
            )
            for b, k in enumerate(bodies.index):
                ref = _reference_body(found.contours[k], found.foreground, params)
                big = ref is not None and ref["area"] >= 2 * math.pi * (0.35 * single_r) ** 2
                expected = (
                    _reference_cores(found.departure, ref, single_r, least_range)
                    if everyone[b] and big
                    else 0
                )
                assert counts[b] == expected
                split += expected >= 2
    assert split > 0


def test_unit_weight_deviation_equals_the_weighted_formula(plates: list) -> None:
    img, _ = plates[4]
    _, copy, params, (x0, y0), usable, _ = plate_area.prepare_plate(img, PlateParams())
    roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
    background = plate_objects.agar_background(roi, usable, params)
    fast = deviation(roi, background, (1.0, 1.0, 1.0))  # the channel-by-channel path
    diff = roi.astype(np.float32) - background.astype(np.float32)
    np.testing.assert_array_equal(fast, (diff * diff).sum(axis=2))  # the formula, in full
    halved = deviation(roi, background, (0.5, 0.5, 0.5))  # the weighted (LUT) path
    np.testing.assert_allclose(halved, fast / 2, rtol=1e-6)


def test_fit_circle_is_exact_on_a_circle_far_from_the_origin() -> None:
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    cx, cy, r = dish_module._fit_circle(900.25 + 410.5 * np.cos(t), 700.75 + 410.5 * np.sin(t))
    assert (cx, cy, r) == pytest.approx((900.25, 700.75, 410.5), abs=1e-9)


def test_stage_times_are_reported(plates: list) -> None:
    result = analyze_plate(plates[0][0])
    assert list(result.stage_ms) == ["dish", "objects", "measures", "classes"]
    assert all(v >= 0 for v in result.stage_ms.values())
    assert sum(result.stage_ms.values()) <= result.timing_ms + 1e-6
    assert "stage_ms" not in result.to_dict()
