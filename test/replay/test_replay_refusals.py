"""plane_replay says when a lock was lost and re-found: CSV columns, summary, /diagnostics."""

from __future__ import annotations

import csv
import json

from bag_helpers import left_stamp, read_bag, write_bag
from domplane_ros.replay.cli import main
from domplane_ros.replay.report import CSV_COLUMNS
from domplane_ros.sim.rigs import plane_error_px
import numpy as np
from truth import drifting_lock_frames

OLD_COLUMNS = (
    'stamp_ns', 'ok', 'reinitialised', 'n_left', 'n_right', 'n_inliers', 'iterations',
    'final_energy', 'converged',
    'h00', 'h01', 'h02', 'h10', 'h11', 'h12', 'h20', 'h21', 'h22',
    'features_ms', 'estimate_ms', 'mask_ms', 'total_ms', 'state', 'warm_start', 'confidence',
    'reason', 'fast_motion',
)


def test_a_lock_refused_and_refound_in_one_pair_reaches_the_csv_and_summary(tmp_path, capsys):
    # Pair 4's warm plane slid off the floor: the lock's reference refuses it and the search
    # in the same pair publishes the floor (truth.drifting_lock_frames).
    frames = drifting_lock_frames()
    stamps = write_bag(tmp_path / 'in', frames)
    csv_path = tmp_path / 'pairs.csv'
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--csv', str(csv_path),
               '--no-progress'])
    out = capsys.readouterr().out
    assert rc == 0, out
    with open(csv_path, newline='', encoding='utf-8') as stream:
        header = next(csv.reader(stream))
        stream.seek(0)
        rows = list(csv.DictReader(stream))
    # The old columns keep their order; the new ones come last.
    assert tuple(header) == CSV_COLUMNS == OLD_COLUMNS + ('lock_lost', 'refusals')
    assert [int(r['stamp_ns']) for r in rows] == stamps
    published = {t: np.asarray(msg.data).reshape(3, 3)
                 for t, msg in read_bag(tmp_path / 'out')['messages']['/plane/homography']}
    refound = rows[4]
    assert refound['ok'] == '1' and refound['reason'] == ''
    assert plane_error_px(frames[4], published[left_stamp(4)]) < 1.0
    assert refound['lock_lost'].startswith('reference: plane not verified: score ')
    assert json.loads(refound['refusals']) == [refound['lock_lost']]
    assert [r['refusals'] for r in rows[1:4]] == ['[]'] * 3
    assert [r['lock_lost'] for r in rows[1:4]] == [''] * 3
    assert ('  locks lost:      1 (reference 1), re-found in the same pair 1'
            in out.splitlines()), out
    assert '  planes refused:  1 (reference 1)' in out.splitlines(), out
    # The bag's last /diagnostics status counts it too, and names the last lock lost.
    status = read_bag(tmp_path / 'out')['messages']['/diagnostics'][-1][1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert values['locks lost (reference)'] == '1'
    assert values['locks re-found in the same pair'] == '1'
    assert values['planes refused (reference)'] == '1'
    assert values['last lock lost'] == refound['lock_lost']
