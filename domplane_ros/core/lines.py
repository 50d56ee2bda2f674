"""Straight-line features: detection, a pixel line distance and the closest-line search.

A plane homography maps lines to lines (a line ``l`` of the left image maps to ``H^-T l``),
so the two-step iteration of :mod:`domplane_ros.core.estimator` runs on line segments as it does
on points. Segments are ``(N, 4) float64`` arrays of endpoints ``(x1, y1, x2, y2)`` in pixels.

**Distance.** Endpoints of a detected segment do not correspond between the views (lines
fragment, end at occlusions and at the image border), only the line through a segment is a
measurement. The distance of a left segment ``(p1, p2)``, predicted by ``H`` to
``(x1, x2) = (H(p1), H(p2))``, to a right segment ``k`` is therefore taken to the *infinite*
line ``n_k . x + c_k = 0`` (unit normal ``n_k``)::

    D_k(x1, x2) = sqrt(d_k(x1)^2 + d_k(x2)^2),    d_k(x) = n_k . x + c_k,

in pixels: the Euclidean distance in R^4 from the predicted endpoint pair to the set
``S_k = {(a1, a2): a1 and a2 on line k}``. ``S_k`` is an affine subspace, so the closest
element of ``S_k`` is the pair of orthogonal projections of the endpoints, and the triangle
inequality gives, exactly as for points, that the closest line of every point on the segment
from ``(x1, x2)`` to those projections is still line ``k``. That is what makes Cohen's
auxiliary-variable step (auxiliary endpoints moved along the normal of the closest line by the
potential's rule) lower the joint energy. A segment-aware distance (with a gap term for
non-overlapping segments) would lose this property; segments that are collinear but apart in
the image lie on one image line, which the homography maps consistently anyway.

**Polarity.** Segments are oriented: LSD orders a segment's endpoints so that the darker
side is always on the same side of the direction ``p1 -> p2``, and a homography of a plane seen
from the front by both cameras keeps that orientation. A predicted segment therefore only
matches right segments of the same polarity (``n_pred . n_k > 0``); this keeps the two edges of
a dark joint (a few pixels apart, opposite polarities) from being confused. A prediction with
no same-polarity line among its candidates is unmatched: its distance is
:data:`UNMATCHED_PX` and its closest position is the prediction itself (no pull).

**Search.** Each right line is keyed by a point in R^4: the foot of the perpendicular from a
reference point (the centre of the right segments), relative to it, and the direction
``(cos phi, sin phi)`` of the oriented segment scaled by a length in pixels (half the median
segment length). The foot point does not depend on the sign ambiguity of ``(n, c)``, and the
oriented direction puts lines of opposite polarity far apart. Near lines have near keys, so a
cKDTree returns ``k`` candidates, and the exact pixel distance ``D`` picks the closest of
them. The search is approximate for far lines (the key is not a bound on ``D``); the estimator
records the energy with the line actually chosen, and its step check keeps that energy
monotone whatever the search returns.
"""

from __future__ import annotations

from typing import Any, Sequence

import cv2
from domplane_ros.config import FeatureConfig
from domplane_ros.core.features import gray_roi, grid_round_robin
from domplane_ros.core.homography import apply_homography, as_rows, similarity_normaliser
import numpy as np
from scipy.spatial import cKDTree

# Distance reported for a prediction with no same-polarity partner among its candidates.
UNMATCHED_PX = 1e4
# Candidates per query, and the longest left segments used, when screening prior homographies
# (cheaper: it only ranks the candidates).
_SCREEN_CANDIDATES = 3
SCREEN_SEGMENTS = 60


def as_segments(segments: Any, name: str = 'segments') -> np.ndarray:
    """Return ``segments`` as a ``(N, 4) float64`` array of endpoints ``(x1, y1, x2, y2)``.

    Raises:
        ValueError: If the shape is not (N, 4) or the values are not numbers.

    """
    return as_rows(segments, 4, name, 'segments (x1, y1, x2, y2)', ' (x1, y1, x2, y2)',
                   empty_ok=True)


def segment_lengths(segments: np.ndarray) -> np.ndarray:
    """Return the (N,) lengths in pixels of (N, 4) segments."""
    return np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])


def segment_lines(segments: np.ndarray) -> np.ndarray:
    """Return the lines through (N, 4) segments as (N, 3) ``(a, b, c)``, ``a^2 + b^2 = 1``.

    A point ``x`` is on line ``i`` when ``a x + b y + c = 0``; ``a x + b y + c`` is its signed
    distance in pixels. Zero-length segments give a zero row.
    """
    d = segments[:, 2:4] - segments[:, 0:2]
    length = np.hypot(d[:, 0], d[:, 1])
    safe = np.where(length > 0, length, 1.0)
    a = -d[:, 1] / safe
    b = d[:, 0] / safe
    c = -(a * segments[:, 0] + b * segments[:, 1])
    out = np.stack([a, b, c], axis=1)
    out[length <= 0] = 0.0
    return out


def endpoints(segments: np.ndarray) -> np.ndarray:
    """Return the (2N, 2) endpoints of (N, 4) segments, ``p1`` of segment i at row ``2 i``."""
    return segments.reshape(-1, 2)


def lines_reason(segments: np.ndarray, side: str) -> str:
    """Return why a segment set cannot fix a homography ('' if it can).

    A homography has 8 degrees of freedom and a line gives 2 constraints, so at least 4
    lines are needed, and lines that all pass through one point (parallel lines meet at a
    point at infinity) leave the pencil's centre free: the (N, 3) matrix of the lines, in
    Hartley-normalised coordinates, must have rank 3.

    Args:
        segments: (N, 4) float64 segments.
        side: ``'left'`` or ``'right'``, for the message.

    Returns:
        The reason in words, or ``''``.

    """
    if not np.all(np.isfinite(segments)):
        return f'{side} segments have non-finite coordinates'
    segments = segments[segment_lengths(segments) > 0]
    if segments.shape[0] < 4:
        return f'need at least 4 {side} line segments, got {segments.shape[0]}'
    t = similarity_normaliser(endpoints(segments))
    normalised = (endpoints(segments) * t[0, 0] + t[:2, 2]).reshape(-1, 4)
    lines = segment_lines(normalised)
    sv = np.linalg.svd(lines, compute_uv=False)
    if sv[2] <= 1e-6 * max(sv[0], 1e-300):
        return f'{side} lines are all concurrent or parallel (one pencil of lines)'
    return ''


def detect_lines(gray: np.ndarray, config: FeatureConfig,
                 roi: Sequence[float] | None = None) -> np.ndarray:
    """Detect straight line segments spread over a grid of cells.

    OpenCV's line segment detector (LSD, ``cv2.createLineSegmentDetector``, in the headless
    wheel since OpenCV 4.5.1) runs on the region of interest at ``config.line_scale`` (its
    Gaussian down-scaling; coordinates are returned at full resolution); segments shorter than
    ``config.min_line_length_px`` are dropped, and the rest are taken round-robin over the
    ``grid_rows x grid_cols`` cells (by midpoint), longest first, up to ``config.max_lines``.

    Args:
        gray: (H, W) uint8 image.
        config: ``min_line_length_px``, ``max_lines``, ``line_scale``, the grid and the
            default ``roi``.
        roi: Optional ``(x0, y0, x1, y1)`` region of interest as fractions; overrides
            ``config.roi``. Segments are clipped to it.

    Returns:
        (N, 4) float64 segments ``(x1, y1, x2, y2)`` in full-image pixels, ``N <= max_lines``,
        longest of every cell first. A flat image gives (0, 4).

    Raises:
        ValueError: If ``gray`` is not a 2-D uint8 array or ``roi`` is invalid.

    """
    x0, y0, x1, y1 = gray_roi(gray, config.roi if roi is None else roi)
    empty = np.zeros((0, 4), np.float64)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return empty
    detector = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD, config.line_scale)
    found = detector.detect(np.ascontiguousarray(gray[y0:y1, x0:x1]))[0]
    if found is None:
        return empty
    seg = found.reshape(-1, 4).astype(np.float64) + np.array([x0, y0, x0, y0], np.float64)
    length = segment_lengths(seg)
    keep = length >= config.min_line_length_px
    seg, length = seg[keep], length[keep]
    if seg.shape[0] == 0:
        return empty
    mid_x = 0.5 * (seg[:, 0] + seg[:, 2]) - x0
    mid_y = 0.5 * (seg[:, 1] + seg[:, 3]) - y0
    rows = config.grid_rows
    cols = config.grid_cols
    cell = (np.clip((mid_y * rows // (y1 - y0)).astype(np.int64), 0, rows - 1) * cols
            + np.clip((mid_x * cols // (x1 - x0)).astype(np.int64), 0, cols - 1))
    return seg[grid_round_robin(length, cell, config.max_lines)]


class LineMatcher:
    """The closest-line search over a fixed set of right segments.

    Args:
        right_segments: (M, 4) float64 right segments, M >= 1, non-zero lengths.

    """

    def __init__(self, right_segments: np.ndarray) -> None:
        """Key every right line and build the tree."""
        self.segments = right_segments
        self.lines = segment_lines(right_segments)
        mids = 0.5 * (right_segments[:, 0:2] + right_segments[:, 2:4])
        self.reference = mids.mean(axis=0)
        self.angle_scale = max(1.0, 0.5 * float(np.median(segment_lengths(right_segments))))
        self.tree = cKDTree(self._keys(self.lines))

    def _keys(self, lines: np.ndarray) -> np.ndarray:
        """Return (N, 4) keys: foot point from the reference, scaled oriented direction."""
        n = lines[:, 0:2]
        dist = n @ self.reference + lines[:, 2]
        foot = -dist[:, None] * n
        # The oriented direction is (b, -a) for the unit normal (a, b).
        return np.column_stack([foot, self.angle_scale * n[:, 1], -self.angle_scale * n[:, 0]])

    def closest(self, x1: np.ndarray, x2: np.ndarray, candidates: int | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Find each predicted segment's closest right line.

        Exact by default: every right line is tried (at most ``features.max_lines`` each
        side, 150 x 150 by default: about the cost of the tree search, which missed a line
        2.9 px away for one 10.4 px away when the foot points' lever arm from the reference
        put it 9th in key distance). With ``candidates`` the tree gives that many per query,
        refined by the exact distance: an approximation, for the screening of many
        homographies.

        Args:
            x1: (N, 2) float64 first predicted endpoints.
            x2: (N, 2) float64 second predicted endpoints.
            candidates: Tree candidates per query (None: every line, exact).

        Returns:
            ``(D, idx, c1, c2)``: (N,) distances ``sqrt(d(x1)^2 + d(x2)^2)`` in pixels, (N,)
            int64 indices of the closest right lines of the same polarity, and (N, 2)
            projections of ``x1`` and ``x2`` onto those lines. Without a same-polarity
            candidate: ``D = UNMATCHED_PX`` and the projections are the predictions.

        """
        n = x1.shape[0]
        if n == 0:
            z = np.zeros((0, 2))
            return np.zeros(0), np.zeros(0, np.int64), z, z
        pred = np.concatenate([x1, x2], axis=1)
        query_lines = segment_lines(pred)
        rows = np.arange(n)
        if candidates is None:
            idx = None
            lines = self.lines
            d1 = x1 @ lines[:, 0:2].T + lines[:, 2]  # (N, M)
            d2 = x2 @ lines[:, 0:2].T + lines[:, 2]
            same = query_lines[:, 0:2] @ lines[:, 0:2].T > 0
        else:
            # Zero-length predictions (degenerate H) get a key from the point alone.
            k = int(min(candidates, self.lines.shape[0]))
            _, idx = self.tree.query(self._keys(query_lines), k=k)
            idx = idx.reshape(n, k)
            cand = self.lines[idx]  # (N, k, 3)
            d1 = cand[:, :, 0] * x1[:, 0:1] + cand[:, :, 1] * x1[:, 1:2] + cand[:, :, 2]
            d2 = cand[:, :, 0] * x2[:, 0:1] + cand[:, :, 1] * x2[:, 1:2] + cand[:, :, 2]
            same = (cand[:, :, 0] * query_lines[:, 0:1]
                    + cand[:, :, 1] * query_lines[:, 1:2]) > 0
        dist2 = np.where(same, d1 * d1 + d2 * d2, np.inf)
        best = np.argmin(dist2, axis=1)
        chosen = (best if idx is None else idx[rows, best]).astype(np.int64)
        line = self.lines[chosen]
        found = same[rows, best]
        e1 = np.where(found, d1[rows, best], 0.0)
        e2 = np.where(found, d2[rows, best], 0.0)
        c1 = x1 - e1[:, None] * line[:, 0:2]
        c2 = x2 - e2[:, None] * line[:, 0:2]
        dist = np.where(found, np.sqrt(np.where(found, dist2[rows, best], 0.0)), UNMATCHED_PX)
        return dist, chosen, c1, c2

    def brute_force(self, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the exact ``(D, idx)`` by trying every right line (for checks and tests)."""
        d1 = x1 @ self.lines[:, 0:2].T + self.lines[:, 2]
        d2 = x2 @ self.lines[:, 0:2].T + self.lines[:, 2]
        query = segment_lines(np.concatenate([x1, x2], axis=1))
        same = query[:, 0:2] @ self.lines[:, 0:2].T > 0
        dist2 = np.where(same, d1 * d1 + d2 * d2, np.inf)
        idx = np.argmin(dist2, axis=1)
        best = dist2[np.arange(x1.shape[0]), idx]
        return np.where(np.isfinite(best), np.sqrt(best), UNMATCHED_PX), idx.astype(np.int64)


def screen_line_candidates(candidates: np.ndarray, left_segments: np.ndarray,
                           matcher: LineMatcher, threshold_px: float) -> np.ndarray:
    """Score candidate homographies by a truncated closest-line energy (lower is better).

    The energy of a candidate is ``sum_i min(D_i, t)^2`` with ``D_i`` the distance of the
    predicted left segment ``i`` to its closest right line, the line analogue of
    :func:`domplane_ros.core.screening.screen_candidates`. Only the :data:`SCREEN_SEGMENTS` longest
    segments take part (the ranking needs no more, and the search is the cost).

    Args:
        candidates: (M, 3, 3) float64 homographies.
        left_segments: (N, 4) float64 left segments.
        matcher: The right lines' search structure.
        threshold_px: Truncation ``t`` in pixels.

    Returns:
        (M,) float64 screening energies.

    """
    if left_segments.shape[0] > SCREEN_SEGMENTS:
        longest = np.argsort(-segment_lengths(left_segments))[:SCREEN_SEGMENTS]
        left_segments = left_segments[longest]
    m = candidates.shape[0]
    n = left_segments.shape[0]
    ends = endpoints(left_segments)
    pred = np.concatenate([apply_homography(h, ends) for h in candidates])
    dist, _, _, _ = matcher.closest(pred[0::2], pred[1::2], _SCREEN_CANDIDATES)
    dist = np.minimum(dist, threshold_px).reshape(m, n)
    return np.sum(dist * dist, axis=1)


def map_segments(homography: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Map (N, 4) segments' endpoints through a homography, giving (N, 4) segments."""
    return apply_homography(homography, endpoints(segments)).reshape(-1, 4)
