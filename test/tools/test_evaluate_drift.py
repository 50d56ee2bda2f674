"""The drift evaluation: its counting, and one small end-to-end run against the truth."""

from __future__ import annotations

import csv

from domplane_ros.tools import evaluate_drift
from domplane_ros.tools.evaluate_drift import drift_lines, Run, Tally


def test_row_counts_pairs_by_error_and_sequences_by_their_worst_pair():
    tally = Tally([Run('plain', 3, '', [0.2, 0.5, 2.0, None]),
                   Run('plain', 4, '', [0.3, 4.0, 6.0], cold_px=0.4, worst_pair=3),
                   Run('plain', 5, '', [None, None])])
    cells = [c.strip() for c in tally.row('plain').strip('|').split('|')]
    # family, sequences, pairs, published, correct, wrong, precision, recall, 1-5 px, worst
    assert cells[:10] == ['plain', '3', '9', '6', '3', '1', '50.0 %', '33.3 %', '2', '6.00']
    assert cells[10] == '2 / 1 / 1'
    assert cells[11] == '4 (6.0), 3 (2.0)'
    lines = drift_lines({'plain': Tally(tally.runs[1:2])})
    assert lines == ['- plain seed 4 (default): worst 6.00 px at pair 3; cold search on that '
                     'pair: 0.40 px (lock)']


def test_small_run_tracks_the_truth_on_every_pair(tmp_path):
    out = tmp_path / 'drift'
    assert evaluate_drift.main(['--seeds', '1', '--frames', '3', '--families', 'plain,head',
                                '--out', str(out)]) == 0
    assert '| plain | 1 | 2 | 2 | 2 | 0 | 100.0 %' in (out / 'summary.md').read_text()
    with open(out / 'sequences.csv', encoding='utf-8') as stream:
        rows = list(csv.DictReader(stream))
    assert [r['family'] for r in rows] == ['plain', 'head']
    for row in rows:
        assert row['pairs'] == '2' and row['correct'] == '2'
        assert float(row['worst_px']) < 1.0
