"""Initial homographies from rough ranges of the camera set-up (Fornland & Schnörr, sec. 2.4).

The camera model (shared with the scene renderer in :mod:`domplane_ros.sim.model`):

* Left camera frame: x right, y down, z forward (optical axis). Principal point at the image
  centre unless ``prior.principal_point_px`` gives it, square pixels, focal length ``f`` in
  pixels: ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]``.
* The plane lies at height ``h`` below the left camera. The camera is tilted toward it by
  ``tilt`` (positive looks down), so the plane's unit normal in left-camera coordinates is
  ``n = (0, cos(tilt), sin(tilt))`` and the plane is ``n . X = h``.
* The right camera's centre is ``C = (b, 0, 0)`` in left-camera coordinates, and it is yawed
  toward the left camera by the vergence ``v`` (positive converges):
  ``X_right = R_v (X_left - C)`` with ``R_v = [[cos v, 0, sin v], [0, 1, 0], [-sin v, 0, cos v]]``.

A plane point then maps from the left to the right image by
``H = K R_v (I - C n^T / h) K^-1``, which depends on ``b`` and ``h`` only through ``b / h``.

The search (:class:`PriorSearch`) screens every candidate by a cheap truncated
closest-feature energy (:mod:`domplane_ros.core.screening`) and runs the full two-step
iteration from the best few; the one-shot
estimator refines them all at once, the pipeline a few per frame.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, Collection, Iterable, Sequence, TYPE_CHECKING

from domplane_ros.core.result import better_estimate, FailedEstimate, PlaneEstimate
import numpy as np

if TYPE_CHECKING:
    from domplane_ros.config import EstimatorConfig, PriorConfig
    from domplane_ros.core.estimator import TwoStep


def plane_homography(focal_px: float, baseline_over_height: float, tilt_deg: float,
                     vergence_deg: float, width: int, height: int,
                     principal_px: Sequence[float] = ()) -> np.ndarray:
    """Return the left-to-right homography of the ground plane for one camera set-up.

    Args:
        focal_px: Focal length in pixels (both cameras).
        baseline_over_height: Stereo baseline divided by the camera height above the plane.
        tilt_deg: Tilt of the cameras toward the plane, degrees (positive looks down).
        vergence_deg: Yaw of the right camera toward the left one, degrees.
        width: Image width in pixels.
        height: Image height in pixels.
        principal_px: Principal point ``(cx, cy)`` in pixels; empty: the image centre.

    Returns:
        (3, 3) float64 homography with ``H[2, 2] == 1``, mapping left pixels (x, y, 1) to
        right pixels.

    Raises:
        ValueError: If a value is non-finite, the focal length or image size is not
            positive, or the plane normal is degenerate.

    """
    values = (focal_px, baseline_over_height, tilt_deg, vergence_deg)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f'camera set-up values must be finite, got {values!r}')
    if focal_px <= 0 or width <= 0 or height <= 0:
        raise ValueError(
            f'focal_px, width and height must be positive, got {focal_px}, {width}, {height}')
    k = intrinsics(focal_px, width, height, principal_px)
    tilt = math.radians(tilt_deg)
    verg = math.radians(vergence_deg)
    normal = np.array([0.0, math.cos(tilt), math.sin(tilt)])
    centre = np.array([baseline_over_height, 0.0, 0.0])
    r_v = np.array([[math.cos(verg), 0.0, math.sin(verg)],
                    [0.0, 1.0, 0.0],
                    [-math.sin(verg), 0.0, math.cos(verg)]])
    h = k @ r_v @ (np.eye(3) - np.outer(centre, normal)) @ np.linalg.inv(k)
    if abs(h[2, 2]) < 1e-12:
        raise ValueError('degenerate camera set-up: H[2, 2] is zero')
    return h / h[2, 2]


def intrinsics(focal_px: float, width: int, height: int,
               principal_px: Sequence[float] = ()) -> np.ndarray:
    """Return the (3, 3) calibration matrix; the principal point is the image centre unless given.

    Raises:
        ValueError: If ``principal_px`` is neither empty nor two finite numbers.

    """
    if len(principal_px) == 0:
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    elif len(principal_px) == 2 and all(math.isfinite(v) for v in principal_px):
        cx, cy = (float(v) for v in principal_px)
    else:
        raise ValueError(f'principal point must be empty or (cx, cy), got {principal_px!r}')
    return np.array([[focal_px, 0.0, cx],
                     [0.0, focal_px, cy],
                     [0.0, 0.0, 1.0]])


def _samples(bounds: tuple[float, float], count: int) -> np.ndarray:
    low, high = bounds
    if high <= low or count == 1:
        return np.array([0.5 * (low + high)])
    return np.linspace(low, high, count)


def prior_candidates(prior: PriorConfig, width: int, height: int) -> np.ndarray:
    """Return candidate homographies on a grid over the camera set-up ranges.

    Each range gets ``prior.samples`` evenly spaced values (one, its middle, if it is a
    single value), and every combination gives one candidate
    ``H = K R_v (I - C n^T / h) K^-1``.

    Args:
        prior: The camera set-up ranges.
        width: Left image width in pixels.
        height: Left image height in pixels.

    Returns:
        (M, 3, 3) float64 candidate homographies, ``H[2, 2] == 1``.

    Raises:
        ValueError: If the image size is not positive.

    """
    if width <= 0 or height <= 0:
        raise ValueError(f'image size must be positive, got {width}x{height}')
    # The grid depends only on the (frozen, hashable) prior and the size: computed once per
    # process, so a fresh pipeline's cold start does not pay for it again.
    return _candidate_grid(prior, int(width), int(height)).copy()


def swapped_candidates(candidates: np.ndarray) -> np.ndarray:
    """Return the candidates' planes seen by the same heads with left and right exchanged.

    A head whose image topics are swapped maps the floor from its given left image to its
    given right one by ``H^-1``: the inverse of a candidate of the prior's camera model. These
    hypotheses let a search test the swap explicitly rather than hope a look-alike of the
    correctly ordered model scores lower than the plane it did not look for.

    Args:
        candidates: (M, 3, 3) float64 homographies (:func:`prior_candidates`).

    Returns:
        (M, 3, 3) float64 inverses, ``H[2, 2] == 1``.

    """
    inverse = np.linalg.inv(candidates)
    return inverse / inverse[:, 2:3, 2:3]


def leaning_candidates(candidates: np.ndarray, height: int) -> np.ndarray:
    """Return the candidates' planes mirrored top to bottom: planes leaning toward the head.

    The prior's camera model describes a plane below the head (its disparity grows toward the
    image bottom). Mirroring the image rows (``y -> height - 1 - y``, on both images) keeps
    the baseline's side and turns each such plane into one above or in front of the head
    whose disparity grows toward the image *top*: a ceiling, or a board or wall leaning its
    top toward the cameras, which ``verification.plane: any`` looks for as well. The
    principal point is mirrored with the rows.

    Args:
        candidates: (M, 3, 3) float64 homographies (:func:`prior_candidates`).
        height: Image height in pixels.

    Returns:
        (M, 3, 3) float64 homographies ``F H F`` with ``F`` the row mirror, ``H[2, 2] == 1``.

    """
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, height - 1.0], [0.0, 0.0, 1.0]])
    mirrored = flip @ candidates @ flip
    return mirrored / mirrored[:, 2:3, 2:3]


def search_candidates(prior: PriorConfig, width: int, height: int, plane: str = 'ground'
                      ) -> np.ndarray:
    """Return the candidates a search screens for ``verification.plane`` (ground or any).

    ``ground``: :func:`prior_candidates`; ``any``: those followed by their
    :func:`leaning_candidates` (twice as many).
    """
    candidates = prior_candidates(prior, width, height)
    if plane == 'ground':
        return candidates
    return np.concatenate([candidates, leaning_candidates(candidates, height)])


@functools.lru_cache(maxsize=16)
def _candidate_grid(prior: PriorConfig, width: int, height: int) -> np.ndarray:
    out = [plane_homography(f, bh, tilt, verg, width, height, prior.principal_point_px)
           for f in _samples(prior.focal_px, prior.samples)
           for bh in _samples(prior.baseline_over_height, prior.samples)
           for tilt in _samples(prior.tilt_deg, prior.samples)
           for verg in _samples(prior.vergence_deg, prior.samples)]
    return np.stack(out)


class PriorSearch:
    """The prior search over one feature set: screen every candidate, refine the best.

    One search serves :func:`~domplane_ros.core.plane.estimate_plane` (the best
    ``prior.refine_best`` at once) and the pipeline (a few per frame, new features each
    frame). The feature set's search structures (the right points' KD-tree, the line matcher,
    the refiner) live in ``problem``, built once and shared by the screening and every
    refinement.

    Args:
        problem: The two-step iteration over the feature set
            (:meth:`~domplane_ros.core.estimator.TwoStep.from_features`).
        candidates: (M, 3, 3) float64 candidate homographies (:func:`prior_candidates`).
        threshold_px: Truncation of the screening energy, pixels.

    """

    def __init__(self, problem: TwoStep, candidates: np.ndarray, threshold_px: float) -> None:
        """Screen every candidate."""
        self.problem = problem
        self.candidates = candidates
        self.costs = problem.screening_energy(candidates, threshold_px)

    def ranked(self, skip: Collection[int] = ()) -> list[int]:
        """Return the candidates' indices, lowest screening energy first, leaving out ``skip``.

        Ties keep the index order.
        """
        return [int(i) for i in np.argsort(self.costs, kind='stable') if int(i) not in skip]

    def refine(self, indices: Iterable[int], options: EstimatorConfig,
               rejection: Callable[[PlaneEstimate], str] | None = None,
               best: PlaneEstimate | FailedEstimate | None = None
               ) -> tuple[PlaneEstimate | FailedEstimate | None, str]:
        """Run the full iteration from each candidate of ``indices``; keep the best result.

        Args:
            indices: Candidates to refine.
            options: Estimator settings.
            rejection: Optional check of a successful result: it returns why the result must
                not be taken (``''`` if it may); a rejected result is dropped.
            best: The best result so far (from earlier frames' candidates), if any; a
                candidate replaces it only if it is better.

        Returns:
            The best result that was not rejected (see
            :func:`~domplane_ros.core.result.better_estimate`), None if there was none, and
            the reason of the last rejection (``''`` if none was rejected).

        """
        rejected = ''
        for index in indices:
            result = self.problem.estimate(self.candidates[index], options, widen=False)
            reason = rejection(result) if rejection is not None and result.ok else ''
            if reason:
                rejected = reason
            elif best is None or better_estimate(result, best):
                best = result
        return best, rejected
