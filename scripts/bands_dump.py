"""Dump every ground plane about to be published, with its bands and its error (round 22).

Run ``python scripts/bands_dump.py OUT.jsonl real_rigs|trust [the tool's arguments]``: runs
``evaluate_real_rigs`` or ``evaluate_trust`` unchanged (its own tables on stdout) and writes
one JSON line per call of :meth:`TrustGate.ground_refusal` (every plane about to be published:
a search's finished winner, a challenger, a warm pair's plane) with the tool's case and seed,
the plane's score, confidence, top / middle / bottom scores, the refusal ('' if none), whether
the pair published that very plane, and its error against the truth (mean transfer error over
the road / the visible floor, pixels; NaN where a crop has no road). Measurement only: the
truth is read after the pipeline has decided.
"""

from __future__ import annotations

import json
import math
import sys

from domplane_ros.stream import trust as trust_module
from domplane_ros.stream.pipeline import PlanePipeline
import numpy as np

LOG: list[dict] = []
ORIGINAL_NEAR_FIELD = trust_module.near_field_refusal
STATE: dict = {'case': '', 'seed': None, 'config': '', 'errors': None, 'frame_index': None}
ORIGINAL_GROUND_REFUSAL = trust_module.TrustGate.ground_refusal
ORIGINAL_PROCESS = PlanePipeline.process


def _ground_refusal(self, homography, width, height, check=None):
    refusal = ORIGINAL_GROUND_REFUSAL(self, homography, width, height, check)
    entry = {'refusal': refusal, 'h': np.asarray(homography, dtype=float).copy()}
    if check is not None:
        entry.update(score=check.score, confidence=check.confidence,
                     top=check.top_score, middle=check.middle_score,
                     bottom=check.bottom_score, accepted=check.accepted)
    LOG.append(entry)
    return refusal


def _near_shares(labels, roi):
    """Return the near band's figures: third, its lower half, and its columns' lowest label."""
    from domplane_ros.core.pixel_decision import OBSTACLE, PLANE
    from domplane_ros.stream.near_field import (_band, ground_below_share,
                                                near_obstacle_share)
    band = _band(labels, roi)
    lower = band[band.shape[0] // 2:]
    low_m = np.count_nonzero((lower == PLANE) | (lower == OBSTACLE))
    third = near_obstacle_share(labels, roi)
    return {'third_measured': third[0], 'third_share': third[1],
            'lower_measured': low_m / max(1, lower.size),
            'lower_share': (np.count_nonzero(lower == OBSTACLE) / low_m) if low_m else 0.0,
            'columns_seen': float(np.mean(((band == PLANE) | (band == OBSTACLE)).any(axis=0)))
            if band.size else 0.0,
            'columns_share': ground_below_share(labels, roi)}


def _near_field(left, right, scale, homography, mask, prior, roi, max_share):
    from domplane_ros.stream.detection import level_mask
    refusal = ORIGINAL_NEAR_FIELD(left, right, scale, homography, mask, prior, roi, max_share)
    labels = level_mask(left, right, scale, homography, mask, prior).labels
    entry = {'kind': 'near', 'refusal': refusal, 'h': np.asarray(homography, float).copy()}
    entry.update(_near_shares(labels, roi))
    LOG.append(entry)
    return refusal


def _process(self, left, right, stamp_ns, *args, **kwargs):
    LOG.clear()
    result = ORIGINAL_PROCESS(self, left, right, stamp_ns, *args, **kwargs)
    errors = STATE['errors']
    published = result.homography if result.ok else None
    for entry in LOG:
        h = entry.pop('h')
        error = math.nan
        if errors is not None:
            try:
                error = float(errors(h))
            except Exception:  # noqa: B902 (a measurement must not stop the run)
                error = math.nan
        entry.update(case=STATE['case'], seed=STATE['seed'], config=STATE['config'],
                     frame=STATE['frame_index'], error_px=error,
                     published=bool(published is not None and np.allclose(h, published)))
        OUT.write(json.dumps(entry) + '\n')
    OUT.flush()
    return result


def _real_rigs(argv: list[str]) -> int:
    from domplane_ros.tools import evaluate_real_rigs as tool
    original_run_pair = tool.run_pair

    def run_pair(pair, seed, settings, baselines=True):
        rows, found = [], {}
        for name, config in settings.items():
            STATE.update(case=pair.family + (f' {pair.detail}' if pair.detail else ''),
                         seed=seed, config=name,
                         errors=((lambda h, p=pair: np.mean(p.errors_px(h)))
                                 if pair.has_road else None))
            new, got = original_run_pair(pair, seed, {name: config}, baselines=False)
            rows += new
            found.update(got)
        if baselines:
            more, got = original_run_pair(pair, seed, {}, baselines=True)
            rows += more
            found.update(got)
        return rows, found

    tool.run_pair = run_pair
    return tool.main(argv)


def _trust(argv: list[str]) -> int:
    from domplane_ros.sim.rigs import plane_error_px
    from domplane_ros.tools import evaluate_trust as tool
    original_progress = tool.progress
    frames: dict[int, object] = {}

    def progress(items, label, *args, **kwargs):
        STATE['case'] = label
        return original_progress(items, label, *args, **kwargs)

    def remember(frame, seed, index=None):
        frames[id(frame.left)] = (frame, seed, index)
        return frame

    original_ours = tool._ours_single

    def ours_single(frame, config):
        frames.clear()
        remember(frame, None)
        return original_ours(frame, config)

    def process(self, left, right, stamp_ns, *args, **kwargs):
        known = frames.get(id(left))
        if known is not None:
            frame = known[0]
            STATE['errors'] = lambda h: plane_error_px(frame, h)
            STATE['frame_index'] = known[2]
            if known[1] is not None:
                STATE['seed'] = known[1]
        else:
            STATE['errors'] = None
        return _process(self, left, right, stamp_ns, *args, **kwargs)

    def track_seeds(maker):
        def make(seed, *args, **kwargs):
            STATE['seed'] = seed
            return maker(seed, *args, **kwargs)
        return make

    def sequence(maker):
        def make(*args, **kwargs):
            seed = kwargs.get('seed', args[-1] if args else None)
            STATE['seed'] = seed
            frames.clear()
            return [remember(f, seed, i) for i, f in enumerate(maker(*args, **kwargs))]
        return make

    tool.random_scene = track_seeds(tool.random_scene)
    tool.cut_sequence = sequence(tool.cut_sequence)
    tool.scene_sequence = sequence(tool.scene_sequence)
    tool.ahead_scene = track_seeds(tool.ahead_scene)
    tool.approach_sequence = sequence(tool.approach_sequence)
    tool.progress = progress
    tool._ours_single = ours_single
    PlanePipeline.process = process
    return tool.main(argv)


if __name__ == '__main__':
    OUT = open(sys.argv[1], 'w')
    trust_module.TrustGate.ground_refusal = _ground_refusal
    trust_module.near_field_refusal = _near_field
    if sys.argv[2] == 'real_rigs':
        PlanePipeline.process = _process
        code = _real_rigs(sys.argv[3:])
    else:
        code = _trust(sys.argv[3:])
    OUT.close()
    sys.exit(code)
