"""Robust potentials and their auxiliary-point rules (Cohen's auxiliary-variable framework).

The joint energy of the two-step iteration is

    E(H, a) = 1/2 sum_i ||H(p_i) - a_i||^2 + sum_i P(d(a_i, Q))

with ``p_i`` the left points, ``Q`` the right point set and ``d(a, Q)`` the distance from an
auxiliary point to its closest right point. For fixed ``H`` the best ``a_i`` lies on the
segment from the prediction ``x_i = H(p_i)`` to its closest right point ``c_i`` (the closest
point of ``x_i`` is also the closest point of every point on that segment), at a distance
``s = step(r)`` from ``x_i`` where ``r = ||x_i - c_i||``: the step minimises the scalar
function ``1/2 s^2 + P(r - s)`` over ``s`` in ``[0, r]``.

Every potential is parameterised by the paper's interpolation weight ``lambda`` in (0, 1)
(for least squares ``a = (1 - lambda) x + lambda c``, i.e. the quadratic data weight is
``mu = lambda / (1 - lambda)``) and by a threshold in pixels, expressed as the distance
``r`` from the prediction to its closest point at which the potential's behaviour changes.
"""

from __future__ import annotations

import numpy as np


class Potential:
    """Base class: the penalty ``P`` on the auxiliary-to-closest distance and its step rule.

    Args:
        lambda_weight: Interpolation weight in (0, 1).
        threshold_px: Threshold in pixels (> 0); see each subclass.

    Raises:
        ValueError: If ``lambda_weight`` is not in (0, 1) or the threshold is not positive.

    """

    name = 'base'
    redescending = False
    # Closest distance from which a point's step is 0 and its penalty constant (None: no such
    # distance): a closest-point query may stop there (cKDTree distance_upper_bound).
    saturation_px: float | None = None

    def __init__(self, lambda_weight: float, threshold_px: float) -> None:
        """Store and check the parameters."""
        if not 0.0 < lambda_weight < 1.0:
            raise ValueError(f'lambda_weight must be in (0, 1), got {lambda_weight!r}')
        if not (np.isfinite(threshold_px) and threshold_px > 0):
            raise ValueError(f'threshold_px must be positive and finite, got {threshold_px!r}')
        self.lambda_weight = float(lambda_weight)
        self.threshold_px = float(threshold_px)
        self.mu = self.lambda_weight / (1.0 - self.lambda_weight)

    def penalty(self, distance: np.ndarray) -> np.ndarray:
        """Return ``P(d)`` for (N,) distances from auxiliary to closest points, pixels."""
        raise NotImplementedError

    def step(self, r: np.ndarray) -> np.ndarray:
        """Return how far (pixels) each auxiliary point moves from its prediction.

        Args:
            r: (N,) float64 distances from predictions to their closest right points.

        Returns:
            (N,) float64 steps ``s`` in ``[0, r]`` minimising ``1/2 s^2 + P(r - s)``.

        """
        raise NotImplementedError

    def point_energy(self, r: np.ndarray) -> np.ndarray:
        """Return ``min_s 1/2 s^2 + P(r - s)``: each point's share of the minimised energy."""
        s = self.step(r)
        return 0.5 * s * s + self.penalty(r - s)

    def __repr__(self) -> str:
        """Return the name and parameters."""
        return (f'{type(self).__name__}(lambda_weight={self.lambda_weight}, '
                f'threshold_px={self.threshold_px})')


class LeastSquares(Potential):
    """Quadratic ``P(d) = mu d^2 / 2``: ``a = (1 - lambda) x + lambda c``; no threshold.

    The threshold is used only for the final inlier decision.
    """

    name = 'least_squares'

    def penalty(self, distance: np.ndarray) -> np.ndarray:
        """Return ``mu d^2 / 2``."""
        return 0.5 * self.mu * distance * distance

    def step(self, r: np.ndarray) -> np.ndarray:
        """Return ``lambda r``."""
        return self.lambda_weight * r


class TruncatedQuadratic(Potential):
    """Truncated quadratic ``P(d) = min(alpha, mu d^2 / 2)`` (the paper's "inf" potential).

    ``alpha = lambda t^2 / 2`` puts the switch at ``r = t`` (the threshold): below it the
    auxiliary point is the least-squares one, above it ``a = x`` (the point is ignored).
    """

    name = 'truncated_quadratic'

    def __init__(self, lambda_weight: float, threshold_px: float) -> None:
        """Derive ``alpha`` from the threshold."""
        super().__init__(lambda_weight, threshold_px)
        self.alpha = 0.5 * self.lambda_weight * self.threshold_px ** 2
        # From r = t on, s = 0 and P(r) = alpha (mu t^2 / 2 >= alpha as mu >= lambda).
        self.saturation_px = self.threshold_px

    def penalty(self, distance: np.ndarray) -> np.ndarray:
        """Return ``min(alpha, mu d^2 / 2)``."""
        return np.minimum(self.alpha, 0.5 * self.mu * distance * distance)

    def step(self, r: np.ndarray) -> np.ndarray:
        """Return ``lambda r`` below the threshold, 0 above it."""
        return np.where(r < self.threshold_px, self.lambda_weight * r, 0.0)


class Huber(Potential):
    """Huber ``P(d) = mu d^2 / 2`` for ``d <= k``, ``mu (k d - k^2 / 2)`` beyond.

    With ``k = t (1 - lambda)`` the step is ``lambda min(r, t)``: least squares below the
    threshold ``t``, a bounded step of ``lambda t`` toward the closest point above it.
    """

    name = 'huber'

    def __init__(self, lambda_weight: float, threshold_px: float) -> None:
        """Derive the Huber corner ``k`` from the threshold."""
        super().__init__(lambda_weight, threshold_px)
        self.k = self.threshold_px * (1.0 - self.lambda_weight)

    def penalty(self, distance: np.ndarray) -> np.ndarray:
        """Return the scaled Huber function of the distance."""
        d = np.abs(distance)
        return self.mu * np.where(d <= self.k, 0.5 * d * d, self.k * d - 0.5 * self.k ** 2)

    def step(self, r: np.ndarray) -> np.ndarray:
        """Return ``lambda min(r, t)``."""
        return self.lambda_weight * np.minimum(r, self.threshold_px)


class GemanMcClure(Potential):
    """Redescending Geman-McClure ``P(d) = mu sigma^2 d^2 / (2 (sigma^2 + d^2))``.

    Quadratic (as least squares) for ``d << sigma``, bounded by ``mu sigma^2 / 2`` far away,
    smooth in between. ``sigma`` is the threshold. The step minimises the non-convex scalar
    function numerically (a grid over ``[0, r]``, then a bracketed refinement), which is
    exact to about 1e-4 of ``r``; the estimator's step check keeps the energy monotone
    regardless. Used with graduated non-convexity: start with a wide ``sigma`` and shrink.
    """

    name = 'geman_mcclure'
    redescending = True
    _GRID = np.linspace(0.0, 1.0, 17)

    def penalty(self, distance: np.ndarray) -> np.ndarray:
        """Return the scaled Geman-McClure function of the distance."""
        d2 = distance * distance
        s2 = self.threshold_px ** 2
        return 0.5 * self.mu * s2 * d2 / (s2 + d2)

    def _objective(self, s: np.ndarray, r: np.ndarray) -> np.ndarray:
        return 0.5 * s * s + self.penalty(r - s)

    def step(self, r: np.ndarray) -> np.ndarray:
        """Return the step minimising ``1/2 s^2 + P(r - s)`` on ``[0, r]``."""
        r = np.asarray(r, dtype=np.float64)
        grid = r[:, None] * self._GRID[None, :]
        values = self._objective(grid, r[:, None])
        best = np.argmin(values, axis=1)
        h = r / (len(self._GRID) - 1)
        lo = np.maximum(grid[np.arange(r.size), best] - h, 0.0)
        hi = np.minimum(grid[np.arange(r.size), best] + h, r)
        best_s = grid[np.arange(r.size), best]
        best_v = values[np.arange(r.size), best]
        # Golden-section refinement inside the bracket around the best grid value.
        ratio = 0.5 * (np.sqrt(5.0) - 1.0)
        c = hi - ratio * (hi - lo)
        d = lo + ratio * (hi - lo)
        fc = self._objective(c, r)
        fd = self._objective(d, r)
        for _ in range(12):
            left = fc < fd
            hi = np.where(left, d, hi)
            lo = np.where(left, lo, c)
            new_c = hi - ratio * (hi - lo)
            new_d = lo + ratio * (hi - lo)
            c, d = new_c, new_d
            fc = self._objective(c, r)
            fd = self._objective(d, r)
        cand = np.where(fc < fd, c, d)
        cand_v = np.minimum(fc, fd)
        return np.where(cand_v < best_v, cand, best_s)


POTENTIALS: dict[str, type[Potential]] = {
    cls.name: cls for cls in (LeastSquares, TruncatedQuadratic, Huber, GemanMcClure)
}


def make_potential(name: str, lambda_weight: float, threshold_px: float) -> Potential:
    """Build a potential by name.

    Args:
        name: One of ``least_squares``, ``truncated_quadratic``, ``huber``,
            ``geman_mcclure``.
        lambda_weight: Interpolation weight in (0, 1).
        threshold_px: Threshold in pixels.

    Returns:
        The potential object.

    Raises:
        ValueError: For an unknown name or invalid parameters.

    """
    try:
        cls = POTENTIALS[name]
    except KeyError:
        raise ValueError(
            f'unknown potential {name!r}; choose one of {", ".join(POTENTIALS)}') from None
    return cls(lambda_weight, threshold_px)
