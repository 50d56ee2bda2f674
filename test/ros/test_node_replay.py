"""The live node over DDS gives the replay's results for the same bag."""

from __future__ import annotations

import time

from bag_helpers import LEFT, N_FRAMES, read_bag, RIGHT, write_bag
from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.replay.cli import run_replay
from domplane_ros.replay.reader import BagInput, pair_messages
from domplane_ros.ros.node import PlaneNode
from domplane_ros.stream.sync import ApproximateTimeSync
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_msgs.msg import Float64MultiArray


def _to_rclpy(msg) -> Image:
    out = Image()
    out.header.stamp.sec = int(msg.header.stamp.sec)
    out.header.stamp.nanosec = int(msg.header.stamp.nanosec)
    out.header.frame_id = msg.header.frame_id
    out.height, out.width = int(msg.height), int(msg.width)
    out.encoding = msg.encoding
    out.is_bigendian = int(msg.is_bigendian)
    out.step = int(msg.step)
    out.data = np.asarray(msg.data, np.uint8).tobytes()
    return out


def test_live_node_gives_the_replay_results(ros_context, tmp_path, frames):
    write_bag(tmp_path / 'in', frames, 'mcap')
    replayed = []
    run_replay(tmp_path / 'in', tmp_path / 'out', on_frame=replayed.append, parallax=True)
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        pairs = list(pair_messages(((m.side, m.msg) for m in bag.messages()),
                                   ApproximateTimeSync(0.01, 5)))
    assert len(pairs) == len(replayed) == N_FRAMES

    node = PlaneNode(context=ros_context,
                     parameter_overrides=[Parameter('diagnostics.period_s', value=0.2)])
    driver = Node('replay_driver', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        pub_left = driver.create_publisher(Image, 'left/image_raw', qos_profile_sensor_data)
        pub_right = driver.create_publisher(Image, 'right/image_raw', qos_profile_sensor_data)
        homographies: list[Float64MultiArray] = []
        masks: list[Image] = []
        parallax: list[Image] = []
        diagnostics: list[DiagnosticArray] = []
        results: list[DiagnosticArray] = []
        driver.create_subscription(DiagnosticArray, 'plane/result', results.append, 10)
        driver.create_subscription(Float64MultiArray, 'plane/homography',
                                   homographies.append, 10)
        driver.create_subscription(Image, 'plane/mask', masks.append, 10)
        driver.create_subscription(Image, 'plane/parallax', parallax.append, 10)
        driver.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
        executor.add_node(node)
        executor.add_node(driver)

        def spin_until(predicate, timeout):
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if predicate():
                    return True
                executor.spin_once(timeout_sec=0.02)
            return predicate()

        assert spin_until(lambda: pub_left.get_subscription_count()
                          and pub_right.get_subscription_count()
                          and node._pub_mask.get_subscription_count()
                          and node._pub_parallax.get_subscription_count()
                          and node._pub_h.get_subscription_count(), 15.0), 'no discovery'

        def mask_stamps():
            return [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in masks]

        for pair in pairs:
            # Send the pair, and wait for the node's mask for it before the next one, so that
            # no pair is replaced before the node's worker takes it. A pair lost on the
            # best-effort link is sent again: the node's sync ignores a stamp it has paired.
            for _attempt in range(5):
                pub_left.publish(_to_rclpy(pair.left))
                pub_right.publish(_to_rclpy(pair.right))
                if spin_until(lambda: pair.left_stamp_ns in mask_stamps(), 5.0):
                    break
            else:
                raise AssertionError(f'no mask from the node for {pair.left_stamp_ns}')
        expected_h = [f.result.homography for f in replayed if f.result.ok]
        spin_until(lambda: len(homographies) >= len(expected_h)
                   and diagnostics and diagnostics[-1].status[0].values
                   and node.session.counters.processed == N_FRAMES
                   and len(results) == N_FRAMES and len(parallax) == N_FRAMES, 5.0)
        spin_until(lambda: False, 0.3)   # anything late would show up as an extra message
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()

    assert node.session.counters.processed == N_FRAMES
    assert node.slot.dropped == 0
    assert mask_stamps() == [f.pair.left_stamp_ns for f in replayed]
    for msg, frame in zip(masks, replayed):
        assert np.array_equal(np.frombuffer(bytes(msg.data), np.uint8).reshape(
            msg.height, msg.width), frame.result.mask)
    assert len(homographies) == len(expected_h)
    for msg, h in zip(homographies, expected_h):
        assert np.allclose(np.array(msg.data).reshape(3, 3), h, rtol=0, atol=1e-9)
    # The stamped result of every pair: the same stamps, state, confidence and homography.
    replay_results = read_bag(tmp_path / 'out')['messages']['/plane/result']
    assert [stamp for stamp, _ in replay_results] == mask_stamps()
    for live, (stamp, offline) in zip(results, replay_results):
        assert live.header.stamp.sec * 10**9 + live.header.stamp.nanosec == stamp
        assert live.header.frame_id == offline.header.frame_id
        assert ([(kv.key, kv.value) for kv in live.status[0].values]
                == [(kv.key, kv.value) for kv in offline.status[0].values])
        assert live.status[0].level == bytes([offline.status[0].level])
    # plane_replay --parallax writes the node's parallax images, byte for byte.
    replay_parallax = read_bag(tmp_path / 'out')['messages']['/plane/parallax']
    assert [stamp for stamp, _ in replay_parallax] == mask_stamps()
    assert len(parallax) == N_FRAMES
    for live, (stamp, offline) in zip(parallax, replay_parallax):
        assert live.header.stamp.sec * 10**9 + live.header.stamp.nanosec == stamp
        assert (live.encoding, live.height, live.width, live.step) == (
            offline.encoding, offline.height, offline.width, offline.step)
        assert bytes(live.data) == np.asarray(offline.data, np.uint8).tobytes()
    # The replay's diagnostics carry the node's keys.
    node_keys = [kv.key for kv in diagnostics[-1].status[0].values]
    replay_diag = read_bag(tmp_path / 'out')['messages']['/diagnostics'][-1][1]
    assert [kv.key for kv in replay_diag.status[0].values] == node_keys
