"""The photometric planes of a pair: proposed and refined by dense alignment, not verified.

The corners are not the only route to a plane: the coarse photometric alignment
(:class:`~domplane_ros.core.coarse.CoarseAligner`) proposes planes from dense optical flow and
refines a plane by the flow left after warping by it. :class:`CoarsePlanes` gives the pipeline
those planes on one pair: the coarse alignment's candidates of a search
(:meth:`CoarsePlanes.coarse_candidates`) and of the lock's challenge, spread over pairs
(:meth:`CoarsePlanes.coarse_steps`); a plane's photometric refinement
(:meth:`CoarsePlanes.refined`); its period siblings on a repeating texture
(:meth:`CoarsePlanes.siblings`); and a photometric polish of a start by the verification's
score (:meth:`CoarsePlanes.polish`). None is verified here: the trust gate
(:class:`~domplane_ros.stream.trust.TrustGate`) judges them, and it owns this object, its
aligner and the per-pair memo that both share (the planes of one pair are computed once
between the gate's ``begin_pair`` and ``end_pair``).
"""

from __future__ import annotations

from typing import Callable, Generator, Sequence

from domplane_ros.config import VerificationSettings
from domplane_ros.core.coarse import CoarseAligner, REFINE_NEAR_PX
from domplane_ros.core.periodic import period_vectors
from domplane_ros.core.verification import PlaneVerification, VerificationConfig
from domplane_ros.stream.uniqueness import Maps, PerPair
import numpy as np

# A plane's period siblings (CoarsePlanes.siblings) are refined photometrically from the plane
# moved by a repeat of its texture, with the samples' residual flow up to this many working
# pixels (the repeat under perspective is not one translation; the first photometric
# refinement of a coarse plane takes the same, stream/candidates.py PHOTOMETRIC_FIRST_NEAR_PX).
SIBLING_NEAR_PX = 8.0

# The gate's verification of a plane on a pair (verified once per plane between begin_pair
# and end_pair): (left, right, homography, roi) -> PlaneVerification.
Verify = Callable[[np.ndarray, np.ndarray, np.ndarray, Sequence[float] | None],
                  PlaneVerification]


class CoarsePlanes:
    """The photometric planes of a pair, over one gate's aligner, memo and verification.

    Args:
        settings: The gate's ``verification.*`` parameters (``coarse_candidates``).
        coarse: The gate's photometric alignment.
        per_pair: The gate's memo for the pair of ``begin_pair``
            (:data:`~domplane_ros.stream.uniqueness.PerPair`).
        maps: The gate's agreement maps of a plane
            (:data:`~domplane_ros.stream.uniqueness.Maps`).
        verify: The gate's verification of a plane (:data:`Verify`).
        config: The gate's verification settings for images of a width, pixels.

    """

    def __init__(self, settings: VerificationSettings, coarse: CoarseAligner,
                 per_pair: PerPair, maps: Maps, verify: Verify,
                 config: Callable[[int], VerificationConfig]) -> None:
        """Keep the gate's settings, aligner, memo, maps and verification."""
        self._settings = settings
        self._coarse = coarse
        self._per_pair = per_pair
        self._maps = maps
        self._verify = verify
        self._config = config

    def coarse_candidates(self, left: np.ndarray, right: np.ndarray, shifted: bool = True,
                          peaks: bool = False) -> np.ndarray:
        """Return (K, 3, 3) planes of the coarse photometric alignment (K = 0 if disabled).

        ``shifted``: also align after the dominant shift (the search); the lock's challenge
        takes the plain alignment only (measured: the shifted planes cost a warm pair of a
        cut sequence 4 ms CPU at the median, mostly as extra challengers). ``peaks``: instead,
        the planes of the further shifted alignments
        (:meth:`~domplane_ros.core.coarse.CoarseAligner.peak_candidates`), for a search in
        doubt. Computed once per pair of the gate's ``begin_pair``.
        """
        if not self._settings.coarse_candidates or left.shape != right.shape:
            return np.zeros((0, 3, 3))
        key = 'peaks' if peaks else shifted
        return self._per_pair(left, right, key,
                              lambda: self._coarse_planes_of(left, right, key)).copy()

    def _coarse_planes_of(self, left: np.ndarray, right: np.ndarray, key: bool | str
                          ) -> np.ndarray:
        if key == 'peaks':
            return self._coarse.peak_candidates(left, right)
        return self._coarse.candidates(left, right, bool(key))

    def coarse_steps(self, left: np.ndarray, right: np.ndarray
                     ) -> Generator[None, None, np.ndarray] | None:
        """Return the plain coarse alignment as resumable steps (the lock's challenge).

        :meth:`CoarseAligner.plain_steps`: ``coarse_candidates(left, right, shifted=False)``
        spread over two ``next()`` calls; None if the coarse candidates are disabled or the
        images differ in size.
        """
        if not self._settings.coarse_candidates or left.shape != right.shape:
            return None
        return self._coarse.plain_steps(left, right)

    def refined(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                near_px: float = REFINE_NEAR_PX, finish: bool = False) -> np.ndarray | None:
        """Return the plane's photometric refinement (:meth:`CoarseAligner.refine`), unverified.

        ``finish``: a search's winner, refined at the finishing width.
        """
        return self._coarse.refine(left, right, homography, near_px, finish)

    def siblings(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                 roi: Sequence[float] | None = None) -> list[np.ndarray]:
        """Return the plane's period siblings: the plane moved by its texture's repeats.

        On a periodic texture a look-alike some periods off explains much of the pattern; the
        true plane is then among its siblings (and explains more: the pattern's border, the
        rest of it). The repeats are :func:`~domplane_ros.core.periodic.period_vectors` of
        the left image over the plane's support (at the verification's working width); each
        of ``+-p1``, ``+-p2``, ``+-(p1 + p2)``, ``+-(p1 - p2)`` moves the plane in the right
        image and is refined photometrically (:meth:`refined`, :data:`SIBLING_NEAR_PX`).
        Unverified: the caller judges them. Cached for the pair of the gate's ``begin_pair``.

        Returns:
            (3, 3) float64 homographies (none when the texture does not repeat).

        """
        key = ('siblings', np.asarray(homography, np.float64).tobytes())
        return list(self._per_pair(left, right, key, lambda: np.array(
            self._siblings_of(left, right, homography, roi)).reshape(-1, 3, 3)))

    def _siblings_of(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                     roi: Sequence[float] | None) -> list[np.ndarray]:
        """Return the period siblings of :meth:`siblings`, computed."""
        maps = self._maps(left, right, homography, roi)
        scale = left.shape[1] / maps.left.shape[1]
        vectors = scale * period_vectors(maps.left, maps.support)
        shifts = list(vectors)
        if len(vectors) == 2:
            shifts += [vectors[0] + vectors[1], vectors[0] - vectors[1]]
        out = []
        for shift in shifts:
            for sign in (1.0, -1.0):
                dx, dy = sign * shift
                moved = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ homography
                refined = self._coarse.refine(left, right, moved, SIBLING_NEAR_PX)
                if refined is not None:
                    out.append(refined)
        return out

    def polish(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
               roi: Sequence[float] | None = None) -> np.ndarray:
        """Return the best-scoring of a plane moved by up to one probe step in the right image.

        A photometric polish for a start the corners cannot refine: the plane and its eight
        neighbours ``T(d) H`` (``d`` on a grid of half a working pixel of the verification,
        in full pixels: 2 px at 640 x 480) are verified and the best returned.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image.
            homography: (3, 3) float64 start homography.
            roi: Region of the left image (fractions), as ``features.roi``.

        Returns:
            (3, 3) float64 homography.

        """
        config = self._config(left.shape[1])
        step = 0.5 * left.shape[1] / config.working_width_px
        best, best_score = homography, -1.0
        for dx in (-step, 0.0, step):
            for dy in (-step, 0.0, step):
                moved = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ homography
                score = self._verify(left, right, moved, roi).peak_score
                if score > best_score:
                    best, best_score = moved / moved[2, 2], score
        return best
