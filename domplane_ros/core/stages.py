"""The stages of a run: graduated non-convexity (GNC) of the potential's scale.

A convex potential runs one stage at ``threshold_px``. A graduated one runs from
``gnc_start_px`` down to the threshold by ``gnc_factor``, so that its wide first stages find
the basin and its last stage decides at the threshold
(:class:`~domplane_ros.core.estimator.TwoStep` runs them; the energy is monotone within each
stage).
"""

from __future__ import annotations

from domplane_ros.config import EstimatorConfig

__all__ = ['GRADUATED', 'GRADUATED_WHEN_FAR', 'can_widen', 'gnc_scales']

# Potentials whose scale is always graduated (GNC): from ``gnc_start_px`` down to the
# threshold.
GRADUATED = ('geman_mcclure',)
# Potentials graduated only from a warm start that does not look near (`core/basin.py`).
# Graduating the truncated quadratic always widens its basin on point sets (0 % -> 95-100 %
# converged from 20 px corner displacements, spread, clustered, half off-plane, 30 % missing,
# sparse) but from the prior's candidates and from good starts on rendered pairs its wide
# stages slide into periodic look-alikes (cold start solved 73 % -> 47 %, planks 64 % -> 21 %,
# one run on seeds 0-29): so only a far warm start is graduated.
GRADUATED_WHEN_FAR = ('truncated_quadratic',)


def can_widen(options: EstimatorConfig) -> bool:
    """Return whether a far start graduates the potential of ``options`` (see ``widen``).

    Only the potentials of ``GRADUATED_WHEN_FAR``, and only with ``gnc_start_px`` at least
    twice the threshold (a threshold near the start scale is wide already).
    """
    return (options.potential in GRADUATED_WHEN_FAR
            and options.gnc_start_px >= 2.0 * options.threshold_px)


def gnc_scales(options: EstimatorConfig, far: bool = False) -> list[float]:
    """Return the scales (pixels) of the stages: one for convex potentials, several for GNC.

    Args:
        options: Estimator settings.
        far: The start looks far: the potentials of ``GRADUATED_WHEN_FAR`` are graduated too.

    Returns:
        Decreasing scales ending at ``options.threshold_px``.

    """
    graduated = options.potential in GRADUATED or (far and
                                                   options.potential in GRADUATED_WHEN_FAR)
    if not graduated or options.gnc_start_px <= options.threshold_px:
        return [options.threshold_px]
    scales = []
    s = options.gnc_start_px
    while s > options.threshold_px * 1.0001:
        scales.append(s)
        s *= options.gnc_factor
    scales.append(options.threshold_px)
    return scales
