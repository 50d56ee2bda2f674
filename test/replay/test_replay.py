"""plane_replay: bags in, the node's outputs out; equal to the pipeline."""

from __future__ import annotations

import csv
import os
from pathlib import Path

from bag_helpers import (check_output, expected_results, image_msg, LEFT, left_stamp, read_bag,
                         RIGHT, RIGHT_OFFSET_NS, T, tree, TS, write_bag)
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.replay.cli import main, run_replay
from domplane_ros.replay.reader import BagInput, pair_messages, replay_frames, ReplaySession
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.sync import ApproximateTimeSync
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_replay_equals_pipeline(tmp_path, frames, storage, capsys):
    stamps = write_bag(tmp_path / 'in', frames, storage)
    expected = expected_results(frames, stamps)
    csv_path = tmp_path / 'pairs.csv'
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--csv', str(csv_path),
               '--no-progress'])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert 'pairs processed: 8' in out.out
    check_output(tmp_path / 'out', expected, stamps, storage)
    with open(csv_path, newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert [int(r['stamp_ns']) for r in rows] == stamps
    assert [r['ok'] for r in rows] == [str(int(r.ok)) for r in expected]
    for row, result in zip(rows, expected):
        assert int(row['n_inliers']) == result.n_inliers
        if result.ok:
            assert float(row['h01']) == result.homography[0, 1]
    assert not [p for p in tree(tmp_path) if 'partial' in p]


def test_compressed_png_input_and_storage_override(tmp_path, frames):
    stamps = write_bag(tmp_path / 'in', frames, 'sqlite3', compressed=True)
    expected = expected_results(frames, stamps)
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--storage', 'mcap',
               '--no-progress'])
    assert rc == 0
    check_output(tmp_path / 'out', expected, stamps, 'mcap')


def test_bag_loop_resets_like_the_node(tmp_path, frames):
    # Stamps go back after frame 4 (a looping bag): the replay drops the warm start there.
    order = [0, 1, 2, 3, 4, 0, 1, 2]
    stamps = write_bag(tmp_path / 'in', frames, 'mcap', order=order)
    expected = expected_results(frames, stamps, resets={5})
    session = ReplaySession(PlaneNodeConfig())
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        got = [f for m in bag.messages() for f in session.add(m.side, m.msg)]
    assert [f.pair.after_reset for f in got] == [k == 5 for k in range(8)]
    assert [f.result.reinitialised for f in got][5]
    for frame, result in zip(got, expected):
        assert np.array_equal(frame.result.mask, result.mask)
        assert (frame.result.homography is None) == (result.homography is None)
        if result.ok:
            assert np.array_equal(frame.result.homography, result.homography)
    # The generator API gives the same results.
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        sync = ApproximateTimeSync(0.01, 5)
        results = list(replay_frames(pair_messages(((m.side, m.msg) for m in bag.messages()),
                                                   sync), PlanePipeline()))
    assert [r.stamp_ns for r in results] == stamps
    assert all(np.array_equal(a.mask, b.mask) for a, b in zip(results, expected))


def _params(tmp_path: Path, body: str) -> Path:
    path = tmp_path / 'params.yaml'
    path.write_text('plane_node:\n  ros__parameters:\n' + body)
    return path


def _garbage_file(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    path.write_bytes(b'this is not a bag\n' * 200)
    return path


def _garbage_in_folder(tmp_path: Path) -> Path:
    # A bag folder whose metadata is fine but whose database is garbage.
    bag = tmp_path / 'broken'
    write_bag(bag, [], 'sqlite3')
    (bag / 'broken.db3').write_bytes(os.urandom(4096))
    return bag


@pytest.mark.parametrize('case,needles', [
    ('missing', ['does not exist', 'nope']),
    ('garbage_db3', ['cannot read bag', 'junk.db3']),
    ('garbage_mcap', ['cannot read bag', 'junk.mcap']),
    ('garbage_folder', ['cannot read bag', 'broken']),
    ('truncated_mcap', ['cannot read bag']),
    ('missing_topic', ["'/nope'", 'image topics in the bag: /left/image_raw (Image), '
                                  '/right/image_raw (Image)']),
    ('not_an_image_topic', ["'/chatter'", 'std_msgs/msg/String']),
    ('existing_output', ['exists', '--force']),
    ('unknown_parameter', ["unknown parameter 'estimator.bogus'", 'params.yaml']),
    ('invalid_parameter', ["'estimator.lambda_weight'", 'above the maximum']),
])
def test_refusals_exit_2_with_one_line_and_write_nothing(tmp_path, frames, capsys, case,
                                                         needles):
    inp = tmp_path / 'in'
    write_bag(inp, frames[:2], 'mcap')
    out = tmp_path / 'out'
    extra: list[str] = []
    if case == 'missing':
        inp = tmp_path / 'nope'
    elif case == 'garbage_db3':
        inp = _garbage_file(tmp_path, 'junk.db3')
    elif case == 'garbage_mcap':
        inp = _garbage_file(tmp_path, 'junk.mcap')
    elif case == 'garbage_folder':
        inp = _garbage_in_folder(tmp_path)
    elif case == 'truncated_mcap':
        data = (inp / 'in.mcap').read_bytes()
        (inp / 'in.mcap').write_bytes(data[:len(data) // 2])
    elif case == 'missing_topic':
        extra = ['--left-topic', '/nope']
    elif case == 'not_an_image_topic':
        extra = ['--right-topic', '/chatter']
    elif case == 'existing_output':
        out.mkdir()
        (out / 'keep.txt').write_text('mine')
    elif case == 'unknown_parameter':
        extra = ['--params-file', str(_params(tmp_path, '    estimator.bogus: 1\n'))]
    elif case == 'invalid_parameter':
        extra = ['--params-file', str(_params(tmp_path, '    estimator:\n'
                                                        '      lambda_weight: 1.5\n'))]
    capsys.readouterr()
    before = tree(tmp_path)
    rc = main([str(inp), str(out), '--csv', str(tmp_path / 'pairs.csv'), '--no-progress']
              + extra)
    captured = capsys.readouterr()
    assert rc == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith('plane_replay: error: ')
    for needle in needles:
        assert needle in lines[0]
    assert captured.out == ''
    assert tree(tmp_path) == before
    if case == 'existing_output':
        assert (out / 'keep.txt').read_text() == 'mine'


def test_force_replaces_existing_output(tmp_path, frames):
    write_bag(tmp_path / 'in', frames[:3], 'sqlite3')
    out = tmp_path / 'out'
    write_bag(out, frames[:1], 'mcap')   # an earlier bag: metadata.yaml and out.mcap
    assert main([str(tmp_path / 'in'), str(out), '--force', '--no-progress']) == 0
    assert not (out / 'out.mcap').exists()
    assert len(read_bag(out)['messages']['/plane/mask']) == 3
    inputs = {'in'} | {f'in/{p}' for p in tree(tmp_path / 'in')}
    assert tree(tmp_path) == inputs | {'out', 'out/metadata.yaml', 'out/out.db3'}


def test_failure_mid_bag_leaves_no_output_that_looks_complete(tmp_path, frames, capsys):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'sqlite3')
    db3 = inp / 'in.db3'
    size = db3.stat().st_size
    with open(db3, 'r+b') as stream:   # overwrite pages in the middle of the message data
        stream.seek(size // 2 // 4096 * 4096)
        stream.write(b'\xff' * 3 * 4096)
    out = tmp_path / 'out'
    csv_path = tmp_path / 'pairs.csv'
    before = tree(tmp_path)
    rc = main([str(inp), str(out), '--csv', str(csv_path), '--no-progress'])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and 'failed after' in err[0] and 'removed' in err[0]
    assert tree(tmp_path) == before   # no output, no CSV, no partial folder


def test_interrupted_replay_removes_partial_output(tmp_path, frames):
    write_bag(tmp_path / 'in', frames, 'mcap')
    before = tree(tmp_path)

    def crash(frame):
        if frame.result.stamp_ns >= left_stamp(3):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_replay(tmp_path / 'in', tmp_path / 'out', on_frame=crash)
    assert tree(tmp_path) == before


def test_decode_error_mid_bag_is_counted_not_fatal(tmp_path, frames, capsys):
    path = tmp_path / 'in'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(t, 'sensor_msgs/msg/Image', typestore=TS)
                 for t in (LEFT, RIGHT)]
        for i in range(4):
            for conn, gray, offset in ((conns[0], frames[i].left, 0),
                                       (conns[1], frames[i].right, RIGHT_OFFSET_NS)):
                _, msg = image_msg(gray, left_stamp(i) + offset, 'cam', False)
                if i == 2 and offset == 0:
                    msg = T['sensor_msgs/msg/Image'](
                        header=msg.header, height=msg.height, width=msg.width,
                        encoding='yuv_bogus', is_bigendian=0, step=msg.step, data=msg.data)
                writer.write(conn, left_stamp(i) + offset,
                             TS.serialize_cdr(msg, 'sensor_msgs/msg/Image'))
    rc = main([str(path), str(tmp_path / 'out'), '--no-progress'])
    captured = capsys.readouterr()
    assert rc == 0
    assert 'decode errors: 1 pairs' in captured.out
    assert 'yuv_bogus' in captured.out
    bag = read_bag(tmp_path / 'out')
    assert len(bag['messages']['/plane/mask']) == 3
    values = {kv.key: kv.value for kv in bag['messages']['/diagnostics'][-1][1].status[0].values}
    assert values['decode errors'] == '1'


# --- The same bag through the live node over DDS ------------------------------------------
