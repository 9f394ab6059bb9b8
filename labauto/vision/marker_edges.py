"""Sub-pixel edges of a marker's three concentric circles, for its bias-free centre.

Canny's sub-pixel points (a parabola through three gradient magnitudes) are good to a few
hundredths of a pixel but carry a small periodic bias with the edge's position in the pixel
grid; on a 10 px circle that moves the fitted centre by up to 0.05 px. The paper's goal ("the
precision of the calibration strongly depends on the precision of the markers in the image") asks
for more, so once a marker is read its three circles are measured again, along rays:

* rays leave the centre of the first fit in the marker's rectified frame (the affine frame of the
  centre circle's ellipse): 64 at even angles for the centre circle (radius 1), and 6 across the
  middle half of every ink sector of the code ring for its inner (2) and outer (3) edges, so the
  sector ends, whose corners are rounded by blur, are never used;
* along each ray the image is sampled (bilinear) every 0.25 px over a window of +-3 px about the
  expected edge (less where the neighbouring edge is closer); a ray whose profile is not flat
  at its ends (``PLATEAU_SHARE``: the window cuts an edge widened by motion blur across it) is
  measured again in the widest window the neighbouring circle leaves (0.45 of the ray's
  radius), as a cut profile pulls the edge toward the window's centre (the previous fit);
* the edge is where the profile's area says it is (the moment method): with the profile
  normalised from 0 at the window's start to 1 at its end (each end the mean of its first or
  last three samples), the step lies ``sum((1 - n_i) * ds)`` after the window's start. For a
  straight edge blurred by any symmetric kernel this is exact whichever way the ray crosses it,
  it averages the noise of all samples, and it needs no threshold; on a curved edge blur moves it
  toward the centre of curvature by about ``sigma^2 / (2 R)``, the same all round, which changes
  the circle's size but not its centre;
* each circle's points get the geometric ellipse fit (:func:`labauto.vision.ellipse_fit.
  fit_ellipses_geometric_batch`, one batch for all markers), and the projected centre comes from
  the centre circle's and the outer edge's conics (:func:`marker_centers`,
  :func:`labauto.vision.concentric.projected_centers`);
* the rays are laid out again from the new fits (same image directions, windows centred on the
  new ellipses) until the windows sat on their edges or the centre stops moving: two passes for
  most markers, up to six under strong perspective (:func:`refine_circles`).
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.concentric import projected_centers
from labauto.vision.ellipse import Ellipse
from labauto.vision.ellipse_fit import fit_ellipses_geometric_batch
from labauto.vision.marker_codes import N_BITS, RING_INNER, RING_OUTER

#: Rays on the centre circle; rays per ink sector (over its middle half) on each ring edge.
CENTRE_RAYS = 64
SECTOR_RAYS = 6
#: Half window (px) and sample step (px) along a ray.
WINDOW_PX = 3.0
STEP_PX = 0.25
#: A ray is used when the ends of its profile differ by at least this share of the contrast.
MIN_STEP_SHARE = 0.5
#: A ray's profile is flat at its ends when the three samples inside each end's three differ
#: from them by at most this share of the step (both ends together); else the window cuts the
#: edge and is widened, for the next pass, to the limit the neighbouring circle sets.
PLATEAU_SHARE = 0.2
#: A pass whose edges lay this close (mean, px) to its windows' centres is the last one.
CENTRED_PX = 0.08
#: A circle's fit is used with at least this many points and at most this rms (px).
MIN_POINTS = 12
MAX_RMS = 0.3


def affine_frames(ellipses: list[Ellipse]) -> tuple[np.ndarray, np.ndarray]:
    """Centres (K, 2) and affine maps (K, 2, 2) taking the unit circle onto each ellipse."""
    return _row_frames(_rows(ellipses))


def _rows(ellipses: list[Ellipse]) -> np.ndarray:
    """(K, 5) rows ``(cx, cy, a, b, angle_deg)``."""
    return np.array([(*e.center, *e.axes, e.angle) for e in ellipses], np.float64).reshape(-1, 5)


def _row_frames(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres and unit-circle maps of ellipse rows ``(cx, cy, a, b, angle_deg)``."""
    theta = np.deg2rad(rows[:, 4])
    c, s = np.cos(theta), np.sin(theta)
    maps = np.empty((len(rows), 2, 2))
    maps[:, 0, 0], maps[:, 0, 1] = c * rows[:, 2], -s * rows[:, 3]
    maps[:, 1, 0], maps[:, 1, 1] = s * rows[:, 2], c * rows[:, 3]
    return rows[:, :2].copy(), maps


def _rays(bits: np.ndarray, bit0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Owner (marker index), angle and circle (0 centre, 1 inner, 2 outer) of every ray.

    Rays come grouped by marker, then by circle: ``CENTRE_RAYS`` on the centre circle, then
    ``SECTOR_RAYS`` per ink sector on the inner edge and the same on the outer edge.
    """
    k = len(bits)
    centre = np.broadcast_to(2.0 * np.pi * (np.arange(CENTRE_RAYS) + 0.5) / CENTRE_RAYS,
                             (k, CENTRE_RAYS))  # fmt: skip
    frac = 0.25 + 0.5 * (np.arange(SECTOR_RAYS) + 0.5) / SECTOR_RAYS
    sector = bit0[:, None, None] + 2.0 * np.pi * (np.arange(N_BITS)[None, :, None] + frac) / N_BITS
    ink = np.repeat(np.asarray(bits, bool), SECTOR_RAYS, axis=1)  # (k, N_BITS * SECTOR_RAYS)
    sector = sector.reshape(k, -1)
    # per marker: centre rays, its ink rays (inner edge), the same again (outer edge)
    n_ink = ink.sum(axis=1)
    counts = CENTRE_RAYS + 2 * n_ink
    owner = np.repeat(np.arange(k), counts)
    which = np.concatenate(
        [np.repeat([0, 1, 2], [CENTRE_RAYS, n, n]) for n in n_ink.tolist()]
    ) if k else np.empty(0, np.int64)  # fmt: skip
    angles = np.concatenate(
        [np.concatenate((centre[m], sector[m][ink[m]], sector[m][ink[m]])) for m in range(k)]
    ) if k else np.empty(0)  # fmt: skip
    return owner, angles, which


Circles = tuple[Ellipse | None, Ellipse | None, Ellipse | None]


def refine_circles(
    grey: np.ndarray,
    ellipses: list[Ellipse],
    bits: list[np.ndarray],
    bit0: list[float],
    min_contrast: float,
    max_passes: int = 6,
    tol_px: float = 0.01,
) -> list[Circles]:
    """Fits of the centre circle and the code ring's inner and outer edges of every marker.

    Parameters
    ----------
    grey : np.ndarray
        HxW float32 image.
    ellipses : list of Ellipse
        First fit of each marker's centre circle.
    bits : list of np.ndarray
        Each marker's code as read (``N_BITS`` values 0/1, read bit 0 first).
    bit0 : list of float
        Direction (rad, rectified frame) where read bit 0 starts.
    min_contrast : float
        Least ink-paper difference of the markers (grey levels).
    max_passes, tol_px : int, float
        Each pass after the first measures along rays laid out from the previous fits, so that
        every window is centred on its edge (its truncation cancels) and, under strong
        perspective, the ring's rays follow the ring's own ellipse rather than the scaled centre
        circle. A marker is measured again until its edges lay within ``CENTRED_PX`` of the
        windows' centres or its centre (:func:`marker_centers`) moves less than ``tol_px``
        (two passes for most markers, up to five or six for one seen with strong
        perspective), at most ``max_passes`` times.

    Returns
    -------
    list of (centre, inner, outer)
        The three fits per marker, None where too few rays were usable or the fit is poor.
    """
    if not ellipses:
        return []
    k = len(ellipses)
    first = _rows(ellipses)
    guess = np.repeat(first[:, None, :], 3, axis=1)  # (K, 3 circles, 5): the scaled centre circle
    for w, f in ((1, RING_INNER), (2, RING_OUTER)):
        guess[:, w, 2:4] *= f
    owner, theta, which = _rays(np.asarray(bits), np.asarray(bit0, np.float64))
    _, centre_maps = _row_frames(first)
    unit = np.column_stack((np.cos(theta), np.sin(theta)))
    # every ray keeps its image direction (from the first fit's frame, where the sectors were
    # read) through all passes; only its start (the circle's centre) and its expected crossing
    # follow the fits. (A frame's rotation is arbitrary for a near-circle: re-deriving the
    # directions from each new fit could turn the ring's rays onto the sector ends.)
    direction = np.einsum("kij,kj->ki", centre_maps[owner], unit)
    reach = np.hypot(direction[:, 0], direction[:, 1])
    # the window stays clear of the neighbouring circle (one centre radius away); a ray whose
    # edge is wider than its window holds (motion blur across it) gets the widest one
    limit = 0.45 * reach
    half = np.minimum(WINDOW_PX, limit)
    key = owner * 3 + which
    result = np.full((k, 3, 5), np.nan)  # NaN rows: no fit
    active = np.ones(k, bool)
    for _ in range(max_passes):
        centres, maps = _row_frames(guess.reshape(-1, 5))
        live = active[owner]
        edge, usable, offset, cut = _measure(
            grey, centres[key[live]], maps[key[live]], direction[live], half[live], min_contrast
        )
        wide = usable & cut & (half[live] < limit[live])
        half[np.flatnonzero(live)[wide]] = limit[live][wide]
        fits = _fit_sets(guess, edge, key[live], usable)
        todo = np.flatnonzero(active)
        now, before = _centres(fits[todo]), _centres(result[todo])
        moved = np.hypot(*(now - before).T)
        centred = _windows_centred(offset, usable, key[live], k)[todo]
        result[todo] = fits[todo]
        got = np.isfinite(fits[:, :, 0]) & active[:, None]
        guess[got] = fits[got]
        # done when the windows sat on their edges (another pass would measure the same) or the
        # centre stopped moving; no centre yet (NaN): nothing more to gain
        active[todo] = np.isfinite(now).all(axis=1) & ~centred & ~(moved <= tol_px)
        active[np.unique(owner[live][wide])] = True  # measure again in the wider windows
        if not active.any():
            break
    return [
        tuple(
            None if not np.isfinite(r[0]) else Ellipse((r[0], r[1]), (r[2], r[3]), r[4])
            for r in circles.tolist()
        )
        for circles in result
    ]  # type: ignore[misc]


def _centres(rows: np.ndarray) -> np.ndarray:
    """(K, 2) projected centres of (K, 3, 5) circle rows (see :func:`marker_centers`)."""
    ring = np.where(np.isfinite(rows[:, 2, :1]), rows[:, 2], rows[:, 1])
    out = np.full((len(rows), 2), np.nan)
    have = np.isfinite(rows[:, 0, 0]) & np.isfinite(ring[:, 0])
    if have.any():
        out[have] = projected_centers(rows[have, 0], ring[have])
    return out


def marker_centers(circles: list[Circles]) -> np.ndarray:
    """(K, 2) projected centres from the fits (NaN where there is none): the centre circle
    with the outer ring edge (radius ratio 3, the best-conditioned pair), or with the inner
    edge when the outer one failed."""
    rows = np.full((len(circles), 3, 5), np.nan)
    for k, fits in enumerate(circles):
        for w, e in enumerate(fits):
            if e is not None:
                rows[k, w] = (*e.center, *e.axes, e.angle)
    return _centres(rows)


def _measure(
    grey: np.ndarray,
    centres: np.ndarray,
    maps: np.ndarray,
    direction: np.ndarray,
    half: np.ndarray,
    min_contrast: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edge point along every ray ``centre + s * direction`` near the ellipse ``(centre, map)``,
    whether it is usable, its offset (px) from the window's centre, and whether the window cuts
    the edge (the profile is not flat at its ends, ``PLATEAU_SHARE``)."""
    n_samples = round(2 * WINDOW_PX / STEP_PX)
    grid = ((np.arange(n_samples) + 0.5) / n_samples * 2.0 - 1.0).astype(np.float32)
    # expected crossing: |map^-1 (s0 direction)| = 1
    det = maps[:, 0, 0] * maps[:, 1, 1] - maps[:, 0, 1] * maps[:, 1, 0]
    local = (
        np.column_stack(
            (
                maps[:, 1, 1] * direction[:, 0] - maps[:, 0, 1] * direction[:, 1],
                maps[:, 0, 0] * direction[:, 1] - maps[:, 1, 0] * direction[:, 0],
            )
        )
        / det[:, None]
    )  # map^-1 direction (2x2 inverse written out)
    s0 = 1.0 / np.hypot(local[:, 0], local[:, 1])
    px_per_unit = np.hypot(direction[:, 0], direction[:, 1])
    along = (half / px_per_unit).astype(np.float32)[:, None] * grid[None, :] + s0.astype(
        np.float32
    )[:, None]
    mx = centres[:, :1].astype(np.float32) + direction[:, :1].astype(np.float32) * along
    my = centres[:, 1:].astype(np.float32) + direction[:, 1:].astype(np.float32) * along
    prof = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, cv2.BORDER_REPLICATE)
    start, end = prof[:, :3].mean(axis=1), prof[:, -3:].mean(axis=1)
    step = (end - start).astype(np.float64)
    usable = np.abs(step) >= MIN_STEP_SHARE * min_contrast
    # sum of (1 - n_i) = n_samples - (sum(prof) - n * start) / step
    total = prof.sum(axis=1, dtype=np.float64)
    ones = n_samples - (total - n_samples * start) / np.where(usable, step, 1.0)
    edge_px = -half + ones * (2.0 * half / n_samples)
    usable &= np.abs(edge_px) < half
    edge = centres + (s0 + edge_px / px_per_unit)[:, None] * direction
    ramp = np.abs(prof[:, 3:6].mean(axis=1) - start) + np.abs(end - prof[:, -6:-3].mean(axis=1))
    cut = ramp > PLATEAU_SHARE * np.abs(step)
    return edge, usable, edge_px, cut


def _windows_centred(
    offset: np.ndarray, usable: np.ndarray, key: np.ndarray, n_markers: int
) -> np.ndarray:
    """(K,) bool: every circle of the marker had its edges within ``CENTRED_PX`` (mean
    distance) of the windows' centres."""
    k = key[usable]
    count = np.bincount(k, minlength=3 * n_markers)
    total = np.bincount(k, np.abs(offset[usable]), minlength=3 * n_markers)
    mean = np.where(count > 0, total / np.maximum(count, 1), np.inf)
    return (mean.reshape(n_markers, 3) <= CENTRED_PX).all(axis=1)


def _fit_sets(
    guess: np.ndarray, edge: np.ndarray, key: np.ndarray, usable: np.ndarray
) -> np.ndarray:
    """(K, 3, 5) geometric fits of each circle's edge points (NaN: too few points or poor fit),
    seeded by ``guess``; ``key`` is ``marker * 3 + circle`` of every ray (grouped by key)."""
    out = np.full(guess.shape, np.nan)
    k = key[usable]
    counts = np.bincount(k, minlength=guess.shape[0] * 3)
    keys = np.flatnonzero(counts >= MIN_POINTS)
    if keys.size == 0:
        return out
    points = edge[usable][np.isin(k, keys)]
    offsets = np.concatenate(([0], np.cumsum(counts[keys]))).astype(np.int64)
    flat = guess.reshape(-1, 5)
    fits = fit_ellipses_geometric_batch(points, offsets, flat[keys], max_iter=20, tol=1e-8)
    flat_out = out.reshape(-1, 5)
    for j, fit in zip(keys.tolist(), fits, strict=True):
        if fit is not None and fit.rms <= MAX_RMS:
            e = fit.ellipse
            flat_out[j] = (*e.center, *e.axes, e.angle)
    return out
