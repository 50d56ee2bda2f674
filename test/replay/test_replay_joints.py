"""plane_replay replays ``head.joint_states_topic`` as plane_node takes it live.

Each JointState message in the bag is a hint for ``head.max_age_s`` of bag (receive) time, and
a pair gets the hint recent when its last image was recorded, as the node's pair gets the hint
recent when it is processed. An implausible speed is flagged, counted and never a hint.
"""

from __future__ import annotations

import csv
from dataclasses import replace

from bag_helpers import _header, image_msg, LEFT, left_stamp, make_frames, read_bag, \
    RIGHT, RIGHT_OFFSET_NS, T, TS
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.errors import BagError
from domplane_ros.replay.cli import run_replay
from domplane_ros.replay.reader import BagInput
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.status import JOINT_SPEED_KEY
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

JOINTS = '/head/joint_states'
# Per pair: the velocities of the JointState recorded 4 ms before its images (None: none).
VELOCITIES = [[0.1, 0.0], [0.1, 0.05], [0.3, 2.0], [float('nan'), -2.0], None, None,
              [0.1, 1e308], [0.2, 0.1]]
# The speed each pair must get with head.max_age_s 0.05: pair 4 the 2.0 of pair 3 (37 ms old),
# pair 5 none (71 ms old), pair 6 none (its message is implausible, the last plausible one
# stale), pair 7 its own.
EXPECTED_SPEEDS = [0.1, 0.1, 2.0, 2.0, 2.0, None, None, 0.2]


def _write(path, frames, joint_type='sensor_msgs/msg/JointState'):
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=TS) for topic, msgtype
                 in ((LEFT, 'sensor_msgs/msg/Image'), (RIGHT, 'sensor_msgs/msg/Image'),
                     (JOINTS, joint_type))}
        for i, frame in enumerate(frames):
            stamp = left_stamp(i)
            if VELOCITIES[i] is not None and joint_type.endswith('JointState'):
                msg = T[joint_type](header=_header(stamp, 'head'), name=['pan', 'tilt'],
                                    position=np.zeros(2),
                                    velocity=np.array(VELOCITIES[i], dtype=np.float64),
                                    effort=np.zeros(0))
                writer.write(conns[JOINTS], stamp + 1_000_000, TS.serialize_cdr(msg, joint_type))
            for topic, gray, frame_id, offset in ((LEFT, frame.left, 'left_cam', 0),
                                                  (RIGHT, frame.right, 'right_cam',
                                                   RIGHT_OFFSET_NS)):
                msgtype, msg = image_msg(gray, stamp + offset, frame_id, compressed=False)
                writer.write(conns[topic], stamp + offset + 5_000_000,
                             TS.serialize_cdr(msg, msgtype))


def _config(topic=JOINTS):
    config = PlaneNodeConfig()
    return replace(config, head=replace(config.head, joint_states_topic=topic, max_age_s=0.05),
                   pipeline=replace(config.pipeline, fast_joint_velocity=1.0))


def test_a_replay_gives_each_pair_the_joint_hint_the_node_would(tmp_path):
    frames = make_frames()
    _write(tmp_path / 'in', frames)
    config = _config()
    replayed = []
    summary = run_replay(tmp_path / 'in', tmp_path / 'out', config,
                         csv_path=tmp_path / 'pairs.csv', on_frame=replayed.append)
    assert len(replayed) == len(frames)
    # The pipeline given the expected speeds gives the same results, pair by pair.
    pipeline = PlanePipeline(config)
    for i, (frame, speed) in enumerate(zip(replayed, EXPECTED_SPEEDS)):
        expected = pipeline.process(frames[i].left, frames[i].right, left_stamp(i),
                                    joint_speed=speed)
        assert frame.result.fast_motion == (speed is not None and speed > 1.0), i
        assert frame.result.fast_motion == expected.fast_motion, i
        assert frame.result.state == expected.state and frame.result.ok == expected.ok, i
        if expected.ok:
            assert np.allclose(frame.result.homography, expected.homography, rtol=0,
                               atol=1e-9), i
    rows = list(csv.DictReader(open(tmp_path / 'pairs.csv')))
    fast = [int(speed is not None and speed > 1.0) for speed in EXPECTED_SPEEDS]
    assert [int(r['fast_motion']) for r in rows] == fast
    # The implausible speed: a note in the summary and a count in /diagnostics, as live.
    assert any(note.startswith('implausible head joint speed 1.000e+308 rad/s')
               and "'tilt'" in note for note in summary.notes), summary.notes
    statuses = read_bag(tmp_path / 'out')['messages']['/diagnostics']
    values = [{kv.key: kv.value for kv in msg.status[0].values} for _, msg in statuses]
    assert values[-1]['joint states implausible'] == '1'
    assert all(JOINT_SPEED_KEY in v for v in values)


def test_without_the_topic_the_replay_has_no_joint_hint_and_no_joint_keys(tmp_path):
    frames = make_frames()[:3]
    _write(tmp_path / 'in', frames)
    replayed = []
    summary = run_replay(tmp_path / 'in', tmp_path / 'out', _config(''),
                         on_frame=replayed.append)
    assert [f.result.fast_motion for f in replayed] == [False] * 3
    assert not any('joint' in note for note in summary.notes)
    statuses = read_bag(tmp_path / 'out')['messages']['/diagnostics']
    assert all('joint states implausible' not in {kv.key for kv in msg.status[0].values}
               for _, msg in statuses)


def test_a_joint_topic_missing_from_the_bag_is_noted_and_a_wrong_type_refused(tmp_path):
    frames = make_frames()[:2]
    _write(tmp_path / 'in', frames)
    summary = run_replay(tmp_path / 'in', tmp_path / 'out', _config('/arm/joint_states'))
    assert ("head.joint_states_topic '/arm/joint_states' is not in the bag: the pairs get no "
            'joint hint') in summary.notes
    _write(tmp_path / 'typed', frames, joint_type='std_msgs/msg/String')
    with pytest.raises(BagError, match=r"head.joint_states_topic '/head/joint_states' has "
                       r'type std_msgs/msg/String, not sensor_msgs/msg/JointState'):
        BagInput(tmp_path / 'typed', LEFT, RIGHT, joint_states_topic=JOINTS)
