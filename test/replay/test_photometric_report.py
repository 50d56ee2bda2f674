"""A photometric plane (too few corners, no point energy) in the replay CSV and the status.

Such a plane carries no corner inliers and no energy (``potential`` is ``'photometric'``):
the CSV's ``final_energy`` is empty and the status's ``final energy`` is ``n/a``, not a
perfect-looking 0; a corner plane still reports its energy.
"""

from __future__ import annotations

import csv
from dataclasses import replace

from domplane_ros.replay.report import CsvOutput
from domplane_ros.stream.candidates import photometric_estimate
from domplane_ros.stream.frame import FrameResult
from domplane_ros.stream.status import _result_values
import numpy as np


def _result(estimate):
    h = np.array([[1.0, 0.0, -40.0], [0.0, 1.0, 2.0], [0.0, 0.0, 1.0]])
    return FrameResult(stamp_ns=7, ok=True, homography=h, mask=np.zeros((4, 4), np.uint8),
                       estimate=estimate, left_points=np.zeros((9, 2)),
                       right_points=np.zeros((9, 2)), reinitialised=True, reason='',
                       state='locked', warm_start=estimate.potential, confidence=0.9)


def test_a_photometric_plane_reports_no_energy(tmp_path):
    h = np.array([[1.0, 0.0, -40.0], [0.0, 1.0, 2.0], [0.0, 0.0, 1.0]])
    photometric = photometric_estimate(h)
    corners = replace(photometric, potential='cauchy', final_energy=12.5,
                      inliers=np.ones(9, bool))
    out = CsvOutput(tmp_path / 'run.csv')
    out.write(_result(photometric))
    out.write(_result(corners))
    out.commit()
    with open(tmp_path / 'run.csv', newline='', encoding='utf-8') as stream:
        rows = list(csv.DictReader(stream))
    assert rows[0]['final_energy'] == '' and rows[0]['n_inliers'] == '0'
    assert rows[0]['warm_start'] == 'photometric' and rows[0]['ok'] == '1'
    assert float(rows[1]['final_energy']) == 12.5 and rows[1]['n_inliers'] == '9'
    assert dict(_result_values(_result(photometric), None))['final energy'] == 'n/a'
    assert dict(_result_values(_result(corners), None))['final energy'] == '12.5'
