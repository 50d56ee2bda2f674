"""plane_node with and without the optional head/joint_states input, over real DDS."""

from __future__ import annotations

import time

from domplane_ros.core.homography import apply_homography
import numpy as np
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from test_node import _prior_overrides, Harness, scene  # noqa: F401 - scene is a fixture


def _values(diagnostics):
    return {kv.key: kv.value for kv in diagnostics[-1].status[0].values}


def _plane_error(msg, frame):
    est = np.array(msg.data).reshape(3, 3)
    pts = np.argwhere(frame.plane_left & frame.visible_in_right)[::50, ::-1].astype(float)
    return float(np.mean(np.linalg.norm(apply_homography(est, pts)
                                        - apply_homography(frame.homography, pts), axis=1)))


def test_node_without_joint_states_reports_no_joint_speed(ros_context, scene):  # noqa: F811
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        assert h.node._joint_sub is None
        h.wait_for_subscribers()
        h.send_until(scene.left, scene.right,
                     lambda: h.homographies and h.diagnostics
                     and _values(h.diagnostics)['lock state'] == 'locked', 10_000_000_000)
        assert _plane_error(h.homographies[-1], scene) < 1.0
        values = _values(h.diagnostics)
        assert values['head joint speed [rad/s]'] == 'n/a'
        assert values['warm start'] in ('prediction', 'last', 'search'), values
        assert h.node.joint_speed() is None
        assert not h.node.session.last_result.fast_motion
    finally:
        h.close()


def test_node_with_joint_states_uses_the_fast_joint_hint(ros_context, scene):  # noqa: F811
    overrides = _prior_overrides(scene) + [
        Parameter('head.joint_states_topic', value='head/joint_states'),
        Parameter('pipeline.fast_joint_velocity', value=1.0),
        Parameter('head.max_age_s', value=5.0)]
    h = Harness(ros_context, overrides)
    # A reliable publisher, as robot drivers use; the node's sensor-data subscription matches.
    pub = h.driver.create_publisher(JointState, 'head/joint_states',
                                    QoSProfile(depth=10,
                                               reliability=ReliabilityPolicy.RELIABLE))
    try:
        assert h.node._joint_sub is not None
        assert h.node._joint_sub.topic_name == '/head/joint_states'
        h.wait_for_subscribers()
        deadline = time.monotonic() + 10.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            h.executor.spin_once(timeout_sec=0.05)

        def send_joints(velocity):
            msg = JointState()
            msg.name = ['pan', 'tilt', 'vergence']
            msg.position = [0.0, 0.3, 0.01]
            msg.velocity = velocity
            pub.publish(msg)

        send_joints([0.2, -2.5, float('nan')])  # tilt at 2.5 rad/s; NaN is ignored
        h.send_until(scene.left, scene.right,
                     lambda: h.node.joint_speed() is not None and h.homographies
                     and h.node.session.last_result is not None and h.node.session.last_result.ok
                     and h.node.session.last_result.fast_motion, 10_000_000_000)
        assert h.node.joint_speed() == 2.5
        # The hint does not cost the plane: it is still right.
        assert _plane_error(h.homographies[-1], scene) < 1.0
        send_joints([0.1, 0.2, 0.0])  # slow again
        h.send_until(scene.left, scene.right,
                     lambda: h.node.joint_speed() == 0.2 and h.node.session.last_result is not None
                     and not h.node.session.last_result.fast_motion and h.diagnostics
                     and _values(h.diagnostics)['head joint speed [rad/s]'] == '0.200',
                     20_000_000_000)
        assert h.node.session.last_result.ok
        assert _values(h.diagnostics)['lock state'] == 'locked'
    finally:
        h.close()
