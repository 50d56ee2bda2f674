"""Rendered sequences of an active head that pans, tilts and verges in place, with truth.

:class:`HeadMotion` says how the head moves; :func:`head_sequence` renders the frames lazily,
with boxes standing all around the head (:func:`ring_of_boxes`).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Iterator

from domplane_ros.sim.model import (Box, CameraSetup, HeadPose, level_boxes, overlaps_any,
                                    StereoFrame)
from domplane_ros.sim.render import render_stereo
import numpy as np


@dataclass(frozen=True)
class HeadMotion:
    """How an active head moves in :func:`head_sequence` (angles in degrees, rates per second).

    The head stands still on the floor. It pans about the vertical axis through the left
    camera at a constant ``pan_rate_deg_s``, tilts sinusoidally about the baseline between
    ``tilt_range_deg`` with peak rate ``tilt_rate_deg_s``, and verges sinusoidally within
    ``vergence_range_deg`` with peak rate ``vergence_rate_deg_s``.

    Attributes:
        pan_rate_deg_s: Pan speed, degrees per second (sign: direction).
        tilt_rate_deg_s: Peak tilt speed, degrees per second.
        vergence_rate_deg_s: Peak vergence speed, degrees per second.
        tilt_range_deg: ``(min, max)`` tilt, degrees.
        vergence_range_deg: ``(min, max)`` vergence, degrees.
        rate_hz: Frame rate.
    """

    pan_rate_deg_s: float = 30.0
    tilt_rate_deg_s: float = 30.0
    vergence_rate_deg_s: float = 6.0
    tilt_range_deg: tuple[float, float] = (15.0, 45.0)
    vergence_range_deg: tuple[float, float] = (-1.5, 3.5)
    rate_hz: float = 30.0

    def __post_init__(self) -> None:
        """Check the values.

        Raises:
            ValueError: If a value is non-finite, a range is inverted, the tilt leaves
                (-89, 89) degrees or the rate is not positive.

        """
        values = (self.pan_rate_deg_s, self.tilt_rate_deg_s, self.vergence_rate_deg_s,
                  *self.tilt_range_deg, *self.vergence_range_deg, self.rate_hz)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'head motion values must be finite, got {values!r}')
        if self.rate_hz <= 0:
            raise ValueError(f'rate_hz must be positive, got {self.rate_hz}')
        for name in ('tilt_range_deg', 'vergence_range_deg'):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f'{name} is inverted: {low} > {high}')
        if not (-89.0 < self.tilt_range_deg[0] and self.tilt_range_deg[1] < 89.0):
            raise ValueError(f'tilt_range_deg must be inside (-89, 89), got '
                             f'{self.tilt_range_deg}')

    @classmethod
    def at_speed(cls, speed_deg_s: float, rate_hz: float = 30.0) -> HeadMotion:
        """Return pan and tilt at ``speed_deg_s`` each, vergence at a fifth of it."""
        return cls(pan_rate_deg_s=speed_deg_s, tilt_rate_deg_s=speed_deg_s,
                   vergence_rate_deg_s=0.2 * speed_deg_s, rate_hz=rate_hz)

    def angles(self, frame: int, phase: float = 0.0) -> tuple[float, float, float]:
        """Return ``(pan, tilt, vergence)`` in degrees at a frame index.

        Args:
            frame: Frame index (time ``frame / rate_hz``).
            phase: Phase offset of the tilt and vergence sines, radians.

        Returns:
            The three angles, degrees.

        """
        t = frame / self.rate_hz
        pan = self.pan_rate_deg_s * t
        out = [pan]
        for (low, high), rate, shift in ((self.tilt_range_deg, self.tilt_rate_deg_s, 0.0),
                                         (self.vergence_range_deg, self.vergence_rate_deg_s,
                                          1.3)):
            centre, amplitude = 0.5 * (low + high), 0.5 * (high - low)
            if amplitude <= 0 or rate == 0:
                out.append(centre)
                continue
            omega = math.radians(abs(rate)) / math.radians(amplitude)
            out.append(centre + amplitude * math.sin(omega * t + phase + shift))
        return out[0], out[1], out[2]


def ring_of_boxes(rng: np.random.Generator, count: int = 10, distance: tuple[float, float] = (
        2.5, 7.0)) -> list[Box]:
    """Place ``count`` boxes around a head at the origin (level frame, all directions).

    Args:
        rng: Random generator.
        count: Number of boxes.
        distance: ``(min, max)`` horizontal distance of a box centre from the head.

    Returns:
        Non-overlapping boxes spread evenly in bearing, with random distance and size.

    """
    boxes: list[Box] = []
    for i in range(count):
        bearing = 2 * math.pi * (i + rng.uniform(0.15, 0.85)) / max(count, 1)
        dist = float(rng.uniform(*distance))
        size = float(np.clip(0.12 * dist, 0.3, 0.8))
        box = Box(x=dist * math.sin(bearing), z=dist * math.cos(bearing),
                  width=float(rng.uniform(0.6, 1.3) * size),
                  depth=float(rng.uniform(0.6, 1.3) * size),
                  height=float(rng.uniform(0.25, 0.8)), yaw_deg=float(rng.uniform(0, 90)))
        if not overlaps_any(box, boxes):
            boxes.append(box)
    return boxes


def head_sequence(n_frames: int, seed: int, motion: HeadMotion, floor: str = 'random',
                  focal_px: float = 600.0, baseline_over_height: float = 0.2,
                  n_boxes: int = 10, width: int = 640, height: int = 480,
                  noise_std: float = 1.0, first_frame: int = 0,
                  supersample: int = 2) -> Iterator[StereoFrame]:
    """Render an active head panning, tilting and verging over a floor with boxes.

    The head stands at a random place on the floor texture; boxes stand around it in all
    directions (:func:`ring_of_boxes`), fixed in the world, so they pass through the view as
    the head pans. Each frame's :attr:`StereoFrame.homography` is its true floor homography
    (it changes with tilt and vergence; pan about the vertical leaves it unchanged, but moves
    the texture and the boxes through the images).

    Args:
        n_frames: Number of frames (>= 1).
        seed: Seed of the head's place, the boxes, the phase and the pixel noise.
        motion: The head's motion.
        floor: Floor texture kind.
        focal_px: Focal length, pixels.
        baseline_over_height: Baseline over camera height.
        n_boxes: Boxes around the head.
        width: Image width in pixels.
        height: Image height in pixels.
        noise_std: Pixel noise, grey levels.
        first_frame: Index of the first frame rendered (to render a sequence in parts).
        supersample: Rays per pixel along each axis.

    Yields:
        ``n_frames`` :class:`StereoFrame` values, rendered lazily.

    Raises:
        ValueError: If ``n_frames < 1``.

    """
    if n_frames < 1:
        raise ValueError(f'n_frames must be >= 1, got {n_frames}')
    rng = np.random.default_rng((int(seed), 9090))
    world_boxes = ring_of_boxes(rng, n_boxes)
    origin = rng.uniform(0, 100, 2)
    heading0 = float(rng.uniform(0, 360))
    phase = float(rng.uniform(0, 2 * math.pi))
    for i in range(first_frame, first_frame + n_frames):
        pan, tilt, vergence = motion.angles(i, phase)
        setup = CameraSetup(focal_px, baseline_over_height, tilt, vergence, width, height)
        pose = HeadPose(float(origin[0]), float(origin[1]), heading0 + pan)
        yield render_stereo(setup, level_boxes(world_boxes, 0.0, 0.0, pan), floor=floor,
                            seed=int(seed), noise_std=noise_std, head_pose=pose,
                            noise_seed=int(seed) * 100003 + i, supersample=supersample)
