"""The parameter table: every tunable's name, default, type, range and description.

:data:`PARAMETERS` is the one table the node declares its ROS parameters from (descriptors
with ranges), the config dataclasses of :mod:`domplane_ros.config` validate against, and the
parameter table of docs/PARAMETERS.md and the default params file are generated from.
"""

from __future__ import annotations

from dataclasses import dataclass
import difflib
import math
from typing import Any, Mapping

from domplane_ros.errors import ConfigError, wire_repr

POTENTIAL_NAMES = ('least_squares', 'truncated_quadratic', 'huber', 'geman_mcclure')
FEATURE_KINDS = ('points', 'lines', 'both')
IMAGE_TRANSPORTS = ('raw', 'compressed')
PLANE_KINDS = ('ground', 'any')


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter: name, default, type and admissible values.

    ``kind`` is one of ``'float'``, ``'int'``, ``'bool'``, ``'str'``, ``'range'`` (two
    floats ``[min, max]`` with ``min <= max``), ``'floats'`` (a list of floats whose allowed
    lengths are given by ``lengths``).
    """

    name: str
    default: Any
    kind: str
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    lengths: tuple[int, ...] | None = None


PARAMETERS: tuple[ParamSpec, ...] = (
    # Features.
    ParamSpec('features.max_points', 400, 'int',
              'Maximum number of corner points detected per image.', 8, 5000),
    ParamSpec('features.quality_level', 0.01, 'float',
              'Corner quality relative to the strongest corner (cv2.goodFeaturesToTrack).',
              1e-4, 1.0),
    ParamSpec('features.min_distance_px', 8.0, 'float',
              'Minimum distance between two detected corners, in pixels.', 1.0, 200.0),
    ParamSpec('features.block_size', 5, 'int',
              'Neighbourhood size of the corner detector, in full-resolution pixels (on a '
              'pyramid level the odd size nearest its extent there, at least 3).', 3, 31),
    ParamSpec('features.grid_rows', 4, 'int',
              'Rows of the detection grid; each cell keeps its share of the corners.', 1, 32),
    ParamSpec('features.grid_cols', 4, 'int',
              'Columns of the detection grid.', 1, 32),
    ParamSpec('features.roi', [0.0, 0.0, 1.0, 1.0], 'floats',
              'Region of interest in the left image as fractions [x0, y0, x1, y1] '
              '(0..1, x0 < x1, y0 < y1).', 0.0, 1.0, lengths=(4,)),
    ParamSpec('features.max_width', 1280, 'int',
              'Working resolution: corners and lines are detected, corners tracked and the mask '
              'computed on the Gaussian pyramid level (halvings) whose width is at most this; '
              'the plane is estimated in full pixels. features.*, tracking.* and mask.* pixel '
              'sizes are at that level (features.block_size: full pixels). 0: no width limit.',
              0, 100000),
    ParamSpec('features.max_megapixels', 0.6, 'float',
              'Working resolution by size: the level is also at most this many million pixels '
              '(0.6: 640x480 and KITTI at full resolution, 1280x720 on 640x360, 3840x2160 on '
              '960x540). 0: no size limit.', 0.0, 1000.0),
    ParamSpec('features.kind', 'points', 'str',
              'Features the plane is estimated from: points (corners), lines (straight line '
              'segments) or both.', choices=FEATURE_KINDS),
    ParamSpec('features.max_lines', 150, 'int',
              'Maximum number of line segments detected per image (lines and both).', 4, 2000),
    ParamSpec('features.min_line_length_px', 25.0, 'float',
              'Line segments shorter than this are dropped, in pixels.', 4.0, 1000.0),
    ParamSpec('features.line_scale', 0.8, 'float',
              'Image scale at which the line segment detector runs (LSD scale; smaller is '
              'faster and less precise).', 0.2, 1.0),
    # Estimator.
    ParamSpec('estimator.potential', 'truncated_quadratic', 'str',
              'Robust potential: least_squares, truncated_quadratic, huber or '
              'geman_mcclure (graduated non-convexity).', choices=POTENTIAL_NAMES),
    ParamSpec('estimator.lambda_weight', 0.8, 'float',
              'Interpolation weight lambda in (0, 1): how far an auxiliary point moves from '
              'the prediction toward its closest point.', 0.01, 0.99),
    ParamSpec('estimator.threshold_px', 3.0, 'float',
              'Robust threshold (truncation, Huber corner, Geman-McClure scale) in pixels; '
              'points farther than this from every partner are off the plane.', 0.1, 200.0),
    ParamSpec('estimator.line_weight', 3.0, 'float',
              'Weight of a line segment relative to a point in the joint energy (features.kind '
              'both).', 0.01, 100.0),
    ParamSpec('estimator.gnc_start_px', 24.0, 'float',
              'Initial (wide) scale of graduated non-convexity, pixels: always for '
              'geman_mcclure; for truncated_quadratic only from a warm start that looks far '
              '(support near chance, or the plain run refused), and only if at least twice '
              'estimator.threshold_px.', 0.1, 500.0),
    ParamSpec('estimator.gnc_factor', 0.5, 'float',
              'Factor by which the graduated scale shrinks per stage.', 0.05, 0.95),
    ParamSpec('estimator.max_iterations', 60, 'int',
              'Iteration cap of one two-step run (per GNC stage).', 1, 10000),
    ParamSpec('estimator.tolerance_px', 0.05, 'float',
              'Convergence when no prediction moves more than this, in pixels.', 1e-6, 10.0),
    ParamSpec('estimator.energy_tolerance', 1e-7, 'float',
              'Convergence when the relative energy decrease falls below this.', 0.0, 1.0),
    ParamSpec('estimator.euclidean_refinement', True, 'bool',
              'After convergence, fit H to the inliers and their closest points by '
              'Gauss-Newton on the transfer error (sub-pixel accuracy).'),
    ParamSpec('estimator.min_inliers', 12, 'int',
              'Fewer inliers than this is a failed estimate.', 4, 100000),
    # Prior.
    ParamSpec('prior.focal_px', [400.0, 900.0], 'range',
              'Focal length range [min, max] in pixels.', 1.0, 1e5),
    ParamSpec('prior.baseline_over_height', [0.05, 0.4], 'range',
              'Stereo baseline divided by camera height above the plane, [min, max].',
              1e-4, 100.0),
    ParamSpec('prior.tilt_deg', [10.0, 50.0], 'range',
              'Camera tilt toward the plane [min, max] in degrees (positive looks down).',
              -89.0, 89.0),
    ParamSpec('prior.vergence_deg', [-2.0, 4.0], 'range',
              "Vergence: the right camera's yaw toward the left camera, [min, max] degrees.",
              -45.0, 45.0),
    ParamSpec('prior.principal_point_px', [], 'floats',
              'Principal point [cx, cy] of both cameras in pixels; empty: the image centre '
              '(set from camera_info when camera_info.topic is given).', 0.0, 1e5,
              lengths=(0, 2)),
    ParamSpec('prior.samples', 5, 'int',
              'Samples per prior range for the candidate grid (samples^4 candidates).', 1, 12),
    ParamSpec('prior.refine_best', 6, 'int',
              'Candidates (best by screening energy) that get the full iteration.', 1, 100),
    ParamSpec('prior.screen_threshold_px', 12.0, 'float',
              'Truncation of the cheap closest-point screening energy, in pixels.', 0.5, 500.0),
    ParamSpec('initial_homography', [], 'floats',
              'Optional initial homography, 9 values row-major, left pixel to right pixel '
              '(finite, invertible: condition number at most 1e6 with pixels scaled by '
              '1/1000); empty means search the prior.', lengths=(0, 9)),
    # Verification (every plane is verified before it is published).
    ParamSpec('verification.min_score', 0.22, 'float',
              'Least verification score for a plane to be published: the share of the '
              'textured image that the plane explains and the same plane moved 3 working '
              'pixels sideways or 1.5 up or down does not (12 and 6 px at 640 x 480); the '
              'confidence is 0.5 there, 0 at min_score - 0.1 and 1 at min_score + 0.1.',
              0.11, 0.89),
    ParamSpec('verification.plane', 'ground', 'str',
              'Which dominant plane to look for: ground (the floor or road below the head: its '
              'disparity must grow toward the image bottom, the plane must explain the bottom '
              'of the image with nothing beyond it, and swapped cameras are detected) or any '
              '(a board, a wall, a table top: those ground checks are off, planes leaning '
              'toward the head are searched too, and swapped cameras cannot be detected).',
              choices=PLANE_KINDS),
    ParamSpec('verification.scale', 0.25, 'float',
              'Image scale at which planes are verified (the working width is kept within '
              '64..480 px); the scores were calibrated at 0.25.', 0.05, 1.0),
    ParamSpec('verification.drop_ratio', 0.5, 'float',
              "A locked plane whose score falls below this fraction of the lock's median "
              'score is refused and the search starts in the same pair (a cut, a saccade).',
              0.0, 1.0),
    ParamSpec('verification.challenge_period', 10, 'int',
              'Every this many locked pairs the best plane of the coarse photometric alignment '
              'challenges the lock and replaces it if it explains clearly more (0: never).',
              0, 10000),
    ParamSpec('verification.coarse_candidates', True, 'bool',
              "Add the coarse photometric alignment's planes (DIS optical flow at "
              'verification.coarse_width_px, no camera model) to the prior search: covers '
              'rough rigs (roll, vertical offset, focal mismatch) the prior grid misses.'),
    ParamSpec('verification.coarse_width_px', 320, 'int',
              'Image width of the coarse photometric alignment, pixels.', 64, 2048),
    ParamSpec('verification.max_ground_roll_deg', 10.0, 'float',
              'Ground mode: largest roll of the ground about the optical axis, degrees (its '
              "disparity must grow down the image within it, the right camera's own roll "
              'taken out): a plane through walls or panels at several depths is refused. A head '
              "rolled as a whole counts once, the left camera's roll against the baseline "
              'about twice (both cameras rolled alike too); raise it for a rolling head; 90 '
              'switches the check off.',
              1.0, 90.0),
    ParamSpec('verification.prior_slope_margin', 0.5, 'float',
              "Ground mode: how far the ground's disparity slope (its growth per image row, "
              "(b/h) cos(tilt)) may lie below the least that the prior's baseline_over_height and "
              'tilt_deg give, as a fraction: a plane whose slope is below that least / (1 + '
              'margin) for every focal length of the prior is refused (a plane through distant '
              'structure, almost at infinity, has a slope near 0; the default prior refuses '
              'below 0.021 px per row). Narrow the prior to make it bite; no upper bound; 100 is '
              'off.',
              0.0, 100.0),
    ParamSpec('verification.max_near_obstacle', 0.5, 'float',
              "Ground mode, new planes only (a search's winner, a challenger; never a held "
              "lock's warm plane): the largest share of the measured pixels (plane or "
              "obstacle) in the bottom third of the view (of features.roi) that the plane's own "
              'parallax mask may mark obstacle: under a plane through distant structure the '
              'near ground shows parallax. Decides only where at least 2 % of that band is '
              'measured, and refuses only where no ground is seen below the obstacle (the '
              'lowest measured pixel is obstacle in more than 30 % of the columns): an '
              'obstacle standing on the ground has ground in front of it. 1 switches the '
              'check off.',
              0.0, 1.0),
    ParamSpec('verification.covisible', True, 'bool',
              'Ground mode: divide the scores by the textured pixels that the plane maps '
              'inside the right image (both cameras see them) instead of all textured pixels: '
              'a vertical offset, a roll or a focal mismatch between the cameras moves the '
              'near ground out of the right image, and counted it scores against the true '
              'plane. A plane mapping less than half its textured pixels inside is refused, '
              'so a score rises at most twice. false: every textured pixel counts, as before '
              'session 20 (planes any always count them all).'),
    # Mask.
    ParamSpec('mask.scale', 0.5, 'float',
              'Resolution of the dense mask computation relative to the image.', 0.1, 1.0),
    ParamSpec('mask.window_px', 5, 'int',
              'Side of the window of the residual parallax estimate and the zero-shift '
              'correlation, pixels at mask scale.', 3, 31),
    ParamSpec('mask.ncc_threshold', 0.7, 'float',
              'Zero-shift normalised correlation (right image warped by the plane) a window '
              'needs for its residual parallax to be measured; below 0.5 a textured window '
              'is off the plane.', 0.5, 1.0),
    ParamSpec('mask.min_texture', 3.0, 'float',
              'Local grey-level standard deviation below which a pixel is unknown.', 0.0, 255.0),
    ParamSpec('mask.morph_px', 5, 'int',
              'Size of the morphological clean-up, pixels at mask scale (0 disables).', 0, 51),
    ParamSpec('mask.parallax_threshold_px', 1.0, 'float',
              'Residual parallax after the plane warp (full-resolution pixels) below which a '
              'pixel is plane and at or above which it is an obstacle.', 0.1, 50.0),
    ParamSpec('mask.min_obstacle_height', 0.1, 'float',
              'Smallest obstacle to detect, as its height over the camera height: pixels '
              'where such an obstacle would show less than mask.parallax_threshold_px '
              '(far away, small baseline, at or above the horizon) are unknown.', 0.01, 0.9),
    # Pipeline.
    ParamSpec('pipeline.max_energy_ratio', 4.0, 'float',
              'A warm-started estimate whose energy per point exceeds this multiple of the '
              "last good one is rejected (the 'tracking' state, then the prior search).",
              1.0, 1e6),
    ParamSpec('pipeline.warm_gnc_start_px', 6.0, 'float',
              'Geman-McClure only: initial GNC scale when warm-starting from the last frame '
              '(the wide estimator.gnc_start_px is used after a re-initialisation).',
              0.1, 500.0),
    ParamSpec('pipeline.check_prior_bounds', True, 'bool',
              'Reject homographies that move the image corners outside what the prior allows.'),
    ParamSpec('pipeline.min_inlier_spread', 0.02, 'float',
              'Smallest convex-hull area of the inliers, as a fraction of the features.roi '
              'area; collinear inliers or inliers in one small patch leave the homography '
              'unconstrained and fail the frame (0 disables).', 0.0, 1.0),
    ParamSpec('pipeline.max_clipped_fraction', 0.6, 'float',
              'A frame with more than this fraction of black (grey <= 2) or saturated '
              '(grey >= 253) pixels is refused (1 disables; images over 0.5 MP are counted '
              'on a regular grid of about 0.5 MP).', 0.01, 1.0),
    ParamSpec('pipeline.max_stamp_jump_s', 10.0, 'float',
              'A pair stamped more than this many seconds after the pair the cameras delivered '
              'before it drops the warm start (as a stamp going backwards does); pairs the node '
              'dropped while busy do not make a gap.', 0.001, 1e6),
    ParamSpec('pipeline.max_tracking_frames', 2, 'int',
              "Frames in the 'tracking' state (the last homography carried forward through "
              "the cameras' tracked motion) after a failed or suspicious estimate before the "
              'prior search starts.', 0, 100),
    ParamSpec('pipeline.search_candidates_per_frame', 6, 'int',
              'Prior candidates refined per frame during a search; with prior.refine_best or '
              'more the whole search fits in one pair, else it is spread over frames, keeping '
              'the best so far.',
              1, 100),
    ParamSpec('pipeline.fast_joint_velocity', 0.5, 'float',
              'Head joint speed (largest absolute velocity in the joint states, rad/s) above '
              'which a big change is expected: no energy-jump check, and a wide warm-start '
              'basin when tracking gives no prediction.', 0.0, 1e3),
    # Temporal prediction.
    ParamSpec('tracking.enabled', True, 'bool',
              "Warm-start from the last homography moved through both cameras' tracked "
              'frame-to-frame motion (H_t ~ M_right H_{t-1} M_left^-1); false warm-starts '
              'from the last homography as is.'),
    ParamSpec('tracking.max_points', 150, 'int',
              "Most corners tracked per camera (the previous frame's first, i.e. strongest "
              'per grid cell).',
              8, 5000),
    ParamSpec('tracking.window_px', 11, 'int',
              'Side of the pyramidal Lucas-Kanade window, pixels at the working resolution '
              '(features.max_width).', 5, 101),
    ParamSpec('tracking.pyramid_levels', 3, 'int',
              'Pyramid levels of the Lucas-Kanade tracker above full resolution.', 0, 8),
    ParamSpec('tracking.forward_backward_px', 0.0, 'float',
              'Largest forward-backward round-trip error of a kept track, pixels; 0: no '
              'tracking back (half the tracker cost; the robust motion fit rejects bad tracks, '
              'and the prediction is only the warm start: the same errors and locks in '
              'evaluate_head, docs/speed.md).', 0.0, 50.0),
    ParamSpec('tracking.min_tracks', 20, 'int',
              'Fewer kept tracks than this in a camera: no prediction this frame.', 4, 10000),
    ParamSpec('tracking.min_inlier_ratio', 0.5, 'float',
              "Share of a camera's tracks that must fit its motion homography (MAGSAC++).",
              0.0, 1.0),
    ParamSpec('tracking.threshold_px', 2.0, 'float',
              'Inlier threshold of the robust camera-motion fit, pixels.', 0.1, 50.0),
    ParamSpec('tracking.reuse_pairs', 0, 'int',
              'Speed for accuracy: while locked, pairs in a row whose corners are the '
              "previous pairs' corners tracked into them (forward Lucas-Kanade from the pair "
              'they were detected in) instead of detected afresh; then a pair detects again '
              '(also when under 70 % of the corners survive). Saves about a quarter of a '
              'warm pair; costs accuracy on tiled and planked floors (docs/speed.md). '
              '0: detect every pair, and fit the motion to tracks of the first '
              'tracking.max_points.', 0, 1000),
    # Optional head input.
    ParamSpec('head.joint_states_topic', '', 'str',
              'sensor_msgs/JointState topic of the head (e.g. head/joint_states); empty: no '
              'joint input. Fast joints hint at a big change (see '
              'pipeline.fast_joint_velocity).'),
    ParamSpec('head.max_age_s', 0.5, 'float',
              'Joint states older than this (receive time) are ignored, seconds.', 0.0, 60.0),
    ParamSpec('head.max_joint_velocity', 20.0, 'float',
              'Joint states whose largest absolute velocity exceeds this (rad/s) are '
              'implausible: flagged in the log and /diagnostics and not used as a hint.',
              0.01, 1e4),
    # Image decoding.
    ParamSpec('image.mono16_bits', 16, 'int',
              'Significant bits of mono16 images: 12 for a 12-bit sensor whose values are '
              'below 4096, 10 for one below 1024. Decoding keeps the top 8 of them (values '
              'above the range saturate); 16 keeps the high byte, as cv_bridge does. mono16 '
              'pairs whose brightest grey uses under 1/16 of this range are reported (log, '
              '/diagnostics image warning, replay note). mono8 and colour are not affected.',
              8, 16),
    # Synchroniser and transport.
    ParamSpec('sync.slop_s', 0.01, 'float',
              'Largest left/right header stamp difference of a pair, in seconds.', 1e-6, 10.0),
    ParamSpec('sync.queue_size', 5, 'int',
              'Per-camera queue of the synchroniser; the oldest frame is dropped when full.',
              1, 1000),
    ParamSpec('image_transport', 'raw', 'str',
              "Image input of the node (image_transport's names): raw subscribes to "
              'sensor_msgs/Image on left/image_raw and right/image_raw, compressed to '
              'sensor_msgs/CompressedImage (JPEG or PNG) on <topic>/compressed, where <topic> '
              'is the remapped image topic.', choices=IMAGE_TRANSPORTS),
    ParamSpec('camera_info.topic', '', 'str',
              'sensor_msgs/CameraInfo topic of the left camera (e.g. left/camera_info); '
              'empty: none. When set, the first valid K narrows prior.focal_px to '
              "K's focal length within camera_info.focal_tolerance and sets "
              "prior.principal_point_px to K's principal point."),
    ParamSpec('camera_info.focal_tolerance', 0.1, 'float',
              'Relative tolerance of the focal length taken from camera_info: '
              'prior.focal_px becomes f * [1 - t, 1 + t].', 0.0, 0.9),
    ParamSpec('qos.reliable', False, 'bool',
              'Subscribe with reliable QoS instead of sensor-data (best effort).'),
    ParamSpec('qos.depth', 2, 'int', 'Subscription queue depth.', 1, 100),
    ParamSpec('diagnostics.period_s', 1.0, 'float',
              'Period of the /diagnostics status, seconds.', 0.05, 60.0),
    ParamSpec('diagnostics.silence_s', 1.0, 'float',
              'A camera that sends no image for this long is reported: /diagnostics WARN '
              'naming its topic (ERROR, with the reason, when the last pairs had no plane '
              'for 3 pairs), and a throttled log warning.', 0.01, 3600.0),
)

PARAMETERS_BY_NAME: dict[str, ParamSpec] = {spec.name: spec for spec in PARAMETERS}


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_finite_number(value: Any) -> bool:
    """Return whether ``value`` is a number that a float holds finitely (huge ints are not)."""
    if not _is_number(value):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def check_value(spec: ParamSpec, value: Any) -> Any:
    """Validate one parameter value against its spec and return it normalised.

    Args:
        spec: The parameter's specification.
        value: The value as read from YAML or a ROS parameter.

    Returns:
        The value converted to its canonical Python type (lists become lists of floats).

    Raises:
        ConfigError: If the type is wrong or the value is outside its admissible set; the
            message names the parameter.

    """
    name = spec.name
    if spec.kind == 'bool':
        if not isinstance(value, bool):
            raise ConfigError(f'parameter {name!r}: expected a bool, got {_shown(value)}')
        return value
    if spec.kind == 'str':
        if not isinstance(value, str):
            raise ConfigError(f'parameter {name!r}: expected a string, got {_shown(value)}')
        if spec.choices is not None and value not in spec.choices:
            raise ConfigError(
                f'parameter {name!r}: {_shown(value)} is not one of {", ".join(spec.choices)}')
        return value
    if spec.kind == 'int':
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(f'parameter {name!r}: expected an integer, got {_shown(value)}')
        _check_bounds(spec, value)
        return int(value)
    if spec.kind == 'float':
        if not _is_finite_number(value):
            raise ConfigError(
                f'parameter {name!r}: expected a finite number, got {_shown(value)}')
        _check_bounds(spec, float(value))
        return float(value)
    # Lists: 'range' and 'floats'.
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        raise ConfigError(f'parameter {name!r}: expected a list of numbers, got {_shown(value)}')
    items = list(value)
    if not all(_is_finite_number(v) for v in items):
        raise ConfigError(
            f'parameter {name!r}: expected finite numbers, got {_shown(items)}')
    items = [float(v) for v in items]
    if spec.kind == 'range':
        if len(items) != 2:
            raise ConfigError(f'parameter {name!r}: expected [min, max], got {_shown(items)}')
        if items[0] > items[1]:
            raise ConfigError(
                f'parameter {name!r}: inverted range [min, max] = {items!r} (min > max)')
        for v in items:
            _check_bounds(spec, v)
        return items
    if spec.lengths is not None and len(items) not in spec.lengths:
        allowed = ' or '.join(str(n) for n in spec.lengths)
        raise ConfigError(
            f'parameter {name!r}: expected {allowed} values, got {len(items)}')
    for v in items:
        _check_bounds(spec, v)
    extra = _EXTRA_CHECKS.get(name)
    if extra is not None and items:
        extra(spec, items)
    return items


def check_homography_values(spec: ParamSpec, values: list[float]) -> None:
    """Refuse a homography that cannot be a warm start: singular or ill-conditioned.

    The condition number is measured with pixel coordinates scaled by 1/1000 (so that a
    translation of hundreds of pixels or a perspective term of 1e-3 weigh about 1, as in
    Hartley normalisation of a 1000-pixel image), after scaling the matrix to unit largest
    entry, so that values as large as 1e308 do not overflow.

    Args:
        spec: The parameter (for messages).
        values: 9 finite floats, row-major.

    Raises:
        ConfigError: If the matrix is all zeros, singular or its condition number exceeds
            :data:`MAX_HOMOGRAPHY_CONDITION`.

    """
    import numpy as np

    matrix = np.asarray(values, dtype=np.float64).reshape(3, 3)
    scale = float(np.max(np.abs(matrix)))
    if scale == 0.0:
        raise ConfigError(f'parameter {spec.name!r}: all zeros is not a homography')
    scaled = matrix / scale
    conditioning = np.diag([1e-3, 1e-3, 1.0])
    normalised = conditioning @ scaled @ np.linalg.inv(conditioning)
    singular = np.linalg.svd(normalised, compute_uv=False)
    if not np.all(np.isfinite(singular)) or singular[2] <= 0.0:
        raise ConfigError(f'parameter {spec.name!r}: singular matrix (rank '
                          f'{int(np.linalg.matrix_rank(normalised))}), not invertible')
    condition = float(singular[0] / singular[2])
    if condition > MAX_HOMOGRAPHY_CONDITION:
        raise ConfigError(
            f'parameter {spec.name!r}: singular or nearly so (condition number '
            f'{condition:.3g} > {MAX_HOMOGRAPHY_CONDITION:.0e}, pixels scaled by 1/1000)')


MAX_HOMOGRAPHY_CONDITION = 1e6
"""Largest condition number of ``initial_homography`` (pixels scaled by 1/1000) accepted."""

_EXTRA_CHECKS = {'initial_homography': check_homography_values}


def _shown(value: Any) -> str:
    """Return ``repr(value)`` for a message, clipped to 80 characters with its length."""
    return wire_repr(value, 80)


def _check_bounds(spec: ParamSpec, value: float) -> None:
    if spec.low is not None and value < spec.low:
        raise ConfigError(
            f'parameter {spec.name!r}: {_shown(value)} is below the minimum {spec.low!r}')
    if spec.high is not None and value > spec.high:
        raise ConfigError(
            f'parameter {spec.name!r}: {_shown(value)} is above the maximum {spec.high!r}')


def flatten_params(params: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Flatten a nested parameter mapping into dotted names.

    ``{'prior': {'tilt_deg': [0, 5]}}`` and ``{'prior.tilt_deg': [0, 5]}`` both give
    ``{'prior.tilt_deg': [0, 5]}``.

    Args:
        params: The ``ros__parameters`` block, nested or already dotted.
        prefix: Name prefix used for recursion.

    Returns:
        A flat dict from dotted parameter name to value.

    Raises:
        ConfigError: If ``params`` is not a mapping.

    """
    if not isinstance(params, Mapping):
        raise ConfigError(f'parameters must be a mapping, got {type(params).__name__}')
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(flatten_params(value, prefix=name + '.'))
        else:
            flat[name] = value
    return flat


def nearest_parameter(name: str) -> str | None:
    """Return the declared parameter name closest to ``name``, or None if none is close."""
    matches = difflib.get_close_matches(name, list(PARAMETERS_BY_NAME), n=1, cutoff=0.6)
    if not matches:
        # A right leaf under a wrong or missing section ('focal_px' for 'prior.focal_px').
        leaf = name.rsplit('.', 1)[-1]
        matches = [spec.name for spec in PARAMETERS if spec.name.rsplit('.', 1)[-1] == leaf]
    return matches[0] if matches else None


def unknown_parameter_message(name: str) -> str:
    """Return "unknown parameter 'x'" with the nearest declared name, if one is close."""
    nearest = nearest_parameter(name)
    hint = f' (did you mean {nearest!r}?)' if nearest else ''
    return f'unknown parameter {name!r}{hint}'


def default_params_yaml(node_name: str = '/**') -> str:
    """Return a ROS 2 parameters file with every parameter at its default, commented.

    The block is keyed ``/**`` by default, so it applies to the node under any name or
    namespace (``-r __node:=front_plane``) and to ``plane_replay``.
    """
    lines = [f'{node_name}:', '  ros__parameters:']
    for spec in PARAMETERS:
        value = spec.default
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        elif isinstance(value, str):
            text = f"'{value}'"
        elif isinstance(value, list):
            text = '[' + ', '.join(_yaml_float(v) for v in value) + ']'
        elif isinstance(value, float):
            text = _yaml_float(value)
        else:
            text = repr(value)
        lines.append(f'    # {spec.description}')
        lines.append(f'    {spec.name}: {text}')
    return '\n'.join(lines) + '\n'


def _yaml_float(value: float) -> str:
    """Format a float so that YAML 1.1 readers (PyYAML) parse it as a float, not a string."""
    text = repr(float(value))
    if 'e' in text and '.' not in text.split('e')[0]:
        mantissa, exponent = text.split('e')
        text = f'{mantissa}.0e{exponent}'
    return text


def parameters_markdown() -> str:
    """Return the parameter table of docs/PARAMETERS.md (markdown)."""
    rows = ['| parameter | default | range | description |', '|---|---|---|---|']
    for spec in PARAMETERS:
        if spec.choices:
            rng = ', '.join(spec.choices)
        elif spec.low is not None and spec.high is not None:
            rng = f'{spec.low:g} .. {spec.high:g}'
        else:
            rng = ''
        rows.append(f'| `{spec.name}` | `{spec.default}` | {rng} | {spec.description} |')
    return '\n'.join(rows) + '\n'
