"""The line-feature evaluation: its scoring, its verdict, and one small end-to-end run."""

from __future__ import annotations

import csv
import math

from domplane_ros.tools import evaluate_lines
from domplane_ros.tools.evaluate_lines import aim_text, LineCase, METHODS, summary_rows
import numpy as np


def _case(scene_class, errors):
    case = LineCase(scene_class, '0', np.zeros((4, 4), np.uint8))
    for method, error in zip(METHODS, errors):
        case.errors[method] = error
        case.times_ms[method] = 10.0
        case.warm_ms[method] = 2.0
        case.inliers[method] = 5
        case.features[method] = '5'
    return case


def test_aim_counts_low_texture_and_control_scenes():
    inf = math.inf
    cases = [_case('tiles_plain', [5.0, 0.4, 0.3, inf]),
             _case('planks_plain', [0.5, 2.0, 0.6, 0.9]),
             _case('random', [0.2, 9.0, 0.2, 0.5])]
    text = aim_text(cases)
    assert text.startswith('Aim met') and '2 / 2 vs points only 1 / 2' in text
    cases.append(_case('random', [0.2, 9.0, 3.0, 0.5]))
    assert aim_text(cases).startswith('Aim MISSED')
    rows = summary_rows(cases)
    assert len(rows) == 3 * len(METHODS)
    tiles_points = rows[0]
    assert tiles_points[:3] == ['tiles plain', 'points only', '0 / 1 (0 %)']
    assert rows[3][2] == '0 / 1 (0 %)' and rows[3][4] == 'failed'  # ORB on the tiles


def test_small_run_writes_every_output(tmp_path):
    out = tmp_path / 'lines'
    empty = tmp_path / 'no_data'
    empty.mkdir()
    assert evaluate_lines.main(['--scenes', '1', '--data', str(empty), '--out', str(out)]) == 0
    for name in ('summary.md', 'results.csv', 'success.png', 'contact_sheet.png'):
        assert (out / name).stat().st_size > 0
    with open(out / 'results.csv', encoding='utf-8') as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 3 * len(METHODS)
    assert {r['scene_class'] for r in rows} == {'tiles_plain', 'planks_plain', 'random'}
    # The textured control is solved by points (and by points + lines) on scene 0.
    control = {r['method']: r for r in rows if r['scene_class'] == 'random'}
    assert control['points']['solved'] == '1' and control['both']['solved'] == '1'
    assert float(control['both']['error_px']) < 1.0
