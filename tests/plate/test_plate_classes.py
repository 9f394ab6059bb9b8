"""What is offered for picking is one colony: bodies of two colonies are never authentic."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from labauto.vision import plate_bodies, plate_mixed
from labauto.vision.plate import PlateParams, analyze_plate

AGAR_BGR = (120, 180, 205)
COLONY_BGR = (60, 110, 170)


def _agar_with(discs: list[tuple[float, float, float]], ellipses=()) -> np.ndarray:
    """A 600 px agar square (10 px/mm) with dark discs ``(x, y, r)`` and ellipses, sensor noise."""
    img = np.zeros((600, 600, 3), np.uint8)
    img[:] = AGAR_BGR
    for x, y, r in discs:
        cv2.circle(
            img, (round(x * 16), round(y * 16)), round(r * 16), COLONY_BGR, -1, cv2.LINE_AA, 4
        )
    for centre, axes, angle in ellipses:
        cv2.ellipse(img, centre, axes, angle, 0, 360, COLONY_BGR, -1, cv2.LINE_AA)
    noise = np.random.default_rng(0).normal(0.0, 2.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def _analyse(img: np.ndarray) -> list:
    return _analyse_with(img)


def _analyse_with(img: np.ndarray, **params: float) -> list:
    plate = PlateParams(region=(300.0, 300.0, 290.0), px_per_mm=10.0, **params)  # type: ignore[arg-type]
    return sorted(analyze_plate(img, plate).colonies, key=lambda c: c.centroid[0])


@pytest.mark.parametrize(("gap", "count"), [(20, 1), (32, 2)])
def test_two_colonies_that_overlap_are_merged_not_authentic(gap: int, count: int) -> None:
    # a round colony beside two of radius 20 px whose centres are ``gap`` px apart: at 20 px the
    # waist is too shallow for the concavity test and the distance transform shows one peak
    # (the body was read authentic before the elongation limit), at 32 px two peaks; with one
    # single colony on the plate there is no yardstick to count the one-peak body as two
    colonies = _analyse(_agar_with([(150, 300, 20), (400, 300, 20), (400 + gap, 300, 20)]))
    assert [c.klass for c in colonies] == ["authentic", "merged"]
    assert [c.estimated_count for c in colonies] == [1, count]


@pytest.mark.parametrize(("axes", "klass"), [((22, 19), "authentic"), ((26, 16), "merged")])
def test_authentic_colonies_are_round(axes: tuple[int, int], klass: str) -> None:
    # 1:1.16 is a colony; 1:1.6 is no colony seen on the real plates: doubtful, not offered
    (colony,) = _analyse(_agar_with([], [((300, 300), axes, 30.0)]))
    assert colony.klass == klass
    assert colony.estimated_count == 1


def test_a_long_one_peak_body_as_large_as_the_plates_colonies_counts_two() -> None:
    singles = [(120, 150, 20), (120, 450, 20), (480, 450, 20)]
    pair = [(400, 300, 20), (420, 300, 20)]  # one distance-transform peak, axis ratio ~1.4
    small = [(250, 150, 9), (259, 150, 9)]  # as long, but smaller than a single colony
    colonies = _analyse(_agar_with(singles + pair + small))
    by_place = {(round(c.centroid[0] / 10), round(c.centroid[1] / 10)): c for c in colonies}
    assert [by_place[(12, 15)].klass, by_place[(48, 45)].klass] == ["authentic", "authentic"]
    assert (by_place[(41, 30)].klass, by_place[(41, 30)].estimated_count) == ("merged", 2)
    assert (by_place[(25, 15)].klass, by_place[(25, 15)].estimated_count) == ("merged", 1)
    off = _analyse_with(_agar_with(singles + pair + small), pair_elongation=0.0)
    assert sum(c.estimated_count for c in off) == sum(c.estimated_count for c in colonies) - 1


def test_a_thin_crescent_beside_large_colonies_is_no_colony() -> None:
    # a beaded arc 12-15 px wide (a piece of a large colony that the rim's background cut
    # away, as on AGAR plate 4904) beside colonies of radius 40 px: no point of it is as far
    # from its outline as 0.3 of theirs (12 px), and it is long, so it is a sliver, not
    # reported; a small round colony (radius 8 px) is as thin but round, and stays
    singles = [(120, 150, 40), (120, 450, 40), (480, 450, 40)]
    arc = [
        (400 + 30 * math.cos(math.radians(a)), 250 + 30 * math.sin(math.radians(a)), 7.5 - i % 2)
        for i, a in enumerate(range(0, 100, 25))
    ]
    img = _agar_with([*singles, *arc, (250, 300, 8)])
    plate = PlateParams(region=(300.0, 300.0, 290.0), px_per_mm=10.0)
    result = analyze_plate(img, plate)
    assert result.rejected.get("sliver") == 1
    assert sorted(round(c.centroid[0]) for c in result.colonies) == [120, 120, 250, 480]
    # kept as a body, its bumps are peaks of the distance transform and the straight segments
    # between them leave the curved body: the plate's yardstick counts it one, not several
    counts = [c.estimated_count for c in _analyse_with(img, sliver_elongation=0.0)]
    assert counts == [1, 1, 1, 1, 1]
    no_floor = _analyse_with(img, sliver_elongation=0.0, peak_floor_ratio=0.0)
    assert max(c.estimated_count for c in no_floor) >= 3


def test_a_colony_with_a_translucent_centre_is_one_colony(monkeypatch: pytest.MonkeyPatch) -> None:
    # a colony of radius 40 px whose centre (radius 7 px, 3 % of it) is the agar's colour
    img = _agar_with([(300.0, 300.0, 40.0)])
    cv2.circle(img, (300, 300), 7, AGAR_BGR, -1, cv2.LINE_AA)
    (colony,) = _analyse(img)
    assert colony.estimated_count == 1
    assert colony.klass in ("authentic", "mixed")  # a DES (the dome test sees two colours)
    # without the hole filled, the body reads as a loop of ink and is dropped
    monkeypatch.setattr("labauto.vision.plate_bodies.HOLE_SHARE", 0.0)
    assert [c.estimated_count for c in _analyse(img)] != [1]


def test_a_ring_with_a_wide_hole_is_not_reported() -> None:
    # the same with a hole of radius 24 px (36 %): a loop of ink, not a colony
    img = _agar_with([(300.0, 300.0, 40.0)])
    cv2.circle(img, (300, 300), 24, AGAR_BGR, -1, cv2.LINE_AA)
    assert _analyse(img) == []


def test_a_chain_of_colonies_along_a_streak_is_counted_not_taken_for_a_stroke() -> None:
    # seven colonies of radius 20 px touching along a bent streak (an arc of radius 60 px):
    # their body is larger than five inscribed discs (the stroke test), yet as wide as the
    # plate's colonies; a zigzag pen line 1 mm wide in the same colour stays a stroke
    singles = [(150, 450, 20), (300, 480, 20), (450, 450, 20)]
    step = 36 / 60  # radians between neighbours: centres 36 px apart
    chain = [(200 + 60 * math.cos(k * step), 200 + 60 * math.sin(k * step), 20) for k in range(7)]
    img = _agar_with(singles + chain)
    pen = np.array([[360, 180], [470, 220], [380, 270], [480, 330]], np.int32)
    cv2.polylines(img, [pen], False, COLONY_BGR, 10, cv2.LINE_AA)

    def analysed(**params: float):
        plate = PlateParams(region=(300.0, 300.0, 290.0), px_per_mm=10.0, **params)  # type: ignore[arg-type]
        return analyze_plate(img, plate)

    result = analysed()
    assert result.rejected.get("stroke") == 1  # the pen line
    merged = [c for c in result.colonies if c.klass == "merged"]
    assert len(merged) == 1 and merged[0].estimated_count == 7
    assert sum(c.estimated_count for c in result.colonies) == 10
    off = analysed(chain_ratio=0.0)
    assert off.rejected.get("stroke") == 2
    assert sum(c.estimated_count for c in off.colonies) == 3


def test_a_round_colony_with_a_wide_translucent_centre_counts_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # a colony of radius 40 px with a patch of the agar's colour in it (radius 15 px, 14 % of
    # it: not filled as a small hole; 14 px off the centre, as the translucent part of the
    # colony of AGAR plate 14130), beside three single colonies: round the hole the distance
    # transform has a ring of peaks, and the body was counted as four colonies (the ring pass,
    # which would fill this hole as a ring colony of its own, is off)
    singles = [(120, 150, 30), (120, 450, 30), (480, 450, 30)]
    img = _agar_with([*singles, (400.0, 220.0, 40.0)])
    cv2.circle(img, (386, 220), 15, AGAR_BGR, -1, cv2.LINE_AA)

    def largest():  # the holed colony
        return max(_analyse_with(img, find_rings=False), key=lambda c: c.area_px)

    assert largest().klass == "merged"  # the hole is a pocket as deep as a waist: not offered
    assert largest().estimated_count == 1
    # counted on the body as it is, the ring of peaks reads as two colonies or more
    monkeypatch.setattr("labauto.vision.plate_counts.holes_filled", lambda mask, *_: mask)
    assert largest().estimated_count >= 2


def test_a_printed_character_touching_a_colony_is_not_counted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # a bold dotted character (11 dots of radius 10 px, grey: every channel at 45 % of the
    # agar's) on the lid, seen across a colony of radius 30 px that it touches: one body, the
    # colony's colour too much of it to be ink, and each dot a peak of the distance transform
    singles = [(120, 150, 20), (120, 450, 20), (480, 450, 20)]
    img = _agar_with([*singles, (280.0, 260.0, 30.0)])
    ink = tuple(round(0.45 * v) for v in AGAR_BGR)
    for k in range(11):
        a = math.radians(180 + 30 * k)
        centre = (round(352 + 38 * math.cos(a)), round(260 + 38 * math.sin(a)))
        cv2.circle(img, centre, 10, ink, -1, cv2.LINE_AA)

    def body():  # the colony with the character
        return max(_analyse(img), key=lambda c: c.area_px)

    assert body().klass == "merged"
    assert body().estimated_count == 1  # the character's pixels left out of the count
    monkeypatch.setattr("labauto.vision.plate_ink.INK_SHARE", 2.0)  # never left out
    assert body().estimated_count >= 8


@pytest.mark.parametrize("spot_mm", [plate_mixed.SPOT_MM, 0.0])
def test_a_small_colony_on_a_large_one_is_mixed(
    monkeypatch: pytest.MonkeyPatch, spot_mm: float
) -> None:
    # a pale colony 0.8 mm across near the edge of one 8 mm across: 1 % of it, far below the
    # outlier fraction, yet a second species in the pick; a pale arc (a ring of the colony's
    # own texture) as large in area is no second colony
    monkeypatch.setattr(plate_mixed, "SPOT_MM", spot_mm)
    img = _agar_with([(150.0, 300.0, 40.0), (420.0, 300.0, 40.0)])
    pale = (150, 200, 230)
    cv2.circle(img, (175, 290), 4, pale, -1, cv2.LINE_AA)
    cv2.ellipse(img, (420, 300), (28, 28), 0, 200, 300, pale, 2, cv2.LINE_AA)
    spotted, ringed = _analyse(img)
    assert ringed.klass == "authentic"
    assert spotted.klass == ("mixed" if spot_mm > 0 else "authentic")
    assert spotted.mix_score < 0.06  # the fraction alone would offer it


@pytest.mark.parametrize("large_ratio", [plate_mixed.LARGE_BODY_RATIO, math.inf])
def test_small_colonies_on_a_large_one_are_counted(
    monkeypatch: pytest.MonkeyPatch, large_ratio: float
) -> None:
    # two pale colonies 0.8 mm across on an irregular colony 9 mm across (a disc with a lobe:
    # no DES, one peak), beside three single colonies 3 mm across: the large body holds three
    # colonies. A colony as large with no spot on it counts one.
    monkeypatch.setattr("labauto.vision.plate.LARGE_BODY_RATIO", large_ratio)
    singles = [(100, 120, 15), (100, 480, 15), (500, 480, 15)]
    img = _agar_with([*singles, (300.0, 250.0, 45.0), (335.0, 220.0, 20.0), (470.0, 330.0, 45.0)])
    pale = (150, 200, 230)
    for spot in ((280, 240), (310, 280)):
        cv2.circle(img, spot, 4, pale, -1, cv2.LINE_AA)
    spotted = min(_analyse(img), key=lambda c: math.dist(c.centroid, (305, 245)))
    plain = min(_analyse(img), key=lambda c: math.dist(c.centroid, (470, 330)))
    assert spotted.klass == "merged"
    assert spotted.estimated_count == (3 if math.isfinite(large_ratio) else 1)
    assert spotted.mix_score == 0.0  # the mixed score is a DES's alone
    assert plain.estimated_count == 1


def test_a_lone_grey_dot_the_opening_erased_is_counted_but_not_offered() -> None:
    # 0.5 mm across, 20 grey levels darker in every channel (no hue, lets 88 % of the light
    # through): narrower than the 0.75 mm opening, it comes back as a lone dot, a doubtful
    # colony: counted as one, never authentic. The large colony beside it is authentic.
    img = _agar_with([(200, 300, 30)])
    cv2.circle(img, (420, 300), 2, (100, 160, 185), -1, cv2.LINE_AA)
    dot, colony = sorted(_analyse(img), key=lambda c: -c.centroid[0])
    assert abs(dot.centroid[0] - 420) < 2 and abs(dot.centroid[1] - 300) < 2
    assert (dot.klass, dot.estimated_count) == ("merged", 1)
    assert colony.klass == "authentic"


def _agar_with_domes(discs: list[tuple[float, float, float]]) -> np.ndarray:
    """A 600 px agar square (10 px/mm) with dome-shaded colonies ``(x, y, r)``: darkest at
    their centres, fading to the agar at their edges (where they overlap, the deeper one shows),
    sensor noise."""
    yy, xx = np.mgrid[0:600, 0:600].astype(np.float32)
    shade = np.zeros((600, 600), np.float32)
    for x, y, r in discs:
        d = np.hypot(xx - x, yy - y) / r
        shade = np.maximum(shade, np.clip(1.0 - d * d, 0.0, 1.0) ** 0.25)
    agar, colony = np.float32(AGAR_BGR), np.float32(COLONY_BGR)
    img = agar + shade[..., None] * (colony - agar)
    img += np.random.default_rng(0).normal(0.0, 2.0, img.shape)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def test_a_clump_without_waists_counts_its_colonies_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    # three domes of radius 20 px, their centres 28 px apart (0.7 of a diameter): the outline
    # is no DES, yet its distance transform has a single peak; above a level of the departure
    # the clump falls apart into three round cores (plate_cores)
    singles = [(120, 150, 20), (120, 450, 20), (480, 450, 20)]
    clump = [(380, 280, 20), (408, 280, 20), (394, 280 + 14 * math.sqrt(3), 20)]
    img = _agar_with_domes(singles + clump)

    def clump_class_and_count() -> tuple[str, int]:
        (body,) = [c for c in _analyse(img) if c.centroid[0] > 300 and c.centroid[1] < 400]
        return body.klass, body.estimated_count

    assert clump_class_and_count() == ("merged", 3)
    assert [c.estimated_count for c in _analyse(img) if c.klass == "authentic"] == [1, 1, 1]

    def no_cores(bodies: plate_bodies.Bodies, *_: object) -> np.ndarray:
        return np.zeros(len(bodies.index), np.intp)

    monkeypatch.setattr("labauto.vision.plate.core_counts", no_cores)
    assert clump_class_and_count() == ("merged", 1)
