"""Sub-pixel edges of a marker's concentric circles, for its bias-free centre.

Canny's sub-pixel points (a parabola through three gradient magnitudes) are good to a few
hundredths of a pixel but carry a small periodic bias with the edge's position in the pixel
grid; on a 10 px circle that moves the fitted centre by up to 0.05 px. The paper's goal ("the
precision of the calibration strongly depends on the precision of the markers in the image") asks
for more, so once a marker is read its centre circle and the outer edge of its code ring (the
pair the centre comes from) are measured again, along rays:

* rays leave the centre of the ellipse the code was read in, in its rectified frame: 64 at even
  angles for the centre circle (radius 1), and 6 across the middle half of every ink sector of
  the code ring for its outer (3) edge, so the sector ends, whose corners are rounded by blur,
  are never used; the same sector rays serve the ring's inner (2) edge, which is measured only
  where the outer one gives no fit and then stands in for it;
* along each ray the image is sampled (bilinear) every 0.25 px over a window of +-3 px about the
  expected edge (+-5 px in the first pass and in a third or later one, see below; less where
  the neighbouring edge is closer);
* the edge is where the profile's area says it is (the moment method): with the profile
  normalised from 0 at the window's start to 1 at its end (each end the mean of its first or
  last three samples), the step lies ``sum((1 - n_i) * ds)`` after the window's start. For a
  straight edge blurred by any symmetric kernel this is exact whichever way the ray crosses it,
  it averages the noise of all samples, and it needs no threshold; on a curved edge blur moves it
  toward the centre of curvature by about ``sigma^2 / (2 R)``, the same all round, which changes
  the circle's size but not its centre. A window off its edge by a good part of its width
  pulls the estimate toward its own centre (its ends cut the blurred step unevenly);
* each circle's points get the geometric ellipse fit (:func:`labauto.vision.ellipse_fit.
  fit_ellipses_geometric_batch`, one batch for all markers), and the projected centre comes from
  the centre circle's and the outer edge's conics (:func:`centres_of`,
  :func:`labauto.vision.concentric.projected_centers`);
* passes (:func:`refine_circles`): the first is a wide, coarse look (every other ray on the
  centre circle, windows of +-5 px sampled every 0.5 px, direct algebraic fits), since the
  ring's first guess, the centre circle scaled by 3, can be pixels off under perspective; it
  only places the next windows. The second measures along every ray with +-3 px windows
  centred on the first pass's fits (an inner edge standing in, which the first pass did not
  measure, on its first guess, the centre circle scaled by 2), which is the last pass for
  nearly every marker (its windows sat on their edges). A marker whose windows were still off
  its edges and whose centre still moved is under strong perspective: it gets wide windows
  again, pass after pass, until they sit on the edges or the centre stops moving (up to six
  passes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from labauto.vision.concentric import projected_centers
from labauto.vision.ellipse_fit import fit_ellipses_algebraic_batch, fit_ellipses_geometric_batch
from labauto.vision.marker_codes import N_BITS, RING_INNER, RING_OUTER

#: Rays on the centre circle; rays per ink sector (over its middle half) on each ring edge.
CENTRE_RAYS = 64
SECTOR_RAYS = 6
#: Half window (px) and sample step (px) along a ray, in the first pass (a wide, coarse look
#: on every other ray: only the next pass's windows depend on it) and after.
FIRST_WINDOW_PX, FIRST_STEP_PX = 5.0, 0.5
WINDOW_PX = 3.0
STEP_PX = 0.25
#: A ray is used when the ends of its profile differ by at least this share of the contrast.
MIN_STEP_SHARE = 0.5
#: A pass whose edges lay this close (mean, px) to its windows' centres is the last one.
CENTRED_PX = 0.08
#: A circle's fit is used with at least this many points and at most this rms (px).
MIN_POINTS = 12
MAX_RMS = 0.3


def affine_frames(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (K, 2) and affine maps (K, 2, 2) taking the unit circle onto each ellipse.

    Parameters
    ----------
    rows : np.ndarray
        (K, 5) ellipse rows ``(cx, cy, a, b, angle_deg)``.
    """
    rows = np.asarray(rows, np.float64).reshape(-1, 5)
    theta = np.deg2rad(rows[:, 4])
    c, s = np.cos(theta), np.sin(theta)
    maps = np.empty((len(rows), 2, 2))
    maps[:, 0, 0], maps[:, 0, 1] = c * rows[:, 2], -s * rows[:, 3]
    maps[:, 1, 0], maps[:, 1, 1] = s * rows[:, 2], c * rows[:, 3]
    return rows[:, :2].copy(), maps


def _rays(bits: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Owner (marker index), angle and circle (0 centre, 1 inner, 2 outer) of every ray.

    Rays come grouped by marker, then by circle: ``CENTRE_RAYS`` on the centre circle, then
    ``SECTOR_RAYS`` per ink sector on the inner edge and the same on the outer edge.
    """
    k = len(bits)
    centre = 2.0 * np.pi * (np.arange(CENTRE_RAYS) + 0.5) / CENTRE_RAYS
    frac = 0.25 + 0.5 * (np.arange(SECTOR_RAYS) + 0.5) / SECTOR_RAYS
    sector = (np.arange(N_BITS)[:, None] + frac).ravel() * (2.0 * np.pi / N_BITS)
    n = len(sector)
    # one row per marker: all centre rays, every sector ray twice; the ink ones are used
    angles = np.concatenate(
        (np.broadcast_to(centre, (k, CENTRE_RAYS)), np.tile(start[:, None] + sector, 2)), axis=1
    )
    ink = np.repeat(np.asarray(bits, bool).reshape(k, N_BITS), SECTOR_RAYS, axis=1)
    used = np.concatenate((np.ones((k, CENTRE_RAYS), bool), ink, ink), axis=1)
    which = np.repeat(np.array([0, 1, 2]), [CENTRE_RAYS, n, n])
    owner = np.broadcast_to(np.arange(k)[:, None], used.shape)
    return owner[used], angles[used], np.broadcast_to(which, used.shape)[used]


def refine_circles(
    grey: np.ndarray,
    frames: np.ndarray,
    bits: np.ndarray,
    start: np.ndarray,
    min_contrast: float,
    max_passes: int = 6,
    tol_px: float = 0.01,
) -> tuple[np.ndarray, np.ndarray]:
    """Fits of the centre circle and the code ring's edges of every marker, and its centre.

    Parameters
    ----------
    grey : np.ndarray
        HxW float32 image.
    frames : np.ndarray
        (K, 5) ellipse rows ``(cx, cy, a, b, angle_deg)``: each marker's centre circle as
        first found, whose rectified frame the code was read in.
    bits : np.ndarray
        (K, N_BITS) each marker's code as read (0/1, read bit 0 first).
    start : np.ndarray
        (K,) direction (rad, rectified frame) where read bit 0 starts.
    min_contrast : float
        Least ink-paper difference of the markers (grey levels).
    max_passes, tol_px : int, float
        Each pass after the first measures along rays laid out from the previous fits, so that
        every window is centred on its edge (its truncation cancels) and, under strong
        perspective, the ring's rays follow the ring's own ellipse rather than the scaled centre
        circle. After the (coarse) first pass a marker is measured again until its edges lay
        within ``CENTRED_PX`` of the windows' centres or its centre moves less than ``tol_px``
        (two passes in all for nearly every marker, up to five or six for one seen with strong
        perspective), at most ``max_passes`` times.

    Returns
    -------
    circles : np.ndarray
        (K, 3, 5) rows of the centre circle's, the ring's inner and its outer edge's fits; NaN
        where too few rays were usable, the fit is poor or (the inner edge) not measured.
    centres : np.ndarray
        (K, 2) projected centres (:func:`centres_of`), NaN where there is none.
    """
    first = np.asarray(frames, np.float64).reshape(-1, 5)
    k = len(first)
    guess = np.repeat(first[:, None, :], 3, axis=1)  # (K, 3 circles, 5): the scaled centre circle
    for w, f in ((1, RING_INNER), (2, RING_OUTER)):
        guess[:, w, 2:4] *= f
    owner, theta, which = _rays(np.asarray(bits), np.asarray(start, np.float64))
    _, centre_maps = affine_frames(first)
    # every ray keeps its image direction (from the first frame, where the sectors were read)
    # through all passes; only its start (the circle's centre) and its expected crossing
    # follow the fits. (A frame's rotation is arbitrary for a near-circle: re-deriving the
    # directions from each new fit could turn the ring's rays onto the sector ends.)
    m = centre_maps[owner]
    cos, sin = np.cos(theta), np.sin(theta)
    dx = m[:, 0, 0] * cos + m[:, 0, 1] * sin
    dy = m[:, 1, 0] * cos + m[:, 1, 1] * sin
    rays = _Rays(owner * 3 + which, dx, dy, np.hypot(dx, dy))
    circles = np.full((k, 3, 5), np.nan)  # NaN rows: no fit
    centres = np.full((k, 2), np.nan)
    active = np.ones(k, bool)
    tried_inner = np.zeros(k, bool)
    outer_failed = np.zeros(k, bool)
    for n_pass in range(max_passes if k else 0):
        measure = _circles_to_measure(active, outer_failed)
        tried_inner |= measure[:, 1]
        use = measure.ravel()[rays.key]
        if n_pass == 0:  # a wide look from the first guesses (every other centre-circle ray)
            use &= (np.arange(len(use)) % 2 == 0) | (rays.key % 3 != 0)
            live = rays.of(use, FIRST_WINDOW_PX, FIRST_STEP_PX)
        else:
            live = rays.of(use, WINDOW_PX if n_pass == 1 else FIRST_WINDOW_PX, STEP_PX)
        edge, usable, offset = _measure(grey, guess.reshape(-1, 5), live, min_contrast)
        # (the coarse first look needs no more than the direct algebraic fits)
        fits = _fit_sets(guess, edge, live.key, usable, geometric=n_pass > 0)
        circles[measure] = fits[measure]
        got = np.isfinite(fits[:, :, 0]) & measure
        guess[got] = fits[got]
        outer_failed = measure[:, 2] & ~got[:, 2]
        if n_pass == 0 and max_passes > 1:
            continue  # the coarse first look only places the next pass's windows
        todo = np.flatnonzero(active)
        now = centres_of(circles[todo])
        moved = np.hypot(*(now - centres[todo]).T)
        centred = _windows_centred(offset, usable, live.key, measure)[todo]
        centres[todo] = now
        # done when the windows sat on their edges (another pass would measure the same) or the
        # centre stopped moving; no centre (NaN): nothing more to gain, unless the inner edge
        # is still to stand in for a failed outer one
        retry = ~np.isfinite(circles[todo, 2, 0]) & ~tried_inner[todo]
        going = np.isfinite(now).all(axis=1) & ~centred & ~(moved <= tol_px)
        active[todo] = going | retry
        if not active.any():
            break
    return circles, centres


def _circles_to_measure(active: np.ndarray, outer_failed: np.ndarray) -> np.ndarray:
    """(K, 3) bool: the circles of each marker to measure in the next pass: the centre circle
    and the code ring's outer edge of every active marker, and the ring's inner edge where the
    outer one was measured and gave no fit (the centre comes from the centre circle and the
    outer edge, the best-conditioned pair; the inner edge only stands in for a failed outer
    one)."""
    return np.column_stack((active, active & outer_failed, active))


@dataclass(frozen=True)
class _Rays:
    """Rays ``centre + s * (dx, dy)`` of circles ``key`` (``marker * 3 + circle``), and what a
    pass needs of them: the length in px of a unit of ``s``, the window (``window`` px each
    side, less where the neighbouring circle, one centre radius away, is closer: ``half``)
    sampled every ``step`` px, and the half window as a vector (float32 columns)."""

    key: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    px_per_unit: np.ndarray
    window: float = WINDOW_PX
    step: float = STEP_PX
    half: np.ndarray = field(init=False)
    reach_x: np.ndarray = field(init=False)
    reach_y: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        half = np.minimum(self.window, 0.45 * self.px_per_unit)
        reach = half / self.px_per_unit  # units of s per half window
        object.__setattr__(self, "half", half)
        object.__setattr__(self, "reach_x", (self.dx * reach).astype(np.float32)[:, None])
        object.__setattr__(self, "reach_y", (self.dy * reach).astype(np.float32)[:, None])

    def of(self, mask: np.ndarray, window: float, step: float) -> _Rays:
        """The rays where ``mask``, with windows of ``window`` px sampled every ``step`` px."""
        return _Rays(
            self.key[mask], self.dx[mask], self.dy[mask], self.px_per_unit[mask], window, step
        )


def ring_rows(circles: np.ndarray) -> np.ndarray:
    """(K, 5) the ring edge each marker's centre is projected with, from (K, 3, 5) circle rows:
    the outer edge, or the inner one where the outer fit failed (NaN where both did)."""
    return np.where(np.isfinite(circles[:, 2, :1]), circles[:, 2], circles[:, 1])


def centres_of(circles: np.ndarray) -> np.ndarray:
    """(K, 2) projected centres of (K, 3, 5) circle rows, NaN where there is none: the centre
    circle with the ring edge of :func:`ring_rows` (the outer one, radius ratio 3, is the
    best-conditioned pair; :func:`labauto.vision.concentric.projected_centers`).
    """
    ring = ring_rows(circles)
    out = np.full((len(circles), 2), np.nan)
    have = np.isfinite(circles[:, 0, 0]) & np.isfinite(ring[:, 0])
    if have.any():
        out[have] = projected_centers(circles[have, 0], ring[have])
    return out


def _measure(
    grey: np.ndarray, circles: np.ndarray, rays: _Rays, min_contrast: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge point along every ray near its circle's ellipse (``circles[rays.key]``, rows
    ``(cx, cy, a, b, angle_deg)``), whether it is usable, and its offset (px) from the
    window's centre."""
    n_samples = round(2 * rays.window / rays.step)
    grid = ((np.arange(n_samples) + 0.5) / n_samples * 2.0 - 1.0).astype(np.float32)
    # expected crossing s0: the ray's direction in the ellipse's unit-circle frame has length
    # 1 / s0 (the inverse of the frame's map, rotation then axes, written out per circle)
    theta = np.deg2rad(circles[:, 4])
    c, s = np.cos(theta), np.sin(theta)
    inverse = np.column_stack((c / circles[:, 2], s / circles[:, 2], c / circles[:, 3],
                               s / circles[:, 3], circles[:, 0], circles[:, 1]))  # fmt: skip
    ca, sa, cb, sb, cx, cy = inverse[rays.key].T
    dx, dy = rays.dx, rays.dy
    s0 = 1.0 / np.hypot(ca * dx + sa * dy, cb * dy - sb * dx)
    # sample i of a ray is at centre + s0 (dx, dy) + grid_i * reach (dx, dy)
    mx = rays.reach_x * grid
    mx += (cx + dx * s0).astype(np.float32)[:, None]
    my = rays.reach_y * grid
    my += (cy + dy * s0).astype(np.float32)[:, None]
    prof = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    # (OpenCV's row reductions: several times faster than numpy's on these short rows)
    total = cv2.reduce(prof, 1, cv2.REDUCE_SUM, dtype=cv2.CV_64F)[:, 0]
    start = cv2.reduce(prof[:, :3], 1, cv2.REDUCE_AVG, dtype=cv2.CV_64F)[:, 0]
    end = cv2.reduce(prof[:, -3:], 1, cv2.REDUCE_AVG, dtype=cv2.CV_64F)[:, 0]
    step = end - start
    usable = np.abs(step) >= MIN_STEP_SHARE * min_contrast
    # sum of (1 - n_i) = n_samples - (sum(prof) - n * start) / step
    ones = n_samples - (total - n_samples * start) / np.where(usable, step, 1.0)
    edge_px = rays.half * (ones * (2.0 / n_samples) - 1.0)
    usable &= np.abs(edge_px) < rays.half
    along = s0 + edge_px / rays.px_per_unit
    edge = np.column_stack((cx + along * dx, cy + along * dy))
    return edge, usable, edge_px


def _windows_centred(
    offset: np.ndarray, usable: np.ndarray, key: np.ndarray, measured: np.ndarray
) -> np.ndarray:
    """(K,) bool: every circle of the marker measured (``measured``, (K, 3)) had its edges
    within ``CENTRED_PX`` (mean distance) of the windows' centres."""
    k = key[usable]
    count = np.bincount(k, minlength=measured.size)
    total = np.bincount(k, np.abs(offset[usable]), minlength=measured.size)
    mean = np.where(count > 0, total / np.maximum(count, 1), np.inf).reshape(measured.shape)
    return ((mean <= CENTRED_PX) | ~measured).all(axis=1)


def _fit_sets(
    guess: np.ndarray,
    edge: np.ndarray,
    key: np.ndarray,
    usable: np.ndarray,
    geometric: bool = True,
) -> np.ndarray:
    """(K, 3, 5) geometric fits of each circle's edge points (NaN: too few points or poor fit),
    seeded by ``guess``; ``key`` is ``marker * 3 + circle`` of every ray (grouped by key).
    With ``geometric`` False, the direct algebraic fits (no seeds, no rms test)."""
    out = np.full(guess.shape, np.nan)
    counts = np.bincount(key[usable], minlength=guess.shape[0] * 3)
    enough = counts >= MIN_POINTS
    keys = np.flatnonzero(enough)
    if keys.size == 0:
        return out
    points = edge[usable & enough[key]]
    offsets = np.concatenate(([0], np.cumsum(counts[keys]))).astype(np.int64)
    if not geometric:
        out.reshape(-1, 5)[keys] = fit_ellipses_algebraic_batch(points, offsets)
        return out
    flat = guess.reshape(-1, 5)
    fits = fit_ellipses_geometric_batch(points, offsets, flat[keys], max_iter=20, tol=1e-8)
    good = [j for j, f in enumerate(fits) if f is not None and f.rms <= MAX_RMS]
    if good:
        es = [fits[j].ellipse for j in good]
        out.reshape(-1, 5)[keys[good]] = [(*e.center, *e.axes, e.angle) for e in es]
    return out
