"""Plane homographies: normalised weighted DLT, Euclidean refinement, transfer errors.

Conventions: points are ``(N, 2) float64`` arrays of pixel coordinates ``(x, y)``; a
homography is a ``(3, 3) float64`` array mapping ``(x, y, 1)`` of the first set to the
second, scaled so that ``H[2, 2] == 1`` where that is possible (otherwise unit Frobenius
norm). Fitting functions return the matrix, or a
:class:`~domplane_ros.core.result.FailedEstimate` that carries the reason: they never
return a non-finite matrix and never let a numpy error escape for degenerate data. Wrong
shapes or types are programming errors and raise ``ValueError``.
"""

from __future__ import annotations

import math

from domplane_ros.core.result import FailedEstimate
import numpy as np

# Points whose projective depth falls below this are "at infinity": they are placed far away
# (finite) so that a closest-point search treats them as unmatched.
_MIN_W = 1e-9
_FAR_PX = 1e9
# Public names for code that maps many points at once as apply_homography does.
MIN_W = _MIN_W
FAR_PX = _FAR_PX
# A point set whose second singular value (centred) is at most this fraction of its first is
# collinear: it cannot fix a homography.
_COLLINEAR_RATIO = 1e-6


def as_points(points: object, name: str = 'points') -> np.ndarray:
    """Return ``points`` as a ``(N, 2) float64`` array.

    Args:
        points: Anything array-like of shape (N, 2).
        name: Name used in the error message.

    Returns:
        (N, 2) float64 array (a copy only when a conversion is needed).

    Raises:
        ValueError: If the shape is not (N, 2) or the values are not numbers.

    """
    return as_rows(points, 2, name, 'coordinates')


def as_rows(values: object, columns: int, name: str, what: str, layout: str = '',
            empty_ok: bool = False) -> np.ndarray:
    """Return ``values`` as a ``(N, columns) float64`` array, or raise ``ValueError``.

    Args:
        values: Anything array-like of shape (N, columns).
        columns: Values per row.
        name: Name used in the error messages.
        what: What the rows are, for the message (``'coordinates'``).
        layout: The row layout for the shape message (``' (x1, y1, x2, y2)'``), or ``''``.
        empty_ok: Whether an empty array of any shape gives ``(0, columns)``.

    """
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{name} must be numeric (N, {columns}) {what}') from err
    if empty_ok and arr.size == 0:
        return np.zeros((0, columns), np.float64)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ValueError(f'{name} must have shape (N, {columns}){layout}, got {arr.shape}')
    return arr


def as_homography(matrix: object, name: str = 'homography') -> np.ndarray:
    """Return ``matrix`` as a ``(3, 3) float64`` array (9 row-major values are accepted).

    Raises:
        ValueError: If it does not hold 9 numbers.

    """
    try:
        arr = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{name} must be numeric') from err
    if arr.shape == (9,):
        arr = arr.reshape(3, 3)
    if arr.shape != (3, 3):
        raise ValueError(f'{name} must have shape (3, 3) or (9,), got {arr.shape}')
    return arr


def as_valid_homography(matrix: object, name: str = 'homography') -> np.ndarray:
    """Return ``matrix`` as a finite, non-singular ``(3, 3) float64`` array.

    For public functions that take a homography to use, not to fit (mask, verification).

    Raises:
        ValueError: If it is not numeric, not (3, 3), not finite or singular; the message
            names the problem.

    """
    try:
        hom = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{name} must be a (3, 3) array of numbers: {err}') from err
    if hom.shape != (3, 3):
        raise ValueError(f'{name} must have shape (3, 3), got {hom.shape}')
    if not np.all(np.isfinite(hom)):
        raise ValueError(f'{name} must be finite, got non-finite entries')
    # The estimator's own test (check_homography), so that every homography it returns as a
    # plane can be verified and masked: a determinant test of the max-scaled matrix refused a
    # plane the estimator accepted (condition number 3e8), and the search raised.
    if check_homography(hom):
        raise ValueError(f'{name} is singular')
    return hom


def resize_homography(sx: float, sy: float) -> np.ndarray:
    """Map full-size pixel centres to resized pixel centres: ``x' = sx (x + 0.5) - 0.5``.

    Returns:
        (3, 3) float64, the pixel map of an image resized by ``sx`` across and ``sy`` down.

    """
    return np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])


def check_homography(matrix: np.ndarray) -> str:
    """Return why ``matrix`` is not a usable homography, or ``''`` if it is.

    Args:
        matrix: (3, 3) float64.

    Returns:
        An empty string for a finite, well-conditioned matrix; else the reason.

    """
    if not np.all(np.isfinite(matrix)):
        return 'homography has non-finite entries'
    s = np.linalg.svd(matrix, compute_uv=False)
    if s[0] <= 0 or s[2] / s[0] < 1e-10:
        return 'homography is singular'
    return ''


def _norm(array: np.ndarray) -> float:
    """Return the Frobenius norm of a float64 array, as ``np.linalg.norm`` computes it."""
    flat = array.ravel()
    return math.sqrt(float(flat.dot(flat)))


def normalise_scale(matrix: np.ndarray) -> np.ndarray:
    """Scale a homography so that ``H[2, 2] == 1``, or to unit Frobenius norm if that is ~0."""
    norm = _norm(matrix)
    if abs(matrix[2, 2]) > 1e-12 * norm:
        return matrix / matrix[2, 2]
    return matrix / norm


def apply_homography(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map points through a homography.

    Points whose projective depth is (almost) zero map to a far-away finite position, so the
    output is always finite for finite input.

    Args:
        matrix: (3, 3) float64 homography.
        points: (N, 2) float64 pixel coordinates.

    Returns:
        (N, 2) float64 mapped coordinates.

    """
    x = points[:, 0]
    y = points[:, 1]
    u = matrix[0, 0] * x + matrix[0, 1] * y + matrix[0, 2]
    v = matrix[1, 0] * x + matrix[1, 1] * y + matrix[1, 2]
    w = matrix[2, 0] * x + matrix[2, 1] * y + matrix[2, 2]
    small = np.abs(w) < _MIN_W
    if np.any(small):
        w = np.where(small, _MIN_W, w)
        out = np.stack([u / w, v / w], axis=1)
        return np.clip(out, -_FAR_PX, _FAR_PX)
    return np.stack([u / w, v / w], axis=1)


def corner_distance_px(first: np.ndarray, second: np.ndarray, width: int, height: int) -> float:
    """Return the largest distance between two homographies' images of the image corners.

    Args:
        first: (3, 3) float64 homography.
        second: (3, 3) float64 homography.
        width: Image width, pixels.
        height: Image height, pixels.

    Returns:
        ``max_c ||first(c) - second(c)||`` over the four corners of a ``width`` x ``height``
        image, pixels (inf if a corner maps to infinity).

    """
    corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [width - 1.0, height - 1.0],
                        [0.0, height - 1.0]])
    with np.errstate(divide='ignore', invalid='ignore'):
        diff = apply_homography(first, corners) - apply_homography(second, corners)
        distance = float(np.max(np.linalg.norm(diff, axis=1)))
    return distance if math.isfinite(distance) else math.inf


def transfer_error(matrix: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Return the one-sided transfer error ``||H(src_i) - dst_i||`` in pixels, shape (N,)."""
    return np.linalg.norm(apply_homography(matrix, src) - dst, axis=1)


def similarity_normaliser(points: np.ndarray) -> np.ndarray:
    """Return Hartley's (3, 3) similarity: centroid to the origin, mean distance sqrt(2).

    Args:
        points: (N, 2) float64, N >= 1, finite.

    Returns:
        (3, 3) float64 similarity transform ``T`` with ``T (x, y, 1)`` normalised.

    """
    centre = points.mean(axis=0)
    mean_dist = np.mean(np.linalg.norm(points - centre, axis=1))
    scale = np.sqrt(2.0) / mean_dist if mean_dist > 1e-12 else 1.0
    return np.array([[scale, 0.0, -scale * centre[0]],
                     [0.0, scale, -scale * centre[1]],
                     [0.0, 0.0, 1.0]])


def _transform(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a similarity (no projective part) to (N, 2) points."""
    return points * t[0, 0] + t[:2, 2]


def count_distinct(points: np.ndarray, enough: int) -> int:
    """Count the distinct rows of (N, 2) points, stopping early once ``enough`` are certain.

    A projection on a generic direction is distinct for distinct points almost always, and
    distinct projections prove distinct points, so the fast path is exact whenever it answers;
    otherwise the exact row-wise count is taken.
    """
    projected = np.unique(points[:, 0] + 0.7548776662466927 * points[:, 1])
    if projected.shape[0] >= enough:
        return int(projected.shape[0])
    return int(np.unique(points, axis=0).shape[0])


def point_set_reason(points: np.ndarray, side: str) -> str:
    """Return why a point set cannot fix a homography, or ``''`` if it can.

    Args:
        points: (N, 2) float64 finite points.
        side: Name of the set in the reason (``'left'``, ``'source'``, ...).

    Returns:
        ``''``, or the reason: fewer than 4 points, fewer than 4 distinct points, or all
        points (nearly) on one line.

    """
    if points.shape[0] < 4:
        return f'need at least 4 {side} points, got {points.shape[0]}'
    if count_distinct(points, 4) < 4:
        return f'fewer than 4 distinct {side} points'
    centred = points - points.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[1] <= _COLLINEAR_RATIO * max(sv[0], 1e-300):
        return f'{side} points are collinear'
    return ''


def _degenerate_reason(src: np.ndarray, dst: np.ndarray,
                       weights: np.ndarray | None) -> str:
    if src.shape != dst.shape:
        return f'point sets differ in shape: {src.shape} and {dst.shape}'
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        return 'points have non-finite coordinates'
    if weights is not None:
        if weights.shape != (src.shape[0],):
            return f'weights must have shape ({src.shape[0]},), got {weights.shape}'
        if not np.all(np.isfinite(weights)) or np.any(weights < 0):
            return 'weights must be finite and non-negative'
        src = src[weights > 0]
        dst = dst[weights > 0]
    if src.shape[0] < 4:
        return f'need at least 4 point pairs, got {src.shape[0]}'
    return point_set_reason(src, 'source') or point_set_reason(dst, 'destination')


def _dlt_system(s: np.ndarray, d: np.ndarray, w: np.ndarray | None) -> np.ndarray:
    """Return the (max(2N, 9), 9) DLT matrix of normalised pairs ``(s_i, d_i)``, row-weighted.

    At least 9 rows, so that the SVD also returns the null vector for 4 points.
    """
    n = s.shape[0]
    a = np.zeros((max(2 * n, 9), 9))
    ones = np.ones(n)
    ax = a[:2 * n]
    ax[0::2, 0] = -s[:, 0]
    ax[0::2, 1] = -s[:, 1]
    ax[0::2, 2] = -ones
    ax[0::2, 6] = d[:, 0] * s[:, 0]
    ax[0::2, 7] = d[:, 0] * s[:, 1]
    ax[0::2, 8] = d[:, 0]
    ax[1::2, 3] = -s[:, 0]
    ax[1::2, 4] = -s[:, 1]
    ax[1::2, 5] = -ones
    ax[1::2, 6] = d[:, 1] * s[:, 0]
    ax[1::2, 7] = d[:, 1] * s[:, 1]
    ax[1::2, 8] = d[:, 1]
    if w is not None:
        a[:2 * n] *= np.repeat(np.sqrt(w), 2)[:, None]
    return a


def fit_homography_dlt(src: np.ndarray, dst: np.ndarray,
                       weights: np.ndarray | None = None) -> np.ndarray | FailedEstimate:
    """Fit a homography by the normalised, weighted direct linear transform.

    Args:
        src: (N, 2) float64 source points.
        dst: (N, 2) float64 destination points, row i paired with ``src[i]``.
        weights: Optional (N,) non-negative row weights (each point's two equations are
            multiplied by ``sqrt(w)``).

    Returns:
        (3, 3) float64 homography with ``H[2, 2] == 1``, or :class:`FailedEstimate` for
        fewer than 4 pairs, repeated or collinear points, non-finite values, or a
        rank-deficient system.

    Raises:
        ValueError: If ``src`` or ``dst`` is not (N, 2).

    """
    src = as_points(src, 'src')
    dst = as_points(dst, 'dst')
    w = None if weights is None else np.asarray(weights, dtype=np.float64)
    reason = _degenerate_reason(src, dst, w)
    if reason:
        return FailedEstimate(reason)
    if w is not None:
        keep = w > 0
        src, dst, w = src[keep], dst[keep], w[keep]
    t_src = similarity_normaliser(src)
    t_dst = similarity_normaliser(dst)
    a = _dlt_system(_transform(t_src, src), _transform(t_dst, dst), w)
    try:
        _, sv, vt = np.linalg.svd(a, full_matrices=False)
    except np.linalg.LinAlgError:
        return FailedEstimate('DLT did not converge (SVD failure)')
    if sv[0] <= 0 or sv[-2] <= 1e-9 * sv[0]:
        return FailedEstimate('DLT system is rank deficient (degenerate configuration)')
    g = vt[-1].reshape(3, 3)
    h = np.linalg.inv(t_dst) @ g @ t_src
    reason = check_homography(h)
    if reason:
        return FailedEstimate(reason)
    return normalise_scale(h)


def _normal_layout() -> tuple[np.ndarray, np.ndarray]:
    """Return where ``J^T W J``'s 81 entries are in the flat 3x3 blocks ``[a, b, c, d, 0]``.

    With ``a = sum m m^T``, ``b = sum px m m^T``, ``c = sum py m m^T`` and
    ``d = sum (px^2 + py^2) m m^T`` (weighted), ``J^T W J = [[a, 0, -b], [0, a, -c],
    [-b^T, -c^T, d]]``: the flat index into ``concatenate(a, b, c, d, [0])`` (each block
    row-major) and the sign of every entry.
    """
    index = np.full((9, 9), 36, np.int64)
    sign = np.ones((9, 9))
    block = np.arange(9).reshape(3, 3)
    for rows, cols, first, transposed, negative in (
            (0, 0, 0, False, False), (3, 3, 0, False, False), (0, 6, 9, False, True),
            (6, 0, 9, True, True), (3, 6, 18, False, True), (6, 3, 18, True, True),
            (6, 6, 27, False, False)):
        index[rows:rows + 3, cols:cols + 3] = first + (block.T if transposed else block)
        sign[rows:rows + 3, cols:cols + 3] = -1.0 if negative else 1.0
    return index.ravel(), sign.ravel()


_NORMAL_INDEX, _NORMAL_SIGN = _normal_layout()
_GRAD_SIGN = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0, -1.0])
_DIAGONAL = np.arange(0, 81, 10)


def _normal_equations(m: np.ndarray, px: np.ndarray, py: np.ndarray, dst_n: np.ndarray,
                      weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Return Gauss-Newton's ``(J^T W J, J^T W r)`` (9 x 9, 9) of the transfer residuals.

    Args:
        m: (N, 3) float64 ``(x, y, 1) / w``, the homogeneous sources over their depths.
        px: (N,) float64 predicted x (normalised).
        py: (N,) float64 predicted y (normalised).
        dst_n: (N, 2) float64 normalised destinations.
        weights: Optional (N,) non-negative weights.

    """
    rx = px - dst_n[:, 0]
    ry = py - dst_n[:, 1]
    # The Jacobian of the x residual is [m, 0, -px m] and of the y residual
    # [0, m, -py m], with m = (x, y, 1) / w: assemble J^T J and J^T r from 3x3 blocks, all
    # from one product of the weighted m with [m, px m, py m, (px^2 + py^2) m, rx, ry, ...].
    mw = m if weights is None else m * weights[:, None]
    cols = np.empty((m.shape[0], 15))
    cols[:, 0:3] = m
    cols[:, 3:6] = m * px[:, None]
    cols[:, 6:9] = m * py[:, None]
    cols[:, 9:12] = m * (px * px + py * py)[:, None]
    cols[:, 12] = rx
    cols[:, 13] = ry
    cols[:, 14] = px * rx + py * ry
    prod = mw.T @ cols
    flat = np.empty(37)
    flat[:36] = prod[:, :12].reshape(3, 4, 3).transpose(1, 0, 2).ravel()
    flat[36] = 0.0
    normal = (flat[_NORMAL_INDEX] * _NORMAL_SIGN).reshape(9, 9)
    grad = prod[:, 12:15].T.ravel() * _GRAD_SIGN
    return normal, grad


class NormalisedRefiner:
    """Gauss-Newton refinement of a homography for a fixed source set.

    It minimises the Euclidean (transfer) energy ``1/2 sum_i w_i ||H(src_i) - dst_i||^2`` in
    pixels. The source points are normalised once (Hartley), the destination frame is fixed
    by a similarity given at construction, so the same object serves many refinements with
    different destinations, as the two-step iteration needs. Every accepted step lowers the
    energy: a step that does not is halved, then rejected, so the energy never increases.

    Args:
        src: (N, 2) float64 source points.
        dst_frame: (M, 2) float64 points that fix the destination normalisation (the right
            point set); a similarity of it is used for conditioning only.

    """

    def __init__(self, src: np.ndarray, dst_frame: np.ndarray) -> None:
        """Normalise the source points once."""
        self.t_src = similarity_normaliser(src)
        self.t_dst = similarity_normaliser(dst_frame)
        self.t_dst_inv = np.linalg.inv(self.t_dst)
        self.t_src_inv = np.linalg.inv(self.t_src)
        self.src_n = _transform(self.t_src, src)
        self.src_h = np.column_stack([self.src_n, np.ones(src.shape[0])])
        self.dst_scale = self.t_dst[0, 0]

    def to_normalised(self, matrix: np.ndarray) -> np.ndarray:
        """Return ``T_dst H T_src^-1`` with unit Frobenius norm."""
        g = self.t_dst @ matrix @ self.t_src_inv
        return g / _norm(g)

    def from_normalised(self, g: np.ndarray) -> np.ndarray:
        """Return the pixel homography ``T_dst^-1 G T_src`` scaled so ``H[2, 2] == 1``."""
        return normalise_scale(self.t_dst_inv @ g @ self.t_src)

    def _evaluate(self, g: np.ndarray, dst_n: np.ndarray, weights: np.ndarray | None
                  ) -> tuple[float, tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
        """Return the transfer energy (pixels^2) of normalised ``g`` and its ``(1 / w, px, py)``.

        The second item is None where a point maps to infinity (energy inf).
        """
        uvw = self.src_h @ g.T
        iw = uvw[:, 2]
        if np.abs(iw).min() < _MIN_W:
            return float('inf'), None
        iw = 1.0 / iw
        pxy = uvw[:, :2] * iw[:, None]
        res = pxy - dst_n
        sq = np.einsum('ij,ij->i', res, res)
        total = float(sq @ weights) if weights is not None else float(sq.sum())
        return 0.5 * total / self.dst_scale ** 2, (iw, pxy[:, 0], pxy[:, 1])

    def refine(self, matrix: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None,
               iterations: int = 3, over_relaxation: float = 0.0
               ) -> tuple[np.ndarray, float, float]:
        """Refine ``matrix`` toward ``dst`` by damped Gauss-Newton steps.

        With ``over_relaxation`` the result is then moved that much further along its
        update (in the normalised, unit-norm parametrisation), kept if its transfer energy
        stays at most the energy before the steps.

        Args:
            matrix: (3, 3) float64 starting homography (pixels).
            dst: (N, 2) float64 destination points (pixels), paired with the source points.
            weights: Optional (N,) non-negative weights.
            iterations: Number of Gauss-Newton steps.
            over_relaxation: Extrapolation factor of the update (0: none).

        Returns:
            ``(H, energy_before, energy_after)`` with ``energy_after <= energy_before``.

        """
        dst_n = _transform(self.t_dst, dst)
        g = g_start = self.to_normalised(matrix)
        e0, state = self._evaluate(g, dst_n, weights)
        e = e0
        src_h = self.src_h
        for _ in range(iterations):
            if state is None:
                break
            iw, px, py = state
            normal, grad = _normal_equations(src_h * iw[:, None], px, py, dst_n, weights)
            gvec = g.ravel()
            # J g = 0 (scale gauge); adding g g^T fixes the scale and makes the system regular.
            normal += np.outer(gvec, gvec)
            normal.flat[_DIAGONAL] *= 1.0 + 1e-9
            try:
                step = -np.linalg.solve(normal, grad)
            except np.linalg.LinAlgError:
                break
            accepted = False
            for _ in range(4):
                cand = gvec + step
                cand = (cand / _norm(cand)).reshape(3, 3)
                if np.all(np.isfinite(cand)):
                    ec, cand_state = self._evaluate(cand, dst_n, weights)
                    if ec <= e:
                        g, e, state, accepted = cand, ec, cand_state, True
                        break
                step *= 0.5
            if not accepted:
                break
        if over_relaxation > 0.0 and g is not g_start:
            if float(np.sum(g_start * g)) < 0:
                g_start = -g_start
            ext = g + over_relaxation * (g - g_start)
            norm = _norm(ext)
            if np.isfinite(norm) and norm > 0:
                ext = ext / norm
                e_ext = self._evaluate(ext, dst_n, weights)[0]
                if e_ext <= e0:
                    g, e = ext, e_ext
        return self.from_normalised(g), e0, e


def refine_homography(matrix: np.ndarray, src: np.ndarray, dst: np.ndarray,
                      weights: np.ndarray | None = None,
                      iterations: int = 10) -> np.ndarray | FailedEstimate:
    """Refine a homography by minimising the Euclidean transfer error (Gauss-Newton).

    Args:
        matrix: (3, 3) float64 initial homography.
        src: (N, 2) float64 source points.
        dst: (N, 2) float64 destination points.
        weights: Optional (N,) non-negative weights.
        iterations: Maximum number of Gauss-Newton steps.

    Returns:
        (3, 3) float64 refined homography (its transfer energy is never above the initial
        one), or :class:`FailedEstimate` for degenerate input.

    Raises:
        ValueError: On wrong shapes.

    """
    matrix = as_homography(matrix)
    src = as_points(src, 'src')
    dst = as_points(dst, 'dst')
    w = None if weights is None else np.asarray(weights, dtype=np.float64)
    reason = check_homography(matrix) or _degenerate_reason(src, dst, w)
    if reason:
        return FailedEstimate(reason)
    refined, _, _ = NormalisedRefiner(src, dst).refine(matrix, dst, w, iterations)
    reason = check_homography(refined)
    if reason:
        return FailedEstimate(reason)
    return refined


def fit_homography(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None,
                   iterations: int = 10) -> np.ndarray | FailedEstimate:
    """Fit a homography: normalised DLT, then Euclidean refinement.

    Args:
        src: (N, 2) float64 source points.
        dst: (N, 2) float64 destination points.
        weights: Optional (N,) non-negative weights.
        iterations: Gauss-Newton steps of the refinement.

    Returns:
        (3, 3) float64 homography or :class:`FailedEstimate`.

    Raises:
        ValueError: On wrong shapes.

    """
    initial = fit_homography_dlt(src, dst, weights)
    if not isinstance(initial, np.ndarray):
        return initial
    return refine_homography(initial, src, dst, weights, iterations)
