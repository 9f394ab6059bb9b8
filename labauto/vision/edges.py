"""Colour Canny edges, ordered edge linking and sub-pixel refinement (section 3.1).

The paper combines Canny's hysteresis with a region growing that "collects all points of the edge
contour with a known sorting". We get the same ordered chains without a Python loop over pixels:

1. ``cv2.Canny(gx, gy, low, high, L2gradient=True)`` on our own colour gradient (eq. 2);
2. the edge pixels are thinned to minimal 8-connected chains (:func:`thin_edges`: Canny leaves
   4-connected staircases that the tracer would meet only on its way back, out of order), then
   ``cv2.findContours(..., RETR_CCOMP, CHAIN_APPROX_NONE)`` traces the outer boundary of every
   8-connected edge component (hole boundaries are dropped: they repeat the same thin edge);
3. an open chain is traced out and back (A..B..A). We rotate such a trace to start at its first
   turnaround point (where the trace reverses, i.e. an end of the chain) and keep every pixel
   once, at its first visit. An open chain comes out ordered from one end to the
   other; a closed thin loop comes out once around (its outer trace). Components with more than
   two ends (branches) keep all their pixels, branches following each other, which is what the
   paper's region growing gives too.

Sub-pixel refinement follows Devernay (1995): along the axis (x or y) closest to the gradient
direction, fit a parabola through the gradient magnitude at the edge pixel and its two neighbours
and move the point to the vertex (at most half a pixel).
"""

from __future__ import annotations

import cv2
import numpy as np


def canny_edges(gx: np.ndarray, gy: np.ndarray, low: float, high: float) -> np.ndarray:
    """Canny non-maximum suppression and hysteresis on a given gradient.

    Parameters
    ----------
    gx, gy : np.ndarray
        int16 HxW derivatives (from :func:`labauto.vision.gradient.color_gradient`).
    low, high : float
        Hysteresis thresholds on the L2 gradient magnitude.

    Returns
    -------
    np.ndarray
        uint8 HxW edge map (255 on edges).
    """
    if not 0 <= low <= high:
        raise ValueError(f"Canny thresholds need 0 <= low <= high, got low={low}, high={high}")
    return cv2.Canny(gx, gy, float(low), float(high), L2gradient=True)


def _removable_table() -> np.ndarray:
    """Which 3x3 neighbourhoods (by 8-bit neighbour code) make the centre pixel removable.

    Bit k of the code is neighbour k in the ring order N, NE, E, SE, S, SW, W, NW. The centre is
    removable when it has at least two neighbours (not a chain end), its neighbours form one
    8-connected group without it (its removal disconnects nothing), and one of its 4-neighbours
    is background (no hole is opened).
    """
    nb = ((np.arange(256)[:, None] >> np.arange(8)) & 1).astype(bool)  # (256, 8)
    # ring neighbours k, k+1 touch; k, k+2 touch too when k is N, E, S or W (even k)
    adjacent = np.zeros((8, 8), bool)
    for k in range(8):
        for step in (1, 2) if k % 2 == 0 else (1,):
            j = (k + step) % 8
            adjacent[k, j] = adjacent[j, k] = True
    table = np.zeros(256, bool)
    for code in range(256):
        members = [int(k) for k in np.flatnonzero(nb[code])]
        if len(members) < 2 or nb[code, 0::2].all():
            continue
        reached, frontier = {members[0]}, [members[0]]
        while frontier:
            k = frontier.pop()
            for j in members:
                if adjacent[k, j] and j not in reached:
                    reached.add(j)
                    frontier.append(j)
        table[code] = len(reached) == len(members)
    return table


_REMOVABLE = _removable_table()
#: (dy, dx) of the ring neighbours N, NE, E, SE, S, SW, W, NW
_NEIGHBOURS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))


def thin_edges(edges: np.ndarray, max_iter: int = 2) -> np.ndarray:
    """Thin an edge map to minimal 8-connected chains, working only on the edge pixels.

    Canny leaves 4-connected staircases and short two-pixel-thick runs; a boundary trace then
    meets some pixels only on its way back, which scrambles the order of the chain. We remove
    every pixel whose neighbours stay 8-connected without it and that is not a chain end (see
    :func:`_removable_table`). Pixels are decided in four checkerboard classes (x and y
    parity): two pixels of one class are never neighbours, so a class is decided at once,
    vectorised, without breaking a chain. The end of a two-pixel-thick run may lose a pixel
    per pass.

    Parameters
    ----------
    edges : np.ndarray
        uint8 HxW map, nonzero on edges.
    max_iter : int
        Maximum number of passes over the four classes (Canny output: 1-2).

    Returns
    -------
    np.ndarray
        uint8 (H+2)x(W+2) 0/1 map: the thinned edges with a one-pixel zero border (pixel ``(x, y)``
        of ``edges`` is at ``(x + 1, y + 1)``; pass ``offset=(-1, -1)`` to ``cv2.findContours``).
    """
    binary = cv2.threshold(edges, 0, 1, cv2.THRESH_BINARY)[1]
    padded = cv2.copyMakeBorder(binary, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    flat = padded.ravel()
    stride = padded.shape[1]
    pixels = _nonzero_sparse(flat)
    if pixels.shape[0] == 0:
        return padded
    neighbour_offsets = np.array([dy * stride + dx for dy, dx in _NEIGHBOURS], np.intp)
    parity = ((pixels // stride) & 1) * 2 + (pixels & 1)
    classes = [pixels[parity == c] for c in range(4)]
    # A pixel found not removable stays so until a neighbour goes: after the first pass only
    # pixels with a neighbour removed since their last decision ("stale") are decided again.
    stale = np.zeros_like(flat)
    for iteration in range(max_iter):
        changed = False
        for c, at in enumerate(classes):
            if iteration > 0:
                at = at[stale[at] != 0]
                if at.shape[0] == 0:
                    continue
            code = np.zeros(at.shape[0], np.uint8)
            for bit, offset in enumerate(neighbour_offsets.tolist()):
                code |= flat[at + offset] << bit
            stale[at] = 0
            remove = _REMOVABLE[code] & (flat[at] != 0)
            if remove.any():
                changed = True
                gone = at[remove]
                flat[gone] = 0
                stale[gone[:, None] + neighbour_offsets] = 1
                classes[c] = classes[c][flat[classes[c]] != 0]
        if not changed:
            break
    return padded


def _nonzero_sparse(flat: np.ndarray) -> np.ndarray:
    """Linear indices of the nonzero bytes of a sparse contiguous uint8 array, ascending.

    Scans 8 bytes at a time (a uint64 view), then looks only inside the nonzero words; on a
    1280x1024 edge map (~18k edge pixels) about 0.7 ms against 0.8 ms for ``cv2.findNonZero``.
    """
    n8 = flat.shape[0] // 8 * 8
    words = np.flatnonzero(flat[:n8].view(np.uint64))
    inside = (words[:, None] * 8 + np.arange(8)).ravel()
    found = inside[flat[inside] != 0]
    tail = np.flatnonzero(flat[n8:])
    return np.concatenate((found, tail + n8)) if tail.shape[0] else found


def link_edges(
    edges: np.ndarray, min_length: int = 1, max_length: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Collect the pixels of a binary edge map into ordered chains, each pixel once.

    Parameters
    ----------
    edges : np.ndarray
        uint8 HxW map, nonzero on edge pixels (one pixel thick, as Canny gives).
    min_length, max_length : int
        Keep chains with ``min_length <= n_points <= max_length`` (None: no upper bound).

    Returns
    -------
    points : np.ndarray
        (N, 2) int32 pixel coordinates ``(x, y)`` of all chains, concatenated in order.
    offsets : np.ndarray
        (K + 1,) int64; chain k is ``points[offsets[k]:offsets[k + 1]]``.
    """
    traces, hierarchy = cv2.findContours(
        thin_edges(edges), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(-1, -1)
    )
    if not traces:
        return np.empty((0, 2), np.int32), np.zeros(1, np.int64)
    outer = hierarchy[0, :, 3] < 0
    # a chain of n pixels gives a trace of n (closed) to 2n - 2 (open) points
    keep = [t for t, o in zip(traces, outer, strict=True) if o and len(t) >= min_length]
    return traces_to_chains(keep, edges.shape[1], min_length, max_length)


def traces_to_chains(
    traces: list[np.ndarray], width: int, min_length: int = 1, max_length: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Turn boundary traces (``cv2.findContours`` output) into chains with each pixel once.

    A trace that visits most of its pixels twice (fewer than 3/4 distinct: an open chain traced
    out and back) is rotated to start at its first turnaround (``t[i - 1] == t[i + 1]``);
    closed loops keep their start (a one-pixel spur on a loop must not open it). Then only the
    first visit of every pixel is kept. See the module docstring.

    Parameters
    ----------
    traces : list of np.ndarray
        (n, 1, 2) int32 traces ``(x, y)``.
    width : int
        Image width (for linear pixel indices).
    min_length, max_length : int
        Length filter applied to the resulting chains.

    Returns
    -------
    points, offsets
        As :func:`link_edges`.
    """
    if not traces:
        return np.empty((0, 2), np.int32), np.zeros(1, np.int64)
    lengths = np.fromiter((len(t) for t in traces), np.int64, len(traces))
    pts = np.concatenate(traces).reshape(-1, 2)
    n_total = pts.shape[0]
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    contour = np.repeat(np.arange(len(traces)), lengths)
    local = np.arange(n_total) - starts[contour]
    n = lengths[contour]
    lin = pts[:, 1].astype(np.int64) * width + pts[:, 0]
    # open chains (traced out and back: few distinct pixels) start at their first turnaround
    unique = np.bincount(contour[_first_visits(lin)], minlength=len(traces))
    out_and_back = unique < 0.75 * lengths
    prev = starts[contour] + (local - 1) % n
    nxt = starts[contour] + (local + 1) % n
    turn = (lin[prev] == lin[nxt]) & (n > 2) & out_and_back[contour]
    big = np.iinfo(np.int64).max
    first_turn = np.minimum.reduceat(np.where(turn, local, big), starts)
    rotation = np.where(first_turn == big, 0, first_turn)
    # position j of a rotated trace holds its old point (j + rotation) mod n
    order = starts[contour] + (local + rotation[contour]) % n
    order = order[_first_visits(lin[order])]
    contour = contour[order]
    counts = np.bincount(contour, minlength=len(traces))
    ok = counts >= min_length
    if max_length is not None:
        ok &= counts <= max_length
    sel = ok[contour]
    points = pts[order[sel]]
    offsets = np.concatenate(([0], np.cumsum(counts[ok])))
    return points, offsets


def _first_visits(lin: np.ndarray) -> np.ndarray:
    """Bool mask of the first occurrence of every value of ``lin`` (non-negative ints)."""
    idx = np.arange(lin.shape[0])
    first = np.empty(int(lin.max()) + 1, np.int64)
    first[lin[::-1]] = idx[::-1]  # repeated indices: the last write (earliest index) wins
    return first[lin] == idx


def gradient_at(gx: np.ndarray, gy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Return the (N, 2) float32 gradient ``(gx, gy)`` at integer pixel ``points`` (x, y)."""
    x, y = points[:, 0], points[:, 1]
    return np.column_stack((gx[y, x], gy[y, x])).astype(np.float32)


def refine_subpixel(points: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Move edge pixels to the sub-pixel maximum of the gradient magnitude (Devernay).

    Parameters
    ----------
    points : np.ndarray
        (N, 2) int pixel coordinates ``(x, y)`` of edge pixels.
    gx, gy : np.ndarray
        int16 HxW gradient the edges were found on.

    Returns
    -------
    np.ndarray
        (N, 2) float64 refined coordinates. Each point moves by at most 0.5 px along x or y
        (whichever is closer to its gradient direction); points on the image border and points
        that are not a strict local maximum stay where they are.
    """
    h, w = gx.shape
    x = points[:, 0].astype(np.intp)
    y = points[:, 1].astype(np.intp)
    out = points.astype(np.float64)
    gxp, gyp = gx[y, x].astype(np.float32), gy[y, x].astype(np.float32)
    along_x = np.abs(gxp) >= np.abs(gyp)
    sx, sy = along_x.astype(np.intp), (~along_x).astype(np.intp)
    inner = (x - sx >= 0) & (x + sx < w) & (y - sy >= 0) & (y + sy < h)
    xm, xp = np.where(inner, x - sx, x), np.where(inner, x + sx, x)
    ym, yp = np.where(inner, y - sy, y), np.where(inner, y + sy, y)

    def magnitude(yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        return np.hypot(gx[yy, xx].astype(np.float32), gy[yy, xx].astype(np.float32))

    m0 = np.hypot(gxp, gyp)
    mm, mp = magnitude(ym, xm), magnitude(yp, xp)
    denom = mm - 2.0 * m0 + mp
    ok = inner & (denom < 0)
    offset = np.zeros(points.shape[0], np.float64)
    offset[ok] = np.clip(0.5 * (mm[ok] - mp[ok]) / denom[ok], -0.5, 0.5)
    out[:, 0] += offset * sx
    out[:, 1] += offset * sy
    return out
