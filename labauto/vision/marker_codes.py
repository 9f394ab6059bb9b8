"""The code and the geometry of labauto's coded circular markers (Ahn / AICON style).

The paper (section 4.2) calibrates with the coded markers of Ahn: a filled centre circle
surrounded by a concentric code ring cut into angular sectors, each sector ink (bit 1) or
paper (bit 0), as in AICON's and Schneider's ring codes. Ours:

Geometry, as multiples of the centre circle's radius ``r``:

* centre circle (ink): radius ``1``;
* paper gap: ``1`` to ``RING_INNER`` (2.0);
* code ring: ``RING_INNER`` (2.0) to ``RING_OUTER`` (3.0), ``N_BITS`` (14) equal sectors of
  360/14 = 25.7 degrees, bit ``k`` covering ``[k, k + 1) * 360/14`` degrees;
* quiet zone (paper): out to ``QUIET_RADIUS`` (3.6); nothing else may be printed there.

So a marker is ``2 * QUIET_RADIUS * r`` = 7.2 r across; a 10 px centre circle makes a 72 px
marker. The ring's inner and outer edges are circles concentric with the centre circle: their
arcs give two more concentric conics, from which the projected centre is found free of
perspective bias (:mod:`labauto.vision.concentric`).

Code: a marker's id is read as 14 bits around the ring from an unknown starting sector, so a
code is a *necklace* (a word up to rotation). The code book holds the binary necklaces of
length 14 that are

* of even weight (an even number of ink sectors): two different even-weight words differ in at
  least 2 bits, and rotations keep the weight, so **any rotation of one code is at least
  Hamming distance 2 from any rotation of another** (a single misread bit never gives another
  valid id: it gives an odd word, which is refused);
* aperiodic (its 14 rotations are all different), so the read also fixes the marker's
  in-plane rotation;
* of weight 4 to 10, with no run of ink or paper longer than 4 sectors (103 degrees): the
  ring's edges are spread around the circle (for the concentric fit), and no ink run is a
  near-full annulus or a lone tiny blob pair.

That leaves 342 codes; ids are their index in the ascending order of each necklace's smallest
rotation read as a 14-bit integer (bit 0 the least significant). The book and the table of all
16384 words are built once, on first use (about 30 ms; :func:`warm` does it ahead).
"""

from __future__ import annotations

import functools

import numpy as np

#: Sectors (bits) of the code ring.
N_BITS = 14
#: Inner and outer radius of the code ring, in centre-circle radii.
RING_INNER = 2.0
RING_OUTER = 3.0
#: Radius of the marker with its quiet zone, in centre-circle radii.
QUIET_RADIUS = 3.6
#: Weight (ink sectors) range and longest run of equal bits of a valid code.
MIN_WEIGHT, MAX_WEIGHT, MAX_RUN = 4, 10, 4

_MASK = (1 << N_BITS) - 1


def rotate(word: int, k: int) -> int:
    """Rotate a ``N_BITS``-bit word by ``k`` sectors (bit ``i`` moves to ``i + k``)."""
    k %= N_BITS
    return ((word << k) | (word >> (N_BITS - k))) & _MASK


def canonical(word: int) -> int:
    """The smallest rotation of ``word`` (the necklace's representative)."""
    return min(rotate(word, k) for k in range(N_BITS))


def _all_rotations() -> np.ndarray:
    """(2**N_BITS, N_BITS) every word's rotations by 0..N_BITS-1 sectors."""
    words = np.arange(1 << N_BITS, dtype=np.int64)[:, None]
    k = np.arange(N_BITS, dtype=np.int64)[None, :]
    return ((words << k) | (words >> ((N_BITS - k) % N_BITS))) & _MASK


def _longest_runs(words: np.ndarray) -> np.ndarray:
    """Longest cyclic run of equal bits of each word."""
    bits = (words[:, None] >> np.arange(N_BITS)) & 1
    doubled = np.concatenate((bits, bits), axis=1)
    best = np.ones(len(words), np.int64)
    run = np.ones(len(words), np.int64)
    for i in range(1, 2 * N_BITS):
        run = np.where(doubled[:, i] == doubled[:, i - 1], run + 1, 1)
        best = np.maximum(best, run)
    return np.minimum(best, N_BITS)


@functools.cache
def code_book() -> tuple[int, ...]:
    """All codes, ``code_book()[id]`` being the canonical word of marker ``id``."""
    rotations = _all_rotations()
    words = rotations[:, 0]
    weight = ((words[:, None] >> np.arange(N_BITS)) & 1).sum(axis=1)
    canonical_word = rotations.min(axis=1)
    aperiodic = ~(rotations[:, 1:] == words[:, None]).any(axis=1)
    valid = (
        (weight % 2 == 0)
        & (weight >= MIN_WEIGHT)
        & (weight <= MAX_WEIGHT)
        & aperiodic
        & (_longest_runs(words) <= MAX_RUN)
        & (canonical_word == words)
    )
    return tuple(int(w) for w in words[valid])


def n_codes() -> int:
    """How many marker ids there are (342)."""
    return len(code_book())


def code_bits(marker_id: int) -> np.ndarray:
    """The ``N_BITS`` bits (0/1, uint8) of marker ``marker_id``, bit 0 first.

    Raises
    ------
    ValueError
        If there is no such id.
    """
    book = code_book()
    if not 0 <= int(marker_id) < len(book):
        raise ValueError(f"marker id must be in 0..{len(book) - 1}, got {marker_id}")
    word = book[int(marker_id)]
    return np.array([(word >> i) & 1 for i in range(N_BITS)], np.uint8)


@functools.cache
def _word_table() -> tuple[np.ndarray, np.ndarray]:
    """For every 14-bit word: its marker id (-1: none) and the rotation onto the code."""
    ids = np.full(1 << N_BITS, -1, np.int32)
    turns = np.zeros(1 << N_BITS, np.int8)
    for marker_id, word in enumerate(code_book()):
        for k in range(N_BITS):
            # rotate(read, k) == word  <=>  read == rotate(word, -k)
            read = rotate(word, -k)
            ids[read], turns[read] = marker_id, k
    return ids, turns


def warm() -> None:
    """Build the code book and the decoding table now (they are cached)."""
    _word_table()


def decode_words(words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ids (-1 where no code) and rotations of many words read around rings at once.

    Parameters
    ----------
    words : np.ndarray
        Integer words, bit ``i`` the ``i``-th sector read.

    Returns
    -------
    ids, rotations : np.ndarray
        ``rotate(word, rotation) == code_book()[id]`` where ``id >= 0``.
    """
    ids, turns = _word_table()
    w = np.asarray(words, np.int64) & _MASK
    return ids[w], turns[w].astype(np.int64)


def decode(bits: np.ndarray) -> tuple[int, int] | None:
    """The id of a word read around the ring, and its rotation, or None when it is no code.

    Parameters
    ----------
    bits : np.ndarray
        ``N_BITS`` values 0/1, bit 0 the first sector read.

    Returns
    -------
    (id, k) or None
        ``k`` is the rotation with ``rotate(read word, k) == code_book()[id]``.
    """
    flat = np.asarray(bits).ravel()
    if flat.size != N_BITS:
        raise ValueError(f"a code has {N_BITS} bits, got {flat.size}")
    word = int(sum(int(b) << i for i, b in enumerate(flat)))
    ids, turns = decode_words(np.array([word]))
    return None if ids[0] < 0 else (int(ids[0]), int(turns[0]))
