"""Review of the warm pair's anchor: it must not replace a warm estimate by an unfitted start.

Ground truth comes from the renderer; the configuration is the documented default.
"""

from __future__ import annotations

from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream import pipeline as pipeline_module
from domplane_ros.stream.pipeline import PlanePipeline
import pytest

PERIOD_NS = 33_333_333


@pytest.fixture(scope='module')
def faint_walk():
    # evaluate_drift's floors family, tuning seed 62 (1.28 m faint tiles): few corners.
    return scene_sequence(16, 62, floor='tiles_faint_256')[:6]


def _errors(frames) -> list[float | None]:
    pipeline = PlanePipeline()
    out = []
    for index, frame in enumerate(frames):
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        out.append(plane_error_px(frame, result.homography) if result.ok else None)
    return out


def test_the_anchor_does_not_publish_an_unfitted_prediction(faint_walk, monkeypatch):
    # Pair 5: the warm estimate is 6.4 px off; the prediction (1.54 px off) has 6 features
    # within the tight band, fewer than the 8 the polish needs, so it comes back unfitted, yet
    # its truncated energy is the lower one: it replaced the warm estimate, passed the gate and
    # was published 1.54 px off. Without the anchor that pair is refused, searched and
    # published 0.02 px off. Fails while an unfitted start may replace the warm estimate.
    errors = _errors(faint_walk)
    assert errors[5] is None or errors[5] < 1.0, errors
    monkeypatch.setattr(pipeline_module, 'WARM_ANCHOR', False)
    off = _errors(faint_walk)
    assert off[5] is not None and off[5] < 1.0, off
