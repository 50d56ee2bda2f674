"""plane_replay with ``verification.plane: any`` from a parameters file: a board, not a floor.

The same bag of a rendered board leaning toward the head (``sim/boards.py``, tuning seed 8)
replayed with the two settings a user would write: the default ``ground`` refuses the board
(its disparity shrinks down the image like a swapped floor), ``any`` publishes its plane.
The prior is what a user looking at a board would set: the plane faces the head.
"""

from __future__ import annotations

import csv

from bag_helpers import write_bag
from domplane_ros.replay.cli import EXIT_NO_PLANE, EXIT_OK, main
from domplane_ros.sim.boards import board_scene
from domplane_ros.sim.rigs import plane_error_px
import numpy as np
import pytest

PARAMS = """plane_node:
  ros__parameters:
    prior.focal_px: [400.0, 900.0]
    prior.tilt_deg: [45.0, 89.0]
    prior.vergence_deg: [-6.0, 6.0]
    verification.plane: {plane}
"""


@pytest.fixture(scope='module')
def board():
    return board_scene(8, 320, 240)


@pytest.mark.parametrize('plane', ['ground', 'any'])
def test_the_replay_seeks_the_plane_its_parameters_file_names(tmp_path, board, plane, capsys):
    write_bag(tmp_path / 'in', [board] * 4, 'mcap')
    params = tmp_path / 'params.yaml'
    params.write_text(PARAMS.format(plane=plane))
    csv_path = tmp_path / 'pairs.csv'
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--params-file', str(params),
               '--csv', str(csv_path), '--no-progress'])
    # No plane in any pair (the ground plane sought on a board): exit 5, output written.
    assert rc == (EXIT_NO_PLANE if plane == 'ground' else EXIT_OK), capsys.readouterr().err
    with open(csv_path, newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 4
    published = [row for row in rows if row['ok'] == '1']
    if plane == 'ground':
        assert published == []
        return
    assert published, [row['reason'] for row in rows]
    for row in published:
        hom = np.array([float(row[f'h{i}{j}']) for i in range(3) for j in range(3)])
        assert plane_error_px(board, hom.reshape(3, 3)) < 1.0
