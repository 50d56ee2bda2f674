"""References of the real data: the KITTI road plane from the ground-truth disparity, chessboards.

Also where the data live (``../shared/data`` beside the repository, else ``test/data``) and the
transfer error every evaluation reports.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path
import sys
from typing import Iterable, Iterator

import cv2
from domplane_ros.core.homography import apply_homography
import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[3]
SHARED_DATA = REPO_ROOT.parent / 'shared' / 'data'
TEST_DATA = REPO_ROOT / 'test' / 'data'

KITTI_DIR = 'kitti2015_000046'
OPENCV_DIR = 'opencv_samples'
ENSENSO_DIR = 'ensenso_fit_primitive'
ENSENSO_STEM = '13200655716648_N35-1602-16-BL'
CHESSBOARD_PATTERN = (9, 6)
# Road: ground-truth pixels within this distance of the disparity plane; off-road: beyond
# OFF_ROAD_PX (car, poles, buildings).
ROAD_PX = 1.0
OFF_ROAD_PX = 3.0


def default_data_dir() -> Path:
    """Return ``../shared/data`` beside the repository if it exists, else ``test/data``."""
    return SHARED_DATA if SHARED_DATA.is_dir() else TEST_DATA


def read_gray(path: Path) -> np.ndarray:
    """Return an image file as (H, W) uint8 grey; ValueError if it cannot be read."""
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise ValueError(f'cannot read image {path}')
    return image


@dataclass(frozen=True)
class DisparityPlane:
    """A plane in a rectified pair's disparity: ``d = a x + b y + c``.

    Attributes:
        a: Disparity change per pixel along x.
        b: Disparity change per pixel along y.
        c: Disparity at pixel (0, 0), pixels.
        inlier_fraction: Share of the ground-truth pixels within 1 px of the plane.
    """

    a: float
    b: float
    c: float
    inlier_fraction: float

    def homography(self) -> np.ndarray:
        """Return the (3, 3) float64 left-to-right homography ``x' = x - d(x, y)``, ``y' = y``."""
        return np.array([[1.0 - self.a, -self.b, -self.c], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])

    def residuals(self, xs: np.ndarray, ys: np.ndarray, disparity: np.ndarray) -> np.ndarray:
        """Return ``|a x + b y + c - d|`` for (N,) pixel coordinates and disparities."""
        return np.abs(self.a * xs + self.b * ys + self.c - disparity)


def read_kitti_disparity(path: Path) -> np.ndarray:
    """Read a KITTI ground-truth disparity PNG.

    Args:
        path: uint16 PNG, value / 256 = disparity in pixels, 0 = no measurement.

    Returns:
        (H, W) float64 disparity, NaN where there is no measurement.

    Raises:
        ValueError: If the file cannot be read or is not a single-channel uint16 image.

    """
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.ndim != 2 or raw.dtype != np.uint16:
        raise ValueError(f'{path}: expected a single-channel uint16 PNG')
    disparity = raw.astype(np.float64) / 256.0
    disparity[raw == 0] = np.nan
    return disparity


def fit_disparity_plane(disparity: np.ndarray, threshold_px: float = 1.0,
                        iterations: int = 1000, seed: int = 0) -> DisparityPlane:
    """Fit ``d = a x + b y + c`` robustly to a sparse disparity map.

    RANSAC over 3-pixel samples (``numpy.random.default_rng(seed)``, ``iterations`` samples,
    the first sample with the most pixels within ``threshold_px`` wins), then least squares on
    that sample's inliers. With the defaults this is the fit quoted in
    ``../shared/data/README.md`` for KITTI 2015 frame 000046.

    Args:
        disparity: (H, W) float64 disparity in pixels, NaN where unknown.
        threshold_px: Inlier distance in disparity pixels.
        iterations: Number of RANSAC samples.
        seed: Seed of the sampler.

    Returns:
        The fitted :class:`DisparityPlane`.

    Raises:
        ValueError: If there are fewer than 3 known pixels or no sample gives a plane.

    """
    ys, xs = np.nonzero(np.isfinite(disparity))
    if xs.size < 3:
        raise ValueError(f'need at least 3 disparity pixels, got {xs.size}')
    values = disparity[ys, xs]
    design = np.stack([xs, ys, np.ones_like(xs)], axis=1).astype(np.float64)
    rng = np.random.default_rng(seed)
    best_count, best = -1, None
    for _ in range(iterations):
        sample = rng.choice(xs.size, 3, replace=False)
        try:
            params = np.linalg.solve(design[sample], values[sample])
        except np.linalg.LinAlgError:
            continue
        count = int(np.count_nonzero(np.abs(design @ params - values) < threshold_px))
        if count > best_count:
            best_count, best = count, params
    if best is None:
        raise ValueError('every RANSAC sample was degenerate')
    inliers = np.abs(design @ best - values) < threshold_px
    params = np.linalg.lstsq(design[inliers], values[inliers], rcond=None)[0]
    plane = DisparityPlane(float(params[0]), float(params[1]), float(params[2]), 0.0)
    fraction = float(np.mean(plane.residuals(xs, ys, values) < 1.0))
    return replace(plane, inlier_fraction=fraction)


def chessboard_corners(left: np.ndarray, right: np.ndarray,
                       pattern: tuple[int, int] = CHESSBOARD_PATTERN
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """Find the chessboard's inner corners in both images, in the same order.

    Args:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        pattern: Inner corners per row and column, as for ``cv2.findChessboardCorners``.

    Returns:
        Two (N, 2) float64 arrays (left, right corners), or None if either image has no
        board.

    """
    found = []
    for image in (left, right):
        ok, corners = cv2.findChessboardCorners(image, pattern)
        if not ok:
            return None
        found.append(corners.reshape(-1, 2).astype(np.float64))
    return found[0], found[1]


def mean_transfer_px(homography: np.ndarray | None, src: np.ndarray, dst: np.ndarray) -> float:
    """Return the mean ``||H(src_i) - dst_i||`` in pixels, or inf without a homography."""
    if homography is None or src.shape[0] == 0:
        return math.inf
    return float(np.mean(np.linalg.norm(apply_homography(homography, src) - dst, axis=1)))


@dataclass(frozen=True)
class KittiReference:
    """The KITTI reference: disparity plane, road and off-road pixels.

    Attributes:
        plane: The robust disparity plane.
        road: (H, W) bool, ground-truth pixels within :data:`ROAD_PX` of the plane.
        off_road: (H, W) bool, ground-truth pixels farther than :data:`OFF_ROAD_PX`.
        disparity: (H, W) float64 ground-truth disparity, NaN where unknown.
    """

    plane: DisparityPlane
    road: np.ndarray
    off_road: np.ndarray
    disparity: np.ndarray


def kitti_reference(folder: Path) -> KittiReference:
    """Fit the road plane to the ground-truth disparity and split road from off-road pixels."""
    disparity = read_kitti_disparity(folder / 'disp_occ_left.png')
    plane = fit_disparity_plane(disparity)
    ys, xs = np.mgrid[0:disparity.shape[0], 0:disparity.shape[1]]
    known = np.isfinite(disparity)
    residual = np.full(disparity.shape, np.inf)
    residual[known] = plane.residuals(xs[known], ys[known], disparity[known])
    return KittiReference(plane=plane, road=known & (residual < ROAD_PX),
                          off_road=known & (residual > OFF_ROAD_PX), disparity=disparity)


def chessboard_pairs(folder: Path) -> list[str]:
    """Return the numbers ``NN`` of the ``leftNN.jpg`` / ``rightNN.jpg`` pairs in a folder."""
    return sorted(p.stem[4:] for p in folder.glob('left[0-9][0-9].jpg')
                  if (folder / f'right{p.stem[4:]}.jpg').exists())


def chessboards(folder: Path, numbers: Iterable[str] | None = None,
                report_skipped: bool = False
                ) -> Iterator[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Yield ``(number, left, right, src, dst)`` for each pair whose board both images show.

    Args:
        folder: Folder of ``leftNN.jpg`` / ``rightNN.jpg`` pairs.
        numbers: The pair numbers to read (default: :func:`chessboard_pairs`), e.g. wrapped
            in a progress bar.
        report_skipped: Say on stderr which pairs are skipped (board not found in both).

    Yields:
        The pair's number, its grey images and the board's (N, 2) corners in each
        (:func:`chessboard_corners`).

    """
    for number in chessboard_pairs(folder) if numbers is None else numbers:
        left = read_gray(folder / f'left{number}.jpg')
        right = read_gray(folder / f'right{number}.jpg')
        corners = chessboard_corners(left, right)
        if corners is None:
            if report_skipped:
                print(f'chessboard pair {number}: board not found in both images, skipped',
                      file=sys.stderr)
            continue
        yield number, left, right, corners[0], corners[1]
