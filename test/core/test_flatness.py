"""One plane or several: the residual flow over a plane's pixels, on pairs with known shifts."""

from __future__ import annotations

from domplane_ros.core.flatness import residual_flow_px
import numpy as np
import pytest
from truth import two_depths


def _shift(dx: float) -> np.ndarray:
    return np.array([[1.0, 0.0, -dx], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def test_one_plane_is_flat_and_a_fit_through_two_depths_is_not():
    support = np.ones((60, 80), bool)
    left, right = two_depths(6.0, 6.0)
    assert residual_flow_px(left, right, _shift(6.0), support) < 0.1
    left, right = two_depths(5.0, 7.0)
    # The plane half-way between: both halves 1 px off it.
    assert residual_flow_px(left, right, _shift(6.0), support) == pytest.approx(1.0, abs=0.25)
    assert residual_flow_px(left, right, _shift(6.0), np.zeros((60, 80), bool)) == np.inf
    with pytest.raises(ValueError, match='one size'):
        residual_flow_px(left, right[:, :100], _shift(6.0), support)
