"""The head's joint speed: the hint to expect a big change, from ``sensor_msgs/JointState``.

Both adapters keep one :class:`JointSpeeds` when ``head.joint_states_topic`` is set: plane_node
feeds it each message as it arrives (monotonic receive time), plane_replay each message of the
bag in bag order (the bag's receive time), so a replay gives the pipeline the hint the live
node gave it. A message's speed is its fastest joint's ``|velocity|`` (non-finite entries
ignored); a speed above ``head.max_joint_velocity`` is a sensor fault or a unit mix-up, never
a hint: it is flagged and counted. A speed is a hint for ``head.max_age_s`` after it arrived.
"""

from __future__ import annotations

from typing import Sequence

from domplane_ros.config import HeadConfig
from domplane_ros.errors import wire_repr
from domplane_ros.stream.status import format_number
import numpy as np


class JointSpeeds:
    """The latest plausible and implausible joint speeds, with their receive times.

    Args:
        settings: ``head.*`` (``max_joint_velocity``, ``max_age_s``).

    """

    def __init__(self, settings: HeadConfig) -> None:
        """Start with no joint state received."""
        self.settings = settings
        self._speed: tuple[float, float] | None = None        # (rad/s, receive time s)
        self._implausible: tuple[float, float] | None = None
        self.implausible_count = 0

    def observe(self, velocity: Sequence[float], names: Sequence[str], now_s: float) -> str:
        """Take one JointState's velocities, received at ``now_s``.

        Args:
            velocity: The message's ``velocity`` (rad/s; may be empty or hold NaN).
            names: The message's ``name`` (for the warning).
            now_s: Receive time in seconds (the adapter's clock).

        Returns:
            A one-line warning for an implausible speed (the message is then no hint), else ''.

        """
        speeds = np.abs(np.asarray(velocity, dtype=np.float64).reshape(-1))
        finite = np.isfinite(speeds)
        if not finite.any():
            return ''   # no velocities: no hint
        fastest = int(np.argmax(np.where(finite, speeds, -1.0)))
        speed = float(speeds[fastest])
        limit = self.settings.max_joint_velocity
        if speed > limit:
            name = names[fastest] if fastest < len(names) else f'#{fastest}'
            self._implausible = (speed, now_s)
            self.implausible_count += 1
            return (f'implausible head joint speed {format_number(speed, 3)} rad/s (joint '
                    f'{wire_repr(name)}) > head.max_joint_velocity {limit:g}: ignored')
        self._speed = (speed, now_s)
        self._implausible = None   # the latest message is plausible again
        return ''

    def speed(self, now_s: float) -> float | None:
        """Return the latest plausible joint speed in rad/s if recent at ``now_s``, else None."""
        return self._recent(self._speed, now_s)

    def implausible_speed(self, now_s: float) -> float | None:
        """Return a recent implausible joint speed in rad/s at ``now_s``, or None."""
        return self._recent(self._implausible, now_s)

    def _recent(self, latest: tuple[float, float] | None, now_s: float) -> float | None:
        if latest is None or now_s - latest[1] > self.settings.max_age_s:
            return None
        return latest[0]
