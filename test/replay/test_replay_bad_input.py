"""plane_replay applies the same bad-input checks as the node and reports them."""

from __future__ import annotations

from types import SimpleNamespace

from bag_helpers import left_stamp, read_bag, write_bag
from domplane_ros.replay.cli import run_replay
import numpy as np


def test_replay_refuses_a_frozen_camera_and_counts_it(tmp_path, frames):  # noqa: F811
    stream = [SimpleNamespace(left=f.left, right=f.right) for f in frames]
    stream[4].right = stream[3].right            # the right camera repeats frame 3
    stream[6].left = np.zeros_like(stream[6].left)   # a black left frame
    write_bag(tmp_path / 'in', stream)
    summary = run_replay(tmp_path / 'in', tmp_path / 'out')
    refused = {k: v for k, v in summary.input_problems.items() if k.startswith('pairs refused')}
    assert refused == {'pairs refused: camera frozen': 1, 'pairs refused: black or saturated': 1}
    # Besides the two refusals, only the verification may have refused a plane (honestly).
    assert set(summary.input_problems) - set(refused) <= {'pairs failed: no plane verified'}
    assert any('input problems:  pairs refused: camera frozen 1' in line
               for line in summary.lines())
    bag = read_bag(tmp_path / 'out')['messages']
    masks = dict(bag['/plane/mask'])
    homography_stamps = {t for t, _ in bag.get('/plane/homography', [])}
    for bad in (4, 6):
        assert not np.asarray(masks[left_stamp(bad)].data).any()
        assert left_stamp(bad) not in homography_stamps
    assert homography_stamps, 'the good pairs should give planes'
    values = {kv.key: kv.value for kv in bag['/diagnostics'][-1][1].status[0].values}
    assert values['pairs refused: camera frozen'] == '1'
    assert values['pairs refused: black or saturated'] == '1'
