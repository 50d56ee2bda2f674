"""plane_replay's outputs never replace what is not a bag, and a refused output leaves nothing.

Found by the session-13 audit (docs/HARDENING.md, "Audit (session 13)"): ``--force`` deleted
any folder or file given as OUTPUT_BAG; a ``--csv`` file that could not be created left the
hidden partial bag folder behind; a topic given as the node names it (``left/image_raw``)
was not found in a bag that records it as ``/left/image_raw``; and the replay ignored
``camera_info.topic``, which narrows the node's prior; a run that wrote nothing ("no pairs")
left the empty folders it had made for its outputs.
"""

from __future__ import annotations

from dataclasses import replace

from bag_helpers import (_header, image_msg, LEFT, left_stamp, read_bag, RIGHT, T, tree, TS,
                         write_bag)
from domplane_ros.params_file import load_params_file
from domplane_ros.replay.cli import EXIT_NO_PAIRS, EXIT_OK, EXIT_REFUSED, main, run_replay
from domplane_ros.stream.pipeline import PlanePipeline
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer


@pytest.fixture
def bag(tmp_path, frames):
    path = tmp_path / 'in'
    write_bag(path, frames[:2], 'sqlite3')
    return path


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith('plane_replay: error: '), captured.err
    assert 'Traceback' not in captured.err
    return lines[0]


@pytest.mark.parametrize('kind', ['folder', 'file'])
def test_force_does_not_replace_what_is_not_a_bag(tmp_path, bag, capsys, kind):
    out = tmp_path / 'data'
    if kind == 'folder':
        (out / 'sub').mkdir(parents=True)
        (out / 'notes.txt').write_text('mine')
        (out / 'sub' / 'more.txt').write_text('mine too')
    else:
        out.write_text('mine')
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--force', '--no-progress'])
    line = _one_error_line(capsys)
    assert rc == EXIT_REFUSED
    assert str(out) in line and '--force only replaces a bag' in line
    if kind == 'folder':
        assert "'notes.txt'" in line and (out / 'notes.txt').read_text() == 'mine'
    else:
        assert 'is a file' in line and out.read_text() == 'mine'
    assert tree(tmp_path) == before


def test_force_with_keep_partial_does_not_replace_what_is_not_a_bag(tmp_path, bag, capsys):
    out = tmp_path / 'out'
    (tmp_path / 'out.incomplete').mkdir()
    (tmp_path / 'out.incomplete' / 'notes.txt').write_text('mine')
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--force', '--keep-partial', '--no-progress'])
    assert rc == EXIT_REFUSED and 'out.incomplete' in _one_error_line(capsys)
    assert tree(tmp_path) == before


@pytest.mark.parametrize('which', ['csv', 'bag'])
def test_output_that_cannot_be_created_is_refused_and_leaves_nothing(tmp_path, bag, capsys,
                                                                     which):
    # A regular file where a folder should be: refused as a read-only folder is, also as root.
    (tmp_path / 'plain.txt').write_text('x')
    out = tmp_path / ('plain.txt' if which == 'bag' else '') / 'out'
    csv_path = tmp_path / ('plain.txt' if which == 'csv' else '') / 'pairs.csv'
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--csv', str(csv_path), '--no-progress'])
    line = _one_error_line(capsys)
    assert rc == EXIT_REFUSED
    assert ('cannot create the CSV file' if which == 'csv'
            else 'cannot create the output bag') in line
    assert tree(tmp_path) == before   # no hidden .out.partial-* folder either


def test_relative_topic_names_find_the_bags_absolute_topics(tmp_path, bag, capsys):
    out = tmp_path / 'out'
    rc = main([str(bag), str(out), '--left-topic', 'left/image_raw',
               '--right-topic', 'right/image_raw', '--no-progress'])
    assert rc == EXIT_OK
    assert len(read_bag(out)['messages']['/plane/mask']) == 2
    # The diagnostics name the topics as the bag (and the node) does.
    diagnostics = read_bag(out)['messages']['/diagnostics'][-1][1]
    keys = [kv.key for kv in diagnostics.status[0].values]
    assert '/left/image_raw images received' in keys
    capsys.readouterr()
    rc = main([str(bag), str(tmp_path / 'out2'), '--left-topic', 'left/image_raw',
               '--right-topic', '/left/image_raw', '--no-progress'])
    assert rc == EXIT_REFUSED and 'the same' in _one_error_line(capsys)


def _bag_with_camera_info(path, frames, k_focal_px, width, height):
    """Write the rendered pairs, each after the left camera's CameraInfo (K of the rig)."""
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=TS) for topic, msgtype
                 in ((LEFT, 'sensor_msgs/msg/Image'), (RIGHT, 'sensor_msgs/msg/Image'),
                     ('/left/camera_info', 'sensor_msgs/msg/CameraInfo'))}
        for i, frame in enumerate(frames):
            stamp = left_stamp(i)
            info = T['sensor_msgs/msg/CameraInfo'](
                header=_header(stamp, 'left_cam'), height=height, width=width,
                distortion_model='plumb_bob', d=np.zeros(5),
                k=np.array([k_focal_px, 0, cx, 0, k_focal_px, cy, 0, 0, 1.0]),
                r=np.eye(3).ravel(), p=np.zeros(12), binning_x=0, binning_y=0,
                roi=T['sensor_msgs/msg/RegionOfInterest'](
                    x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
            writer.write(conns['/left/camera_info'], stamp,
                         TS.serialize_cdr(info, 'sensor_msgs/msg/CameraInfo'))
            for topic, gray, frame_id in ((LEFT, frame.left, 'left_cam'),
                                          (RIGHT, frame.right, 'right_cam')):
                msgtype, msg = image_msg(gray, stamp, frame_id, compressed=False)
                writer.write(conns[topic], stamp + 1000, TS.serialize_cdr(msg, msgtype))
    return cx, cy


def test_camera_info_topic_narrows_the_prior_as_on_the_node(tmp_path, frames, capsys):
    height, width = frames[0].left.shape
    focal = 1.03 * frames[0].setup.focal_px   # a calibration 3 % off, as the node's test
    cx, cy = _bag_with_camera_info(tmp_path / 'in', frames[:3], focal, width, height)
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    camera_info:\n'
                      '      topic: left/camera_info\n'
                      '    prior:\n      focal_px: [1500.0, 2500.0]\n')
    replayed = []
    config = load_params_file(str(params))
    summary = run_replay(tmp_path / 'in', tmp_path / 'out', config, on_frame=replayed.append)
    assert any(note.startswith('prior from camera_info: focal_px') for note in summary.notes)
    # The node's camera_info handling: the prior narrowed to K before the first pair.
    narrowed = replace(config, prior=replace(config.prior, focal_px=(0.9 * focal, 1.1 * focal),
                                             principal_point_px=(cx, cy)))
    pipeline = PlanePipeline(narrowed)
    for i, frame in enumerate(replayed):
        expected = pipeline.process(frames[i].left, frames[i].right, left_stamp(i))
        assert frame.result.state == expected.state and frame.result.ok == expected.ok
        assert np.array_equal(frame.result.mask, expected.mask)
        if expected.ok:
            assert np.allclose(frame.result.homography, expected.homography, rtol=0,
                               atol=1e-9)
    # Without the topic in the bag the prior stays, and the summary says so.
    write_bag(tmp_path / 'plain', frames[:2])
    capsys.readouterr()
    assert main([str(tmp_path / 'plain'), str(tmp_path / 'out2'), '--params-file', str(params),
                 '--no-progress']) == EXIT_OK
    assert ("note: camera_info.topic 'left/camera_info' is not in the bag: the prior stays "
            'as configured') in capsys.readouterr().out


def test_a_run_that_writes_nothing_leaves_no_folders_it_made(tmp_path, capsys):
    write_bag(tmp_path / 'empty', [], 'mcap')
    before = tree(tmp_path)
    rc = main([str(tmp_path / 'empty'), str(tmp_path / 'new' / 'a' / 'out'),
               '--csv', str(tmp_path / 'new2' / 'b' / 'pairs.csv'), '--no-progress'])
    assert rc == EXIT_NO_PAIRS and 'nothing was written' in capsys.readouterr().err
    assert tree(tmp_path) == before


def test_node_name_reads_the_blocks_of_a_renamed_node(tmp_path, bag, capsys):
    params = tmp_path / 'front.yaml'   # a file for '-r __node:=front_plane -r __ns:=/front'
    params.write_text('/front/front_plane:\n  ros__parameters:\n    camera_info:\n'
                      '      topic: front/camera_info\n')
    capsys.readouterr()
    rc = main([str(bag), str(tmp_path / 'out'), '--params-file', str(params), '--no-progress'])
    line = _one_error_line(capsys)
    assert rc == EXIT_REFUSED and 'blocks found: front/front_plane' in line
    assert '--node-name' in line
    rc = main([str(bag), str(tmp_path / 'out'), '--params-file', str(params),
               '--node-name', 'front_plane', '--no-progress'])
    # The block was read: its camera_info.topic is looked for in the bag.
    assert rc == EXIT_OK
    assert "note: camera_info.topic 'front/camera_info' is not in the bag" in (
        capsys.readouterr().out)
