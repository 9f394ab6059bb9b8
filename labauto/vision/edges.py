"""Colour Canny edges, ordered edge linking and sub-pixel refinement (section 3.1).

The paper combines Canny's hysteresis with a region growing that "collects all points of the edge
contour with a known sorting". We get the same ordered chains in three steps, written here in
numpy/OpenCV; the compiled kernel (:mod:`labauto.vision.kernels.edges`) does steps 2-3 and the
sampling below in one pass over the edge pixels with the same result:

1. ``cv2.Canny(gx, gy, low, high, L2gradient=True)`` on our own colour gradient (eq. 2);
2. the edge pixels are thinned to minimal 8-connected chains (:func:`thin_edges`: Canny leaves
   4-connected staircases that the tracer would meet only on its way back, out of order), then
   the outer boundary of every 8-connected edge component is traced in the 8-neighbourhood
   (Suzuki and Abe's border following, step for step as ``cv2.findContours(...,
   RETR_CCOMP, CHAIN_APPROX_NONE)`` traces it; hole boundaries are not traced: they repeat the
   same thin edge);
3. an open chain is traced out and back (A..B..A). We rotate such a trace to start at its first
   turnaround point (where the trace reverses, i.e. an end of the chain) and keep every pixel
   once, at its first visit (:func:`traces_to_chains`). An open chain comes out ordered from one
   end to the other; a closed thin loop comes out once around (its outer trace). Components
   with more than two ends (branches) keep all their pixels, branches following each other,
   which is what the paper's region growing gives too. Chains are listed in the order
   ``findContours`` lists the components (reverse raster order of their first pixels).

Sub-pixel refinement follows Devernay (1995): along the axis (x or y) closest to the gradient
direction, fit a parabola through the gradient magnitude at the edge pixel and its two neighbours
and move the point to the vertex (at most half a pixel). :func:`edge_contours` does steps 2-3,
the gradient lookup and the refinement in one kernel call.
"""

from __future__ import annotations

import threading
from types import ModuleType

import cv2
import numpy as np

from labauto.vision import kernels


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
_REMOVABLE_U8 = _REMOVABLE.view(np.uint8)  # the same table, as the kernel reads it
#: (dy, dx) of the ring neighbours N, NE, E, SE, S, SW, W, NW
_NEIGHBOURS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
#: thinning passes used by the linker (Canny output needs 1-2)
_THIN_PASSES = 2


def thin_edges(edges: np.ndarray, max_iter: int = 2) -> np.ndarray:
    """Thin an edge map to minimal 8-connected chains, working only on the edge pixels.

    Canny leaves 4-connected staircases and short two-pixel-thick runs; a boundary trace then
    meets some pixels only on its way back, which scrambles the order of the chain. We remove
    every pixel whose neighbours stay 8-connected without it and that is not a chain end (see
    :func:`_removable_table`). Pixels are decided in four checkerboard classes (parity of the
    row and of the linear index in the padded map, i.e. of x and y): two pixels of one class
    are never neighbours, so a class is decided at once without breaking a chain. A pass decides
    the four classes in turn; passes repeat until nothing changes or ``max_iter`` passes are
    done. The end of a two-pixel-thick run may lose a pixel per pass.

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
    binary = (_edge_map(edges) != 0).view(np.uint8)
    padded = cv2.copyMakeBorder(binary, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    kernel = kernels.compiled("edges")
    if kernel is not None:
        kernel.thin(padded, _REMOVABLE_U8, int(max_iter))
        return padded
    ys, xs = np.nonzero(padded)
    pixel_class = (ys % 2) * 2 + ((ys * padded.shape[1] + xs) % 2)
    classes = [(ys[pixel_class == c], xs[pixel_class == c]) for c in range(4)]
    for _ in range(max_iter):
        changed = False
        for y, x in classes:
            code = np.zeros(y.shape[0], np.uint8)
            for bit, (dy, dx) in enumerate(_NEIGHBOURS):
                code |= padded[y + dy, x + dx] << bit
            remove = _REMOVABLE[code] & (padded[y, x] != 0)
            changed |= bool(remove.any())
            padded[y[remove], x[remove]] = 0
        if not changed:
            break
    return padded


def link_edges(
    edges: np.ndarray, min_length: int = 1, max_length: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Collect the pixels of a binary edge map into ordered chains, each pixel once.

    Thinning (:func:`thin_edges`), the outer trace of every 8-connected component and
    :func:`traces_to_chains`, in one kernel call; see the module docstring.

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
    edges = _edge_map(edges)
    _limits(min_length, max_length)
    kernel = kernels.compiled("edges")
    if kernel is None:
        return _outer_chains(edges, min_length, max_length)
    return kernel.link(
        edges,
        _work_map(edges.shape),
        _REMOVABLE_U8,
        _THIN_PASSES,
        *_limits(min_length, max_length),
        workspace=_workspace(kernel),
    )


def _outer_chains(
    edges: np.ndarray, min_length: int, max_length: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 2 and 3 of the module docstring: thin, trace the outer boundaries, chain."""
    thin = thin_edges(edges, _THIN_PASSES)
    traces, hierarchy = cv2.findContours(
        thin, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(-1, -1)
    )
    outer = [t for t, h in zip(traces, hierarchy[0], strict=True) if h[3] < 0] if traces else []
    return traces_to_chains(outer, edges.shape[1], min_length, max_length)


def edge_contours(
    edges: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    min_length: int = 1,
    max_length: int | None = None,
    subpixel: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ordered chains of an edge map with their gradients and (sub-pixel) positions.

    :func:`link_edges`, :func:`gradient_at` and :func:`refine_subpixel` (with the compiled
    kernel: in one call, on one thread).

    Parameters
    ----------
    edges : np.ndarray
        uint8 HxW map, nonzero on edge pixels.
    gx, gy : np.ndarray
        int16 HxW gradient the edges were found on.
    min_length, max_length : int
        Keep chains with ``min_length <= n_points <= max_length`` (None: no upper bound).
    subpixel : bool
        Refine the points (else they are the pixel coordinates).

    Returns
    -------
    points : np.ndarray
        (N, 2) float64 points ``(x, y)`` of all chains, concatenated in order.
    offsets : np.ndarray
        (K + 1,) int64; chain k is ``points[offsets[k]:offsets[k + 1]]``.
    gradients : np.ndarray
        (N, 2) float32 gradient ``(gx, gy)`` at each pixel.
    closed : np.ndarray
        (K,) bool: the first and last pixels of a chain of more than two are 8-neighbours.
    """
    edges = _edge_map(edges)
    gx, gy = _gradient_pair(gx, gy, edges.shape)
    _limits(min_length, max_length)
    kernel = kernels.compiled("edges")
    if kernel is not None:
        return kernel.link(
            edges,
            _work_map(edges.shape),
            _REMOVABLE_U8,
            _THIN_PASSES,
            *_limits(min_length, max_length),
            gx,
            gy,
            bool(subpixel),
            _workspace(kernel),
        )
    pixels, offsets = _outer_chains(edges, min_length, max_length)
    points, gradients = _sample(pixels, gx, gy, subpixel)
    first, last = pixels[offsets[:-1]], pixels[np.maximum(offsets[1:] - 1, 0)]
    closed = (np.diff(offsets) > 2) & np.all(np.abs(first - last) <= 1, axis=1)
    return points, offsets, gradients, closed


def traces_to_chains(
    traces: list[np.ndarray], width: int, min_length: int = 1, max_length: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Turn boundary traces (``cv2.findContours`` output) into chains with each pixel once.

    A trace that visits most of its pixels twice (fewer than 3/4 of its points are pixels not
    met before: an open chain traced out and back) is rotated to start at its first turnaround
    (``t[i - 1] == t[i + 1]``, indices modulo its length); closed loops keep their start (a
    one-pixel spur on a loop must not open it). Then only the first visit of every pixel is
    kept, over all traces in order (a pixel of an earlier trace is not repeated). See the
    module docstring.

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
    low, high = _limits(min_length, max_length)
    if not traces:
        return np.empty((0, 2), np.int32), np.zeros(1, np.int64)
    lengths = np.fromiter((len(t) for t in traces), np.int64, len(traces))
    pts = np.ascontiguousarray(np.concatenate(traces).reshape(-1, 2), np.int32)
    if width < 1:
        raise ValueError(f"width must be >= 1, got {width}")
    kernel = kernels.compiled("edges")
    if kernel is not None:
        return kernel.chains_from_traces(pts, lengths, int(width), low, high)
    if pts.shape[0] and (pts.min() < 0 or pts[:, 0].max() >= width):
        raise ValueError("chains_from_traces: points must lie in 0 <= x < width, 0 <= y")
    linear = pts[:, 1].astype(np.int64) * width + pts[:, 0]
    seen = np.zeros(int(linear.max()) + 1 if linear.size else 0, bool)
    chains, starts = [], np.cumsum(lengths) - lengths
    for start, n in zip(starts.tolist(), lengths.tolist(), strict=True):
        lin = linear[start : start + n]
        rotation = 0
        if n > 2 and np.unique(lin[~seen[lin]]).shape[0] < 0.75 * n:  # out and back
            turns = np.flatnonzero(np.roll(lin, 1) == np.roll(lin, -1))
            rotation = int(turns[0]) if turns.shape[0] else 0
        order = np.roll(np.arange(n), -rotation)
        _, first = np.unique(lin[order], return_index=True)  # each pixel's first visit
        keep = order[np.sort(first)]
        keep = keep[~seen[lin[keep]]]
        seen[lin] = True
        if keep.shape[0] >= low and (high < 0 or keep.shape[0] <= high):
            chains.append(pts[start + keep])
    if not chains:
        return np.empty((0, 2), np.int32), np.zeros(1, np.int64)
    offsets = np.concatenate(([0], np.cumsum([c.shape[0] for c in chains]))).astype(np.int64)
    return np.concatenate(chains), offsets


def gradient_at(gx: np.ndarray, gy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Return the (N, 2) float32 gradient ``(gx, gy)`` at integer pixel ``points`` (x, y)."""
    return _sample(points, gx, gy, subpixel=False)[1]


def refine_subpixel(points: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Move edge pixels to the sub-pixel maximum of the gradient magnitude (Devernay).

    With ``m`` the float32 gradient magnitude and ``m-``, ``m0``, ``m+`` its values at the
    pixel's two neighbours along the chosen axis and at the pixel, the offset is
    ``0.5 (m- - m+) / (m- - 2 m0 + m+)``, computed in float32 and clipped to +-0.5.

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
        (whichever is closer to its gradient direction; x on ties); points on the image border
        and points that are not a strict local maximum stay where they are.
    """
    return _sample(points, gx, gy, subpixel=True)[0]


def _sample(
    points: np.ndarray, gx: np.ndarray, gy: np.ndarray, subpixel: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) float64 positions (refined if ``subpixel``) and float32 gradients at ``points``."""
    gx, gy = _gradient_pair(gx, gy)
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.issubdtype(pts.dtype, np.integer):
        raise ValueError(f"points must be (N, 2) integer (x, y), got {pts.dtype} {pts.shape}")
    h, w = gx.shape
    if pts.shape[0] and (pts.min() < 0 or pts[:, 0].max() >= w or pts[:, 1].max() >= h):
        raise ValueError(f"points must lie inside the {w}x{h} gradient image")
    pts = np.ascontiguousarray(pts, np.int32)
    kernel = kernels.compiled("edges")
    if kernel is not None:
        out_points = np.empty((pts.shape[0], 2), np.float64)
        out_gradients = np.empty((pts.shape[0], 2), np.float32)
        kernel.sample(pts, gx, gy, bool(subpixel), out_points, out_gradients)
        return out_points, out_gradients
    x, y = pts[:, 0].astype(np.intp), pts[:, 1].astype(np.intp)
    a, b = gx[y, x], gy[y, x]
    gradients = np.column_stack((a, b)).astype(np.float32)
    points = pts.astype(np.float64)
    if not subpixel:
        return points, gradients
    # the neighbours along the axis closer to the gradient (x on ties); at the border none
    along_x = np.abs(a.astype(np.int32)) >= np.abs(b.astype(np.int32))
    inner = np.where(along_x, (x >= 1) & (x < w - 1), (y >= 1) & (y < h - 1))
    sx, sy = (along_x & inner).astype(np.intp), (~along_x & inner).astype(np.intp)

    def magnitude(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        gxs, gys = gx[ys, xs].astype(np.float64), gy[ys, xs].astype(np.float64)
        return np.sqrt(gxs * gxs + gys * gys).astype(np.float32)

    m0, m_minus, m_plus = magnitude(x, y), magnitude(x - sx, y - sy), magnitude(x + sx, y + sy)
    denom = (m_minus - np.float32(2.0) * m0) + m_plus
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = (np.float32(0.5) * (m_minus - m_plus)) / denom
    offset = np.where(denom < 0, np.clip(offset, np.float32(-0.5), np.float32(0.5)), 0)
    points[:, 0] += np.where(along_x, offset, 0).astype(np.float64)
    points[:, 1] += np.where(along_x, 0, offset).astype(np.float64)
    return points, gradients


def _edge_map(edges: np.ndarray) -> np.ndarray:
    """Validate an HxW edge map; return it as C-contiguous uint8 (nonzero on edges)."""
    if not isinstance(edges, np.ndarray) or edges.ndim != 2 or edges.size == 0:
        shape = getattr(edges, "shape", None)
        raise ValueError(f"edges must be a non-empty HxW numpy array, got shape {shape}")
    if edges.dtype != np.uint8:
        return (edges != 0).view(np.uint8)
    return np.ascontiguousarray(edges)


def _gradient_pair(
    gx: np.ndarray, gy: np.ndarray, shape: tuple[int, ...] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Validate an int16 HxW gradient pair (of ``shape`` if given); return it C-contiguous."""
    for name, g in (("gx", gx), ("gy", gy)):
        if not isinstance(g, np.ndarray) or g.ndim != 2 or g.dtype != np.int16:
            raise ValueError(f"{name} must be an int16 HxW numpy array")
    if gx.shape != gy.shape or (shape is not None and gx.shape != shape):
        raise ValueError(
            f"gx {gx.shape} and gy {gy.shape} must have one shape"
            + (f", that of the edge map {shape}" if shape is not None else "")
        )
    return np.ascontiguousarray(gx), np.ascontiguousarray(gy)


def _limits(min_length: int, max_length: int | None) -> tuple[int, int]:
    """Length filter as the kernel takes it (no upper bound: -1)."""
    if max_length is not None and max_length < 0:
        raise ValueError(f"max_length must be None or >= 0, got {max_length}")
    return int(min_length), -1 if max_length is None else int(max_length)


_WORK = threading.local()


def _workspace(kernel: ModuleType) -> object:
    """This thread's buffers for the linker (kept between calls: see ``kernels.edges``)."""
    workspace = getattr(_WORK, "workspace", None)
    if workspace is None:
        workspace = _WORK.workspace = kernel.Workspace()
    return workspace


def _work_map(shape: tuple[int, ...]) -> np.ndarray:
    """This thread's all-zero uint8 (H+2)x(W+2) work map for the linker (kept between calls).

    The kernel leaves it all zero; keeping it saves an image-sized allocation (page faults) and
    clearing per call.
    """
    work = getattr(_WORK, "map", None)
    if work is None or work.shape != (shape[0] + 2, shape[1] + 2):
        work = _WORK.map = np.zeros((shape[0] + 2, shape[1] + 2), np.uint8)
    return work
