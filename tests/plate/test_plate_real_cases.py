"""Plate analysis on the generator's cases that real photographs showed (exact truth).

Crowding (over a thousand colonies), colonies down to 0.3 mm across, faint translucent
colonies, colonies at the meniscus, a dot-matrix label across the lid and a webcam's scale:
each case is drawn with ``generate_plate`` and scored against its exact truth. The limits leave
room for what the module docstrings name as misses; they fail when a case breaks.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from labauto.synthetic.plates import generate_plate, score_plate
from labauto.vision.plate import PlateParams, analyze_plate


def _score(**kwargs: object) -> tuple:
    img, truth = generate_plate(1, **kwargs)  # type: ignore[arg-type]
    result = analyze_plate(img)
    return truth, result, score_plate(truth, result.colonies)


def test_a_plate_of_over_a_thousand_colonies_is_counted_within_12_percent() -> None:
    # measured: 1098 colonies of 0.5-1.6 mm, 91.7 % found, counted 7.6 % short, 2 false;
    # with an opening of 1.2 mm rather than 0.75, 69 % found and 30 % short
    truth, result, score = _score(
        n_authentic=1150, n_merged=0, n_mixed=0, colony_scale=0.33, artefacts=False
    )
    n = truth.counts()["colonies_total"]
    assert n >= 1000  # the generator fits this many small colonies on the dish
    assert score.found >= 0.88 * n
    assert abs(result.counts["colonies_estimate"] - n) <= 0.12 * n
    assert score.false_positives <= 0.01 * n


def test_colonies_down_to_a_third_of_a_millimetre_are_found() -> None:
    # 60 colonies of 0.3-0.8 mm on each of four agars. Measured: 215 of 240 found, 43 of the
    # 58 under 0.4 mm, none false. An opening of 1 mm rather than 0.75 finds 191 in all; a
    # least colony of 0.4 mm rather than 0.3, 36 of those under 0.4 mm
    found, total, small, false = 0, 0, [0, 0], 0
    for agar in ("amber", "clear", "red_blood", "chocolate"):
        img, truth = generate_plate(
            2, n_authentic=60, n_merged=0, n_mixed=0, colony_scale=0.17, artefacts=False,
            agar=agar,
        )  # fmt: skip
        result = analyze_plate(img)
        false += score_plate(truth, result.colonies).false_positives
        centroids = [colony.centroid for colony in result.colonies]
        px_per_mm = 2 * truth.dish.radius / 90.0
        for colony in truth.colonies:
            outline = colony.contour.astype(np.float32).reshape(-1, 1, 2)
            hit = any(cv2.pointPolygonTest(outline, c, False) >= 0 for c in centroids)
            found += hit
            total += 1
            if 2 * math.sqrt(colony.area_px / math.pi) < 0.4 * px_per_mm:
                small[0] += hit
                small[1] += 1
    assert total == 240 and found >= 0.85 * total
    assert small[1] >= 40 and small[0] >= 0.65 * small[1]
    assert false == 0


def test_faint_translucent_colonies_are_found() -> None:
    _, _, score = _score(faint_fraction=1.0)
    assert score.found >= 0.85 * score.n_truth
    assert score.artefacts_reported == 0


def test_colonies_touching_the_meniscus_are_found() -> None:
    _, _, score = _score(n_meniscus=8)
    assert score.n_truth == 38  # 30 as usual and 8 cut by the agar's edge
    assert score.found >= 34
    assert score.artefacts_reported == 0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_dot_matrix_label_across_the_lid_is_not_reported(seed: int) -> None:
    img, truth = generate_plate(seed, lid_label=True)
    score = score_plate(truth, analyze_plate(img).colonies)
    assert any(a.kind == "lid-label" for a in truth.artefacts)
    assert score.artefacts_reported == 0
    assert score.found >= 28  # of 30; a colony under the label may go with it


@pytest.mark.parametrize(("width", "height"), [(800, 640), (3200, 2560)])
def test_webcam_and_photo_scales(width: int, height: int) -> None:
    _, _, score = _score(width=width, height=height)
    assert score.found >= 28
    assert score.false_positives <= 2


def test_large_translucent_colonies_come_from_the_faint_pass() -> None:
    # 3-8 grey levels of contrast, 3-8 mm across: below eq. 1's threshold, as on the AGAR photos
    found = {True: 0, False: 0}
    for seed in (1, 2, 3):
        img, truth = generate_plate(
            seed,
            agar="amber",
            faint_fraction=1.0,
            faint_contrast=0.08,
            colony_scale=1.6,
            n_merged=0,
            n_mixed=0,
            artefacts=False,
        )
        for faint in (True, False):
            # the ring pass off in both: it finds some of these colonies by their edge
            params = PlateParams(faint_factor=4.0 if faint else 0.0, find_rings=False)
            score = score_plate(truth, analyze_plate(img, params).colonies)
            assert score.false_positives == 0
            found[faint] += score.found
    # measured: 46 against 0 of 60, of which the search in the hue (the deviation across the
    # grey axis) finds 39: searching the full deviation alone found 7. Before the generator
    # drew a translucent colony's shading and highlight at its contrast too, they departed
    # from the agar by ~25 levels and eq. 1 found 51 of these
    assert found[True] >= found[False] + 35
