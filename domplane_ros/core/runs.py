"""Where a run of the two-step iteration stopped, so that a smaller tolerance goes on from there.

A search refines the same starts more than once on one pair: its swapped cameras' rivals stop
at the candidates' tolerance and, near the uniqueness margin, are refined again from the same
starts at the configured one (``stream/search.py`` ``_checked_pick``). The iteration is
deterministic and its tolerance only decides where it stops, so the second run follows the
first round for round until the first one stopped. :class:`RunRecord` keeps each stage's end
(its energies, its result and, where it stopped only for the tolerance, the whole state there)
and :meth:`~domplane_ros.core.estimator.TwoStep.estimate` iterates on from it: the same
homography, inliers, energies and iteration count as a fresh run, without the rounds repeated.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import NamedTuple

from domplane_ros.config import EstimatorConfig
import numpy as np

__all__ = ['RunRecord', 'StageEnd', 'StageState']


class StageState(NamedTuple):
    """The state of a stage after ``rounds`` rounds (all arrays as the iteration holds them).

    Attributes:
        rounds: Rounds done in the stage.
        h: (3, 3) float64 homography.
        pred: (rows, 2) predictions of the rows under ``h``.
        r: (features,) closest distances.
        idx: (features,) closest indices.
        aux: (rows, 2) auxiliary points.
        penalty: (features,) penalties.
        energy: The joint energy.
        closest: (rows, 2) closest positions.
        move: The largest prediction move of the last round, pixels.
        beta: The extrapolation's next factor (``TwoStep.estimate``'s ``extrapolate``).
        h_before: (3, 3) float64 ``H`` before the last round where the stage stopped for
            the tolerance (a smaller one runs that round's trial step first), else None.
    """

    rounds: int
    h: np.ndarray
    pred: np.ndarray
    r: np.ndarray
    idx: np.ndarray
    aux: np.ndarray
    penalty: np.ndarray
    energy: float
    closest: np.ndarray
    move: float = np.inf
    beta: float = 1.0
    h_before: np.ndarray | None = None


@dataclass(frozen=True)
class StageEnd:
    """How a stage ended: its energies and the iteration's result tuple.

    ``result`` is ``(H, iterations, converged, (pred, r, idx, closest), stopped)`` with
    ``stopped`` the :class:`StageState` where the stage stopped only for the tolerance (a
    smaller one iterates on from it), else None.
    """

    energies: list[float]
    result: tuple

    @property
    def stopped(self) -> StageState | None:
        """Return the state the stage stopped at for the tolerance alone, or None."""
        return self.result[4]


@dataclass
class RunRecord:
    """The stage ends of one run (one start, one set of settings) at ``tolerance_px``."""

    tolerance_px: float
    stages: list[StageEnd] = field(default_factory=list)

    @staticmethod
    def key(start: np.ndarray, options: EstimatorConfig, far: bool,
            extrapolate: bool = False) -> tuple:
        """Return a run's key: start bytes, ``far``, ``extrapolate``, settings but tolerance."""
        rest = tuple(getattr(options, f.name) for f in fields(options) if f.name != 'tolerance_px')
        return np.ascontiguousarray(start, np.float64).tobytes(), far, extrapolate, rest
