"""Random rendered scenes and sequences with ground truth, drawn within the default prior.

:func:`random_scene` draws one stereo pair (set-up, floor kind, boxes in view, background);
:func:`scene_sequence` renders a head walking over the floor past fixed boxes. The same seed
gives the same frames.
"""

from __future__ import annotations

import math
from typing import Iterator, Sequence

from domplane_ros.config import PriorConfig
from domplane_ros.sim.model import (BACKGROUNDS, Box, CameraSetup, footprint_radius, HeadPose,
                                    level_boxes, level_from_left, overlaps_any, StereoFrame)
from domplane_ros.sim.render import BOX, FLOOR, left_labels, render_stereo
from domplane_ros.sim.textures import FLOOR_KINDS
import numpy as np

SETUP_RANGES = {
    'focal_px': (400.0, 900.0),
    'baseline_over_height': (0.05, 0.4),
    'tilt_deg': (10.0, 50.0),
    'vergence_deg': (-2.0, 4.0),
}
# The prior that covers every drawn set-up (equal to the default prior).
RENDERED_PRIOR = PriorConfig(**SETUP_RANGES)


def random_setup(rng: np.random.Generator, width: int = 640, height: int = 480) -> CameraSetup:
    """Draw a camera set-up uniformly within :data:`SETUP_RANGES` (the default prior)."""
    return CameraSetup(**{name: float(rng.uniform(lo, hi))
                          for name, (lo, hi) in SETUP_RANGES.items()},
                       width=width, height=height)


def _obstacle_fraction(setup: CameraSetup, boxes: Sequence[Box]) -> tuple[float, float]:
    """Return (obstacle / (floor + obstacle) pixels, floor fraction) from a coarse render."""
    factor = max(1, setup.width // 80)
    small = CameraSetup(setup.focal_px / factor, setup.baseline_over_height, setup.tilt_deg,
                        setup.vergence_deg, max(8, setup.width // factor),
                        max(8, setup.height // factor))
    label = left_labels(small, boxes)
    floor = np.count_nonzero(label == FLOOR)
    obstacle = np.count_nonzero(label == BOX)
    return obstacle / max(1, floor + obstacle), floor / label.size


def random_boxes(rng: np.random.Generator, setup: CameraSetup, count: int,
                 max_obstacle_fraction: float = 0.25, max_distance: float = 9.0
                 ) -> list[Box]:
    """Place up to ``count`` non-overlapping boxes on floor points seen by the left camera.

    Boxes whose addition makes the obstacles cover more than ``max_obstacle_fraction`` of the
    floor-or-obstacle pixels are dropped, so the floor stays the dominant plane.

    Args:
        rng: Random generator.
        setup: The stereo head.
        count: Number of boxes wanted.
        max_obstacle_fraction: Largest obstacle share of floor-or-obstacle pixels.
        max_distance: Farthest box centre from the head.

    Returns:
        The boxes in the level frame (at least one if the floor is visible at all).

    """
    r_lc = level_from_left(setup.tilt_deg)
    k_inv = np.linalg.inv(setup.intrinsics())
    boxes: list[Box] = []
    for _ in range(40 * max(1, count)):
        if len(boxes) >= count:
            break
        px = rng.uniform(0.08, 0.92) * (setup.width - 1)
        py = rng.uniform(0.3, 0.97) * (setup.height - 1)
        ray = r_lc @ (k_inv @ np.array([px, py, 1.0]))
        if ray[1] <= 1e-3:
            continue
        point = ray / ray[1]
        if not 1.2 < point[2] < max_distance:
            continue
        size = float(np.clip(0.15 * point[2], 0.3, 1.0))
        box = Box(x=float(point[0]), z=float(point[2]),
                  width=float(rng.uniform(0.6, 1.3) * size),
                  depth=float(rng.uniform(0.6, 1.3) * size),
                  height=float(rng.uniform(0.25, 0.9)), yaw_deg=float(rng.uniform(-40, 40)))
        if box.z - footprint_radius(box) < 0.8 or overlaps_any(box, boxes):
            continue
        fraction, _ = _obstacle_fraction(setup, boxes + [box])
        if fraction > max_obstacle_fraction:
            continue
        boxes.append(box)
    return boxes


def random_scene(seed: int, width: int = 640, height: int = 480, floor: str | None = None,
                 n_boxes: int | tuple[int, int] = (1, 5), gain: float | None = 1.0,
                 offset: float | None = 0.0, noise_std: float = 1.0,
                 background: str | None = None, setup: CameraSetup | None = None,
                 blur_sigma: float = 0.5, box_contrast: float = 1.0) -> StereoFrame:
    """Render a random scene: set-up within :data:`SETUP_RANGES`, 1-5 boxes in view.

    Args:
        seed: Seed of every random choice; the same seed gives the same frame.
        width: Image width in pixels.
        height: Image height in pixels.
        floor: Floor kind (one of :data:`ALL_FLOOR_KINDS`), or None for a random one of
            :data:`FLOOR_KINDS`.
        n_boxes: Number of boxes, or an inclusive ``(min, max)`` range to draw from.
        gain: Right camera gain, or None to draw one in [0.8, 1.25].
        offset: Right camera offset in grey levels, or None to draw one in [-20, 20].
        noise_std: Pixel noise standard deviation in grey levels.
        background: ``'horizon'``, ``'wall'`` or None for a random one.
        setup: A fixed camera set-up instead of a random one.
        blur_sigma: Gaussian blur of both images in pixels.
        box_contrast: Contrast of the box face texture (1 as drawn, 0 plain faces; see
            :func:`~domplane_ros.sim.render.render_stereo`). Every other choice is the same.

    Returns:
        The rendered :class:`StereoFrame`.

    """
    rng = np.random.default_rng((int(seed), 4242))
    setup = setup or random_setup(rng, width, height)
    floor = floor or FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    background = background or BACKGROUNDS[int(rng.integers(len(BACKGROUNDS)))]
    if isinstance(n_boxes, tuple):
        n_boxes = int(rng.integers(n_boxes[0], n_boxes[1] + 1))
    boxes = random_boxes(rng, setup, n_boxes)
    pose = HeadPose(float(rng.uniform(0, 100)), float(rng.uniform(0, 100)),
                    float(rng.uniform(0, 360)))
    gain = float(rng.uniform(0.8, 1.25)) if gain is None else gain
    offset = float(rng.uniform(-20, 20)) if offset is None else offset
    return render_stereo(setup, boxes, floor=floor, seed=int(seed), gain=gain, offset=offset,
                         noise_std=noise_std, head_pose=pose, background=background,
                         wall_distance=float(rng.uniform(8, 20)), blur_sigma=blur_sigma,
                         box_contrast=box_contrast)


def indoor_scene(seed: int, width: int = 640, height: int = 480,
                 baseline_over_height: float = 0.075, focal_px: float = 525.0
                 ) -> StereoFrame:
    """Render a small-baseline indoor head: a wall 3-6 m ahead, 2-4 boxes (furniture) before it.

    The default is a 7.5 cm baseline at 1 m height, focal 525 px, no vergence, tilt drawn in
    10-25 degrees, a random floor kind. Every pixel that is not floor is wall or furniture.

    Args:
        seed: Seed of every random choice.
        width: Image width in pixels.
        height: Image height in pixels.
        baseline_over_height: Stereo baseline over camera height.
        focal_px: Focal length in pixels.

    Returns:
        The rendered :class:`StereoFrame` (``background='wall'``).

    """
    rng = np.random.default_rng((int(seed), 7575))
    setup = CameraSetup(focal_px, baseline_over_height, float(rng.uniform(10.0, 25.0)), 0.0,
                        width, height)
    wall = float(rng.uniform(3.0, 6.0))
    boxes = random_boxes(rng, setup, int(rng.integers(2, 5)), max_distance=wall - 0.6)
    floor = FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    return render_stereo(setup, boxes, floor=floor, seed=int(seed), background='wall',
                         wall_distance=wall, noise_std=1.0)


def scene_sequence(n_frames: int, seed: int, width: int = 640, height: int = 480,
                   floor: str | None = None, n_boxes: int = 3, step: float = 0.04,
                   yaw_rate_deg: float = 0.6, tilt_jitter_deg: float = 1.0,
                   vergence_jitter_deg: float = 0.3, gain: float = 1.0, offset: float = 0.0,
                   noise_std: float = 1.0, background: str = 'horizon',
                   setup: CameraSetup | None = None, blur_sigma: float = 0.5,
                   only: Sequence[int] | None = None) -> list[StereoFrame]:
    """Render a short sequence of a head walking over the floor past fixed boxes.

    The head moves ``step`` per frame along its heading, which turns slowly (a sine of
    amplitude ``yaw_rate_deg * n_frames / 4`` degrees); tilt and vergence wobble smoothly by up
    to the given jitter, so the true homography changes from frame to frame only through them.
    Boxes are fixed in the world and move through the level frame.

    Args:
        n_frames: Number of frames (>= 1).
        seed: Seed of every random choice.
        width: Image width in pixels.
        height: Image height in pixels.
        floor: Floor kind, or None for a random one.
        n_boxes: Number of boxes placed ahead of the start pose.
        step: Forward motion per frame (camera height = 1).
        yaw_rate_deg: Scale of the heading change per frame, degrees.
        tilt_jitter_deg: Amplitude of the tilt wobble, degrees.
        vergence_jitter_deg: Amplitude of the vergence wobble, degrees.
        gain: Right camera gain.
        offset: Right camera offset in grey levels.
        noise_std: Pixel noise standard deviation in grey levels.
        background: ``'horizon'`` or ``'wall'``.
        setup: The nominal set-up (default: a random one).
        blur_sigma: Gaussian blur of both images in pixels.
        only: Render only these frame indices (each as in the whole sequence), in order.

    Returns:
        ``n_frames`` :class:`StereoFrame` values (those of ``only`` if given).

    Raises:
        ValueError: If ``n_frames < 1`` or an index of ``only`` is not below it.

    """
    if n_frames < 1:
        raise ValueError(f'n_frames must be >= 1, got {n_frames}')
    wanted = None if only is None else [int(i) for i in only]
    if wanted is not None and not all(0 <= i < n_frames for i in wanted):
        raise ValueError(f'only must hold indices in [0, {n_frames}), got {only!r}')
    rng = np.random.default_rng((int(seed), 777))
    nominal = _inside_prior(setup or random_setup(rng, width, height), tilt_jitter_deg,
                            vergence_jitter_deg)
    floor = floor or FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    world_boxes = _boxes_ahead(rng, nominal, n_boxes, step * n_frames)
    origin = np.array([rng.uniform(0, 100), rng.uniform(0, 100)])
    heading0 = float(rng.uniform(0, 360))
    phases = rng.uniform(0, 2 * np.pi, 3)
    frames = {}
    for i, (x, z, yaw) in enumerate(_walk(n_frames, step, yaw_rate_deg, phases[2])):
        if wanted is not None and i not in wanted:
            continue
        wobble = (tilt_jitter_deg * math.sin(_phase(i, n_frames) + phases[0]),
                  vergence_jitter_deg * math.sin(_phase(i, n_frames) + phases[1]))
        frames[i] = render_stereo(
            _wobbled(nominal, *wobble), level_boxes(world_boxes, x, z, yaw), floor=floor,
            seed=int(seed), gain=gain, offset=offset, noise_std=noise_std,
            head_pose=_texture_pose(origin, heading0, x, z, yaw), background=background,
            blur_sigma=blur_sigma, noise_seed=int(seed) * 100003 + i)
    return [frames[i] for i in (range(n_frames) if wanted is None else wanted)]


def _phase(index: int, n_frames: int) -> float:
    """Return the phase of the wobble and of the turn at a frame, radians."""
    return 2 * np.pi * index / max(n_frames, 8)


def _wobbled(nominal: CameraSetup, tilt_offset_deg: float,
             vergence_offset_deg: float) -> CameraSetup:
    """Return ``nominal`` with its tilt and vergence moved by the given offsets."""
    return CameraSetup(nominal.focal_px, nominal.baseline_over_height,
                       nominal.tilt_deg + tilt_offset_deg,
                       nominal.vergence_deg + vergence_offset_deg, nominal.width, nominal.height)


def _inside_prior(nominal: CameraSetup, tilt_jitter_deg: float,
                  vergence_jitter_deg: float) -> CameraSetup:
    """Return ``nominal`` moved so that its wobble stays inside :data:`SETUP_RANGES`."""
    lo_t, hi_t = SETUP_RANGES['tilt_deg']
    lo_v, hi_v = SETUP_RANGES['vergence_deg']
    return CameraSetup(nominal.focal_px, nominal.baseline_over_height,
                       float(np.clip(nominal.tilt_deg, lo_t + tilt_jitter_deg,
                                     hi_t - tilt_jitter_deg)),
                       float(np.clip(nominal.vergence_deg, lo_v + vergence_jitter_deg,
                                     hi_v - vergence_jitter_deg)),
                       nominal.width, nominal.height)


def _boxes_ahead(rng: np.random.Generator, nominal: CameraSetup, n_boxes: int,
                 travel: float) -> list[Box]:
    """Return boxes placed for the head half-way along its path, beyond the path's end."""
    world_boxes = [Box(b.x, b.z + 0.5 * travel, b.width, b.depth, b.height, b.yaw_deg)
                   for b in random_boxes(rng, nominal, n_boxes)]
    return [b for b in world_boxes if b.z - footprint_radius(b) > travel + 0.8]


def _walk(n_frames: int, step: float, yaw_rate_deg: float,
          yaw_phase: float) -> Iterator[tuple[float, float, float]]:
    """Yield the head's ``(x, z, yaw_deg)`` per frame, relative to the start's level frame."""
    x, z, yaw = 0.0, 0.0, 0.0
    for i in range(n_frames):
        yield x, z, yaw
        yaw_step = yaw_rate_deg * math.cos(_phase(i, n_frames) + yaw_phase)
        x += step * math.sin(math.radians(yaw))
        z += step * math.cos(math.radians(yaw))
        yaw += yaw_step


def _texture_pose(origin: np.ndarray, heading0_deg: float, x: float, z: float,
                  yaw_deg: float) -> HeadPose:
    """Return the pose on the floor texture of a head at ``(x, z, yaw)`` from the start."""
    h0 = math.radians(heading0_deg)
    return HeadPose(float(origin[0] + x * math.cos(h0) + z * math.sin(h0)),
                    float(origin[1] - x * math.sin(h0) + z * math.cos(h0)),
                    heading0_deg + yaw_deg)


# Where the base of the box of :func:`ahead_scene` lies: a fraction of the image height,
# drawn in this range (the bottom third of the view; the lower, the closer the box).
AHEAD_BASE_ROWS = (0.8, 0.97)


def _base_distance(setup: CameraSetup, row_fraction: float) -> float:
    """Return the floor distance (camera height = 1) seen at a row of the image's centre."""
    below = math.radians(setup.tilt_deg) + math.atan(
        (row_fraction - 0.5) * setup.height / setup.focal_px)
    return 1.0 / math.tan(below)


def ahead_scene(seed: int, width: int = 640, height: int = 480, remaining: float = 0.0,
                base_row: float | None = None) -> StereoFrame:
    """Render a wide box standing right in front of the head, filling much of the near field.

    The set-up and floor are drawn as in :func:`random_scene` (within the default prior); one
    box, 50-90 % of the view wide, 0.3-0.9 camera heights high, stands on the floor with its
    front face where the image centre's column sees the floor at ``base_row`` (drawn in
    :data:`AHEAD_BASE_ROWS`), so its face and top fill a large part of the bottom third of
    the view (20-45 % on tuning seeds 0-5) above a strip of floor: the obstacle in front of
    a robot that has to stop. ``remaining`` moves the head back by that distance (camera
    heights) along the floor, box and texture fixed in the world: the frames of an approach
    (:func:`approach_sequence`; the background wall, when drawn, keeps its distance).

    Args:
        seed: Seed of every random choice.
        width: Image width in pixels.
        height: Image height in pixels.
        remaining: Distance still to go to the final pose (camera height = 1, >= 0).
        base_row: Row of the box's base at the final pose, a fraction of the image height
            (None: drawn).

    Returns:
        The rendered :class:`StereoFrame`.

    """
    rng = np.random.default_rng((int(seed), 9191))
    setup = random_setup(rng, width, height)
    floor = FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    background = BACKGROUNDS[int(rng.integers(len(BACKGROUNDS)))]
    row = float(rng.uniform(*AHEAD_BASE_ROWS))
    distance = _base_distance(setup, row if base_row is None else base_row)
    box_width = float(rng.uniform(0.5, 0.9)) * setup.width / setup.focal_px * distance
    depth = float(rng.uniform(0.4, 1.0))
    box = Box(x=float(rng.uniform(-0.2, 0.2)) * box_width,
              z=distance + 0.5 * depth + float(remaining), width=box_width, depth=depth,
              height=float(rng.uniform(0.3, 0.9)), yaw_deg=float(rng.uniform(-10.0, 10.0)))
    pose = HeadPose(float(rng.uniform(0, 100)), float(rng.uniform(0, 100)) - float(remaining),
                    0.0)
    return render_stereo(setup, [box], floor=floor, seed=int(seed), head_pose=pose,
                         background=background, wall_distance=float(rng.uniform(8, 20)),
                         noise_seed=int(seed) * 100003 + int(round(1000 * remaining)))


def approach_sequence(n_frames: int, seed: int, travel: float = 2.0,
                      width: int = 640, height: int = 480) -> list[StereoFrame]:
    """Render a head driving straight at the box of :func:`ahead_scene` over ``travel``.

    Frame ``i`` is :func:`ahead_scene` with ``remaining = travel (1 - i / (n_frames - 1))``:
    the box's base moves from far up the view down to the bottom third of the last frame.

    Raises:
        ValueError: If ``n_frames < 2`` or ``travel`` is negative.

    """
    if n_frames < 2 or travel < 0:
        raise ValueError(f'need n_frames >= 2 and travel >= 0, got {n_frames}, {travel}')
    return [ahead_scene(seed, width, height, travel * (1.0 - i / (n_frames - 1)))
            for i in range(n_frames)]
