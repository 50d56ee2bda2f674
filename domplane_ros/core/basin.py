"""The warm-start basin: how near a start looks, and the multi-start of a far one.

A warm start 20 px off at the image corners is outside the plain truncated quadratic's basin;
graduating its scale (:func:`domplane_ros.core.stages.gnc_scales`) widens the basin, but on
clustered point sets one graduated run still slides into a wrong plane in about 5-10 % of
the scenes, and the far-start test alone missed a fifth of the sparse or 30 %-missing sets'
far starts (partly aligned: a start whose corners move 20 px in random directions is right
somewhere in the image). Two mechanisms, both measured in docs/BENCHMARKS.md:

* :func:`start_support`: the support of a start (features within the threshold of their
  closest partner) and the support by chance (the same start shifted by
  ``FAR_SHIFT_THRESHOLDS`` thresholds). A start is *near* only with several times the chance
  support (``FAR_SUPPORT_RATIO``) and an excess of ``NEAR_EXCESS_SUPPORT`` over it (a start
  2 px off had at least 0.34 on every kind of point set, one 20 px off at most 0.17).
* :func:`far_start`: the graduated run from the start and, one after the other, from the start
  moved ``FAR_START_SHIFT_PX`` right, left, down and up in the right image, until two runs
  agree (within ``FAR_AGREE_PX`` over the left features' bounding box); of the runs made the
  one of lowest energy at the threshold wins (a wrong plane had at least twice the energy of
  the true one on every failure looked at).

This module works on a :class:`~domplane_ros.core.estimator.TwoStep` (duck-typed: ``left``,
``n_points``, ``tree``, ``src``, ``apply``, ``match``, ``local_step``) and imports nothing of
the estimator.
"""

from __future__ import annotations

from typing import Any, Callable

from domplane_ros.core.homography import apply_homography
from domplane_ros.core.potentials import make_potential
import numpy as np

# A start is near when its support is at least this multiple of the mean support of the same
# start shifted by FAR_SHIFT_THRESHOLDS thresholds up, down, left and right (the support by
# chance, which clustered or dense features raise) ...
FAR_SUPPORT_RATIO = 2.5
FAR_SHIFT_THRESHOLDS = 4.0
# ... and exceeds that chance support by at least this fraction of the features (sparse sets
# have little support by chance, so the ratio alone passed partly aligned far starts).
NEAR_EXCESS_SUPPORT = 0.25
# With at least this many points, the support is measured on about this many of them.
FAR_SAMPLE_POINTS = 128
# The start itself, then its shifts right, left, down and up (times the shift).
_FAR_OFFSETS = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
# The multi-start of a far start: the start, then the start moved this much (right image
# pixels) along each of _FAR_OFFSETS[1:], until two graduated runs agree within FAR_AGREE_PX.
FAR_START_SHIFT_PX = 10.0
FAR_AGREE_PX = 1.0


def start_support(problem: Any, h: np.ndarray, threshold_px: float) -> tuple[float, float]:
    """Return the support of the start ``h`` and the support by chance.

    The support is the fraction of features whose prediction lies within ``threshold_px`` of
    its closest partner; the support by chance the mean of that of ``h``'s predictions shifted
    by ``FAR_SHIFT_THRESHOLDS`` thresholds right, left, down and up.

    Args:
        problem: The :class:`~domplane_ros.core.estimator.TwoStep` of the feature set.
        h: (3, 3) float64 start.
        threshold_px: The robust threshold, pixels.

    Returns:
        ``(support, chance)``, fractions in [0, 1].

    """
    shift = FAR_SHIFT_THRESHOLDS * threshold_px
    if problem.n_points >= FAR_SAMPLE_POINTS:
        # Points only, an evenly strided sample: a fraction of a warm run's cost.
        step = max(1, problem.n_points // FAR_SAMPLE_POINTS)
        pred = apply_homography(h, problem.left[::step])
        # The start and its four shifts in one tree query (each point's answer is its own).
        near = (problem.tree.query(pred[None] + _FAR_OFFSETS[:, None] * shift,
                                   distance_upper_bound=threshold_px)[0] < threshold_px)
        support = near.mean(axis=1)
        return float(support[0]), float(np.mean(support[1:]))
    pred = problem.apply(h)
    support = [float(np.mean(problem.match(pred + offset * shift, threshold_px)[0]
                             < threshold_px)) for offset in _FAR_OFFSETS]
    return support[0], float(np.mean(support[1:]))


def start_nearness(problem: Any, h: np.ndarray, threshold_px: float) -> str:
    """Say how near the start ``h`` looks: ``'near'``, ``'doubtful'`` or ``'far'``.

    Far: its support is below ``FAR_SUPPORT_RATIO`` times the support by chance. Near: not
    far, and its support exceeds the chance support by ``NEAR_EXCESS_SUPPORT``. Doubtful:
    in between.

    Args:
        problem: The :class:`~domplane_ros.core.estimator.TwoStep` of the feature set.
        h: (3, 3) float64 start.
        threshold_px: The robust threshold, pixels.

    """
    support, chance = start_support(problem, h, threshold_px)
    if support < FAR_SUPPORT_RATIO * chance:
        return 'far'
    return 'near' if support - chance >= NEAR_EXCESS_SUPPORT else 'doubtful'


def threshold_energy(problem: Any, h: np.ndarray, options: Any) -> float:
    """Return the energy of ``h`` under the plain potential at the threshold (every feature).

    Each feature's auxiliary variable is placed by the potential's rule, so this is the joint
    energy minimised over the auxiliary variables: the same yardstick for results reached
    from different starts or through different stages.
    """
    potential = make_potential(options.potential, options.lambda_weight, options.threshold_px)
    return float(problem.local_step(problem.apply(h), potential)[4].sum())


def far_start(problem: Any, h: np.ndarray, run: Callable[[np.ndarray], Any],
              options: Any, plain: Any = None) -> Any:
    """Run the multi-start of a far start and return the result of lowest energy.

    Args:
        problem: The :class:`~domplane_ros.core.estimator.TwoStep` of the feature set.
        h: (3, 3) float64 start (normalised).
        run: The graduated run from a start: returns a result (``ok``, ``homography``).
        options: The estimator settings (potential, lambda, threshold).
        plain: Optional result of the plain run from ``h``, one more contender (a doubtful
            start: the plain run may be right).

    Returns:
        The successful result of lowest :func:`threshold_energy`, else the first failure.

    """
    box = _feature_box(problem)
    done: list[tuple[float, Any]] = []
    if plain is not None and plain.ok:
        done.append((threshold_energy(problem, plain.homography, options), plain))
    first_failure = None
    for offset in _FAR_OFFSETS:
        start = h if not offset.any() else _shifted(h, FAR_START_SHIFT_PX * offset)
        result = run(start)
        if not result.ok:
            # A failure is false in a boolean context: ``first_failure or result`` kept the last.
            if first_failure is None:
                first_failure = result
            continue
        agrees = any(_max_distance(box, result.homography, other.homography) < FAR_AGREE_PX
                     for _, other in done)
        done.append((threshold_energy(problem, result.homography, options), result))
        if agrees:
            break
    if not done:
        return first_failure
    return min(done, key=lambda item: item[0])[1]


def _shifted(h: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Return ``h`` followed by a translation of the right image by ``offset`` (2,) pixels."""
    move = np.eye(3)
    move[:2, 2] = offset
    return move @ h


def _feature_box(problem: Any) -> np.ndarray:
    """Return the (4, 2) corners of the left features' bounding box."""
    lo, hi = problem.src.min(axis=0), problem.src.max(axis=0)
    return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])


def _max_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Return the largest distance between the images of ``points`` under ``a`` and ``b``."""
    diff = apply_homography(a, points) - apply_homography(b, points)
    return float(np.sqrt(np.einsum('ij,ij->i', diff, diff)).max())
