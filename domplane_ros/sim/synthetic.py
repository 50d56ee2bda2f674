"""Seeded synthetic point scenes with ground truth, for tests and the core benchmark.

A point scene is what the estimator sees after corner detection: left and right point sets
without correspondences. Plane points map by the true homography (plus detection noise);
off-plane points (obstacles standing on the plane) are closer to the cameras, so their right
image positions have a larger disparity than the plane predicts; some detections are missing
in one image or the other.
"""

from __future__ import annotations

from dataclasses import dataclass

from domplane_ros.core.homography import apply_homography, fit_homography_dlt
from domplane_ros.core.prior import plane_homography
import numpy as np


@dataclass(frozen=True)
class _SceneTruth:
    """Left and right features with the truth.

    Attributes:
        left: (N, K) float64 left features.
        right: (M, K) float64 right features, shuffled (no correspondence by index).
        homography: (3, 3) float64 true plane homography, left to right.
        on_plane: (N,) bool, left features that lie on the plane.
        width: Image width in pixels.
        height: Image height in pixels.

    """

    left: np.ndarray
    right: np.ndarray
    homography: np.ndarray
    on_plane: np.ndarray
    width: int
    height: int


@dataclass(frozen=True)
class PointScene(_SceneTruth):
    """Left and right points with the truth.

    ``left`` is (N, 2) float64, ``right`` (M, 2) float64 and shuffled, ``on_plane`` marks the
    left points on the plane; the other attributes are those of every scene with truth.
    """


# Kinds of point sets for the warm-start basin, as keyword arguments of :func:`point_scene`
# (``n_points`` 500 unless given): spread over the image (30 % off-plane, 10 % missing), in 5
# clusters, half off the plane, 30 % missing detections, and 150 points only.
POINT_SET_KINDS: dict[str, dict[str, int | float]] = {
    'spread': {}, 'clustered': {'clusters': 5}, 'half_off_plane': {'outlier_fraction': 0.5},
    'missing_30': {'missing_fraction': 0.3}, 'sparse_150': {'n_points': 150}}


def random_plane_homography(rng: np.random.Generator, width: int = 640,
                            height: int = 480) -> np.ndarray:
    """Draw a plausible stereo-head ground-plane homography (focal 500-800 px, tilt 15-45)."""
    return plane_homography(focal_px=rng.uniform(500, 800),
                            baseline_over_height=rng.uniform(0.08, 0.3),
                            tilt_deg=rng.uniform(15, 45), vergence_deg=rng.uniform(-1, 3),
                            width=width, height=height)


def point_scene(rng: np.random.Generator, n_points: int = 500, outlier_fraction: float = 0.3,
                missing_fraction: float = 0.1, noise_px: float = 0.3,
                homography: np.ndarray | None = None, width: int = 640,
                height: int = 480, clusters: int = 0) -> PointScene:
    """Draw a point scene.

    Args:
        rng: Random generator (seeded by the caller).
        n_points: Number of detections per image before removing missing ones.
        outlier_fraction: Fraction of points off the plane (obstacles).
        missing_fraction: Fraction of points detected in one image only (half of them
            missing on each side).
        noise_px: Standard deviation of the detection noise, pixels.
        homography: True homography; drawn with :func:`random_plane_homography` if None.
        width: Image width.
        height: Image height.
        clusters: 0 spreads the left points uniformly over the image; else they are drawn
            around this many centres (Gaussian, 40 px standard deviation), as corners gather
            on a few textured objects.

    Returns:
        The :class:`PointScene`.

    """
    h = random_plane_homography(rng, width, height) if homography is None else homography
    centres = rng.uniform([0, 0], [width - 1, height - 1], size=(clusters, 2))
    # Left points whose plane image lands inside the right image.
    pts = np.empty((0, 2))
    while pts.shape[0] < n_points:
        cand = _draw_left(rng, 2 * n_points, width, height, centres)
        mapped = apply_homography(h, cand)
        inside = ((mapped[:, 0] >= 0) & (mapped[:, 0] <= width - 1)
                  & (mapped[:, 1] >= 0) & (mapped[:, 1] <= height - 1))
        pts = np.concatenate([pts, cand[inside]])
    left = pts[:n_points]
    right = apply_homography(h, left)
    on_plane = rng.random(n_points) >= outlier_fraction
    n_off = int(np.count_nonzero(~on_plane))
    # Obstacles are nearer than the plane: extra disparity (right image moves left).
    right[~on_plane, 0] -= rng.uniform(4.0, 40.0, n_off)
    right[~on_plane, 1] += rng.normal(0.0, 1.0, n_off)
    right += rng.normal(0.0, noise_px, right.shape)
    missing = rng.random(n_points) < missing_fraction
    only_left = missing & (rng.random(n_points) < 0.5)
    only_right = missing & ~only_left
    keep_left = ~only_right
    keep_right = ~only_left
    right = right[keep_right]
    right = right[rng.permutation(right.shape[0])]
    return PointScene(left=left[keep_left], right=right, homography=h,
                      on_plane=on_plane[keep_left], width=width, height=height)


def _draw_left(rng: np.random.Generator, count: int, width: int, height: int,
               centres: np.ndarray) -> np.ndarray:
    """Return (count, 2) left points inside the image: uniform, or around ``centres``."""
    if centres.shape[0] == 0:
        return rng.uniform([0, 0], [width - 1, height - 1], size=(count, 2))
    around = centres[rng.integers(0, centres.shape[0], count)]
    pts = around + rng.normal(0.0, 40.0, (count, 2))
    inside = ((pts[:, 0] >= 0) & (pts[:, 0] <= width - 1)
              & (pts[:, 1] >= 0) & (pts[:, 1] <= height - 1))
    return pts[inside]


def displace_homography(homography: np.ndarray, displacement_px: float,
                        rng: np.random.Generator, width: int = 640,
                        height: int = 480) -> np.ndarray:
    """Perturb a homography by moving the images of the four image corners.

    Each corner's image moves by exactly ``displacement_px`` in a random direction.

    Args:
        homography: (3, 3) float64 homography.
        displacement_px: Length of each corner's displacement, pixels.
        rng: Random generator.
        width: Image width.
        height: Image height.

    Returns:
        (3, 3) float64 perturbed homography.

    """
    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]],
                       dtype=np.float64)
    mapped = apply_homography(homography, corners)
    angles = rng.uniform(0, 2 * np.pi, 4)
    moved = mapped + displacement_px * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    result = fit_homography_dlt(corners, moved)
    assert isinstance(result, np.ndarray), result
    return result


def plane_error_px(estimate: np.ndarray, truth: np.ndarray, points: np.ndarray) -> float:
    """Return the mean transfer error between two homographies over (N, 2) points, pixels."""
    diff = apply_homography(estimate, points) - apply_homography(truth, points)
    return float(np.mean(np.linalg.norm(diff, axis=1)))


@dataclass(frozen=True)
class LineScene(_SceneTruth):
    """Left and right line segments with the truth.

    ``left`` is (N, 4) float64 segments ``(x1, y1, x2, y2)``; ``right`` is (M, 4) float64,
    shuffled, with endpoints that do not correspond to the left ones (each right segment is a
    random part of the mapped line); ``on_plane`` marks the left segments on the plane.
    """


def line_scene(rng: np.random.Generator, n_lines: int = 120, outlier_fraction: float = 0.3,
               missing_fraction: float = 0.1, noise_px: float = 0.3,
               homography: np.ndarray | None = None, width: int = 640, height: int = 480,
               directions_deg: np.ndarray | None = None,
               through_point: tuple[float, float] | None = None) -> LineScene:
    """Draw a line-segment scene.

    Args:
        rng: Random generator (seeded by the caller).
        n_lines: Number of left segments before removing missing ones.
        outlier_fraction: Fraction of segments off the plane (shifted by an extra disparity).
        missing_fraction: Fraction of segments detected in one image only.
        noise_px: Standard deviation of the endpoint noise, pixels.
        homography: True homography; drawn with :func:`random_plane_homography` if None.
        width: Image width.
        height: Image height.
        directions_deg: Optional directions to draw the left segments' angles from (e.g. one
            value for all-parallel segments).
        through_point: Optional point all left lines pass through (a concurrent pencil).

    Returns:
        The :class:`LineScene`.

    """
    h = random_plane_homography(rng, width, height) if homography is None else homography
    left = _left_segments(rng, h, n_lines, width, height, directions_deg, through_point)
    right = apply_homography(h, left.reshape(-1, 2)).reshape(-1, 4)
    on_plane = rng.random(n_lines) >= outlier_fraction
    n_off = int(np.count_nonzero(~on_plane))
    shift = rng.uniform(4.0, 40.0, n_off)
    right[~on_plane, 0] -= shift
    right[~on_plane, 2] -= shift
    # Fragment: each right segment is a random part (70-100 %) of the mapped segment, or a bit
    # longer, so endpoints do not correspond.
    t0 = rng.uniform(-0.15, 0.15, n_lines)
    t1 = rng.uniform(0.85, 1.15, n_lines)
    p, q = right[:, 0:2].copy(), right[:, 2:4].copy()
    right[:, 0:2] = p + (q - p) * t0[:, None]
    right[:, 2:4] = p + (q - p) * t1[:, None]
    right += rng.normal(0.0, noise_px, right.shape)
    missing = rng.random(n_lines) < missing_fraction
    only_left = missing & (rng.random(n_lines) < 0.5)
    only_right = missing & ~only_left
    right = right[~only_left]
    right = right[rng.permutation(right.shape[0])]
    return LineScene(left=left[~only_right], right=right, homography=h,
                     on_plane=on_plane[~only_right], width=width, height=height)


def _left_segments(rng: np.random.Generator, h: np.ndarray, n_lines: int, width: int,
                   height: int, directions_deg: np.ndarray | None,
                   through_point: tuple[float, float] | None) -> np.ndarray:
    """Return (n_lines, 4) float64 left segments inside both images (mapped by ``h``)."""
    segs = []
    while len(segs) < n_lines:
        length = rng.uniform(40.0, 220.0)
        if directions_deg is not None:
            angle = np.radians(rng.choice(np.asarray(directions_deg, np.float64)))
        else:
            angle = rng.uniform(0.0, np.pi)
        d = np.array([np.cos(angle), np.sin(angle)])
        if through_point is not None:
            start = np.asarray(through_point) + rng.uniform(-300.0, 300.0) * d
        else:
            start = rng.uniform([0, 0], [width - 1, height - 1])
        end = start + length * d
        seg = np.array([start, end])
        mapped = apply_homography(h, seg)
        if (np.all((seg >= 0) & (seg <= [width - 1, height - 1]))
                and np.all((mapped >= 0) & (mapped <= [width - 1, height - 1]))):
            segs.append(seg.ravel())
    return np.array(segs)
