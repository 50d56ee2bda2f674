"""A cold pair's search re-uses the rounds and the screening its rechecked rivals repeat."""

from __future__ import annotations

from itertools import count

from domplane_ros.core import estimator
from domplane_ros.core.homography import NormalisedRefiner
from domplane_ros.core.runs import RunRecord
from domplane_ros.sim.generators import random_scene
from domplane_ros.sim.rigs import swapped
from domplane_ros.stream.pipeline import PlanePipeline
import pytest


@pytest.mark.parametrize('make', [lambda: swapped(random_scene(68)),
                                  lambda: random_scene(101, floor='random')],
                         ids=['swapped68', 'cold101'])
def test_rechecked_rivals_go_on_from_their_stops_with_the_same_verdict(monkeypatch, make):
    # Swapped 68 is ambiguous: its search refines the swapped rivals again at the configured
    # tolerance from the same starts (stream/search.py _checked_pick). Cold 101 is not
    # rechecked: nothing is re-used there, and nothing changes.
    frame = make()
    steps, screenings = [0], [0]
    refine, screen = NormalisedRefiner.refine, estimator.screen_candidates

    def counted_refine(self, *args, **kwargs):
        steps[0] += 1
        return refine(self, *args, **kwargs)

    def counted_screen(*args):
        screenings[0] += 1
        return screen(*args)
    monkeypatch.setattr(NormalisedRefiner, 'refine', counted_refine)
    monkeypatch.setattr(estimator, 'screen_candidates', counted_screen)
    runs = []
    for reuse in (True, False):
        if not reuse:  # every run and screening afresh: a key that never matches
            fresh = count()
            monkeypatch.setattr(RunRecord, 'key', staticmethod(lambda *args: next(fresh)))
            monkeypatch.setattr(estimator.TwoStep, 'screening_energy', _unkept_screening)
        steps[0] = screenings[0] = 0
        result = PlanePipeline().process(frame.left, frame.right, 0)
        runs.append((result, steps[0], screenings[0]))
    (kept, kept_steps, kept_screens), (afresh, fresh_steps, fresh_screens) = runs
    assert kept.ok == afresh.ok and kept.reason == afresh.reason
    assert kept.confidence == afresh.confidence
    if kept.ok:
        assert kept.homography.tobytes() == afresh.homography.tobytes()
    if 'swapped' in kept.reason:
        assert kept_steps < fresh_steps and kept_screens < fresh_screens
    else:
        assert kept_steps == fresh_steps and kept_screens == fresh_screens


def _unkept_screening(self, candidates, threshold_px):
    """Screen as before the screening was kept (the points' energy only, as the search's)."""
    return estimator.screen_candidates(candidates, self.left, self.tree, threshold_px)
