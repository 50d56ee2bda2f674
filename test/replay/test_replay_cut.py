"""plane_replay on a bag with a cut: re-lock within 3 pairs, no wrong plane published."""

from __future__ import annotations

from bag_helpers import left_stamp, read_bag, write_bag
from domplane_ros.replay.cli import run_replay
from domplane_ros.sim.rigs import cut_sequence, plane_error_px
import numpy as np

CUT = 5


def test_a_cut_in_a_bag_relocks_within_three_pairs_and_publishes_no_wrong_plane(tmp_path):
    frames = cut_sequence(CUT, 5, seed=1, width=640, height=480)
    write_bag(tmp_path / 'in', frames)
    run_replay(tmp_path / 'in', tmp_path / 'out')
    bag = read_bag(tmp_path / 'out')['messages']
    published = {t: np.asarray(msg.data).reshape(3, 3) for t, msg in bag['/plane/homography']}
    errors = [plane_error_px(f, published[left_stamp(i)]) if left_stamp(i) in published
              else None for i, f in enumerate(frames)]
    assert all(e is None or e < 5.0 for e in errors), errors
    after = errors[CUT:]
    relock = next((i for i, e in enumerate(after) if e is not None and e < 1.0), None)
    assert relock is not None and relock < 3, errors
    # No mask without a published plane.
    for t, msg in bag['/plane/mask']:
        if t not in published:
            assert not np.asarray(msg.data).any()
