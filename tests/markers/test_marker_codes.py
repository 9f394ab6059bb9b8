"""The code book: enough ids, rotation invariance, and distance 2 between any two rotations."""

from __future__ import annotations

import numpy as np
import pytest

from labauto.vision import marker_codes as mc


def _rotations() -> np.ndarray:
    book = np.array(mc.code_book(), np.int64)
    return np.array([[mc.rotate(int(w), k) for k in range(mc.N_BITS)] for w in book])


def test_at_least_200_ids() -> None:
    assert mc.n_codes() >= 200


def test_every_rotation_of_another_code_differs_in_two_bits_or_more() -> None:
    rots = _rotations()  # (n, 14)
    words = rots.ravel()
    owner = np.repeat(np.arange(rots.shape[0]), mc.N_BITS)
    xor = words[:, None] ^ words[None, :]
    dist = np.zeros(xor.shape, np.int64)
    for bit in range(mc.N_BITS):
        dist += (xor >> bit) & 1
    other = owner[:, None] != owner[None, :]
    assert dist[other].min() >= 2


def test_codes_are_aperiodic_even_and_runs_are_short() -> None:
    rots = _rotations()
    assert all(len(set(r.tolist())) == mc.N_BITS for r in rots)
    for marker_id in range(mc.n_codes()):
        bits = mc.code_bits(marker_id)
        assert bits.sum() % 2 == 0 and mc.MIN_WEIGHT <= bits.sum() <= mc.MAX_WEIGHT
        doubled = np.concatenate((bits, bits))
        runs = np.diff(np.flatnonzero(np.diff(doubled) != 0))
        assert runs.max() <= mc.MAX_RUN


@pytest.mark.parametrize("marker_id", [0, 7, 199, 341])
def test_decode_any_rotation_and_refuse_one_flipped_bit(marker_id: int) -> None:
    bits = mc.code_bits(marker_id)
    for k in range(mc.N_BITS):
        read = np.roll(bits, k)
        found, turn = mc.decode(read)
        assert found == marker_id
        assert np.array_equal(np.roll(read, turn), bits)
        flipped = read.copy()
        flipped[(3 * k) % mc.N_BITS] ^= 1
        assert mc.decode(flipped) is None


def test_unknown_id_is_refused() -> None:
    with pytest.raises(ValueError, match="marker id"):
        mc.code_bits(mc.n_codes())
