"""Scoring a plate analysis against a synthetic plate's truth (:func:`score_plate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from labauto.synthetic.plate_truth import PlateTruth

__all__ = ["PlateScore", "score_plate"]


@dataclass(frozen=True)
class PlateScore:
    """How well a list of reported colonies matches a plate's truth.

    Attributes
    ----------
    n_truth : int
        Colonies (bodies) in the truth.
    found : int
        Truth colonies matched by a reported colony.
    correct : int
        Matched colonies whose class equals the truth's kind.
    count_correct, n_merged_found : int
        Merged bodies found as merged whose estimated count equals the truth count, and merged
        bodies found as merged.
    false_positives : int
        Reported colonies that match no truth colony.
    artefacts_reported : int
        False positives that lie on an artefact.
    confusion : dict
        ``{(truth kind, reported class): n}``, with ``"missed"`` as the reported class.
    """

    n_truth: int
    found: int
    correct: int
    count_correct: int
    n_merged_found: int
    false_positives: int
    artefacts_reported: int
    confusion: dict[tuple[str, str], int]


def score_plate(truth: PlateTruth, colonies: list[Any], scale: float = 1.0) -> PlateScore:
    """Match reported colonies to the truth and count what was found and classified right.

    A reported colony (anything with ``centroid``, ``klass`` and ``estimated_count``) matches
    the truth colony whose outline contains its centroid, or, failing that, the nearest truth
    centre within half the truth's equivalent radius; each truth colony is matched at most once.
    ``scale``: the colonies were reported on the plate resampled by this factor (as
    ``cv2.resize(image, None, fx=scale, fy=scale)``); their centroids are mapped back first.
    """
    polys = [c.contour.astype(np.float32).reshape(-1, 1, 2) for c in truth.colonies]
    used: set[int] = set()
    found = correct = count_ok = merged_found = fp = art = 0
    confusion: dict[tuple[str, str], int] = {}
    for col in colonies:
        # pixel centres: x in the resampled image is at (x + 0.5) / scale - 0.5 in the plate's
        x = (float(col.centroid[0]) + 0.5) / scale - 0.5
        y = (float(col.centroid[1]) + 0.5) / scale - 0.5
        match = None
        for i, (tc, poly) in enumerate(zip(truth.colonies, polys, strict=True)):
            if i in used:
                continue
            if cv2.pointPolygonTest(poly, (x, y), False) >= 0 or math.hypot(
                x - tc.center[0], y - tc.center[1]
            ) <= 0.5 * math.sqrt(tc.area_px / math.pi):
                match = i
                break
        if match is None:
            fp += 1
            for a in truth.artefacts:
                pts = a.points.reshape(-1, 2)
                if np.min(np.hypot(pts[:, 0] - x, pts[:, 1] - y)) < 25.0 or (
                    a.kind in ("label", "lid-label")
                    and cv2.pointPolygonTest(
                        pts.astype(np.float32).reshape(-1, 1, 2), (x, y), False
                    )
                    >= 0
                ):
                    art += 1
                    break
            continue
        used.add(match)
        tc = truth.colonies[match]
        found += 1
        key = (tc.kind, col.klass)
        confusion[key] = confusion.get(key, 0) + 1
        if col.klass == tc.kind:
            correct += 1
            if tc.kind == "merged":
                merged_found += 1
                count_ok += int(col.estimated_count == tc.count)
    for i, tc in enumerate(truth.colonies):
        if i not in used:
            confusion[(tc.kind, "missed")] = confusion.get((tc.kind, "missed"), 0) + 1
    return PlateScore(
        len(truth.colonies), found, correct, count_ok, merged_found, fp, art, confusion
    )
