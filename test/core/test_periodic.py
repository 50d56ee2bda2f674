"""Period vectors: the repeats of a checkerboard found, none on a texture that does not repeat."""

from __future__ import annotations

import cv2
from domplane_ros.core.periodic import period_vectors
import numpy as np
import pytest


def _checker(square: int, angle_deg: float, size: int = 160) -> np.ndarray:
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float64)
    a = np.radians(angle_deg)
    u = (np.cos(a) * xs + np.sin(a) * ys) / square
    v = (-np.sin(a) * xs + np.cos(a) * ys) / square
    board = ((np.floor(u) + np.floor(v)) % 2) * 200 + 30
    return cv2.GaussianBlur(board.astype(np.float32), (0, 0), 0.7)


@pytest.mark.parametrize('square, angle_deg', [(6, 0.0), (8, 20.0), (10, -35.0)])
def test_checkerboard_repeats_along_its_diagonals(square, angle_deg):
    image = _checker(square, angle_deg)
    mask = np.zeros(image.shape, bool)
    mask[20:140, 30:150] = True
    vectors = period_vectors(image, mask)
    assert vectors.shape == (2, 2)
    a = np.radians(angle_deg)
    # A checkerboard repeats one square along both board axes at once (black to black): its
    # repeats are the lattice spanned by the two diagonals.
    basis = square * np.array([[np.cos(a) - np.sin(a), np.sin(a) + np.cos(a)],
                               [np.cos(a) + np.sin(a), np.sin(a) - np.cos(a)]]).T
    for vector in vectors:
        steps = np.linalg.solve(basis, vector)
        assert np.abs(steps).sum() <= 2  # the shortest repeats, not far multiples
        assert np.linalg.norm(basis @ np.round(steps) - vector) < 1.5, (vector, basis)
    cross = vectors[0, 0] * vectors[1, 1] - vectors[0, 1] * vectors[1, 0]
    assert abs(cross) > 0.5 * square ** 2  # two directions, not one twice


def test_blobby_texture_and_empty_mask_have_no_period():
    rng = np.random.default_rng(3)
    noise = cv2.GaussianBlur(rng.standard_normal((160, 160)).astype(np.float32), (0, 0), 2.0)
    assert period_vectors(noise, np.ones(noise.shape, bool)).shape == (0, 2)
    assert period_vectors(noise, np.zeros(noise.shape, bool)).shape == (0, 2)
    with pytest.raises(ValueError, match='mask of its shape'):
        period_vectors(noise, np.ones((10, 10), bool))


def test_a_repeat_is_found_however_its_peak_rounds_to_float32():
    # A random texture tiled with a period of 17 x 13 pixels under masks of random holes: the
    # normalised autocorrelation's peak at the period is a float64 value, and its local-maximum
    # test once compared it with cv2.dilate's float32: a peak whose float32 rounded up was not
    # its own maximum, and the period was lost on about half the masks (a 32 cm checker,
    # rendered floors_rough 23028, whose look-alike one period off was then published).
    rng = np.random.default_rng(17)
    tile = rng.uniform(20.0, 230.0, (13, 17))
    image = np.tile(tile, (10, 8))[:120, :130]
    image = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 0.8)
    for seed in range(24):
        holes = cv2.resize(np.random.default_rng(seed).uniform(0, 1, (12, 13)), (130, 120),
                           interpolation=cv2.INTER_NEAREST) < 0.3
        vectors = period_vectors(image, ~holes)
        periods = sorted(tuple(abs(v) + 0.0) for v in vectors)
        assert periods == [(0.0, 13.0), (17.0, 0.0)], (seed, periods)


@pytest.mark.parametrize('width', [4, 5, 8, 12])
def test_stripes_give_their_one_period_not_a_neighbour_of_its_peak(width):
    # Diagonal stripes repeat only by shifts that move x + y by a multiple of two widths (or
    # along the stripes): every vector returned must be such a repeat, not a neighbour of one
    # (the local maxima are compared exactly, so a plateau's members are not all peaks).
    ys, xs = np.mgrid[0:64, 0:64]
    image = (((xs + ys) // width) % 2 * 200 + 30).astype(np.float32)
    vectors = period_vectors(cv2.GaussianBlur(image, (0, 0), 0.7), np.ones((64, 64), bool))
    assert vectors.shape[0] >= 1
    for vector in vectors:
        # Every repeat of the stripes shifts x + y by a multiple of two widths.
        assert abs(vector[0] + vector[1]) % (2 * width) < 1e-9, (width, vectors)
