"""Typed, validated configuration shared by the live node and the offline replay.

Every tunable lives in one table, :data:`~domplane_ros.parameters.PARAMETERS` (re-exported
here with its validator and generators). The node declares its ROS parameters
from it (with descriptions and ranges), the replay reads the same YAML block through
:meth:`PlaneNodeConfig.from_ros_params`, and the table of docs/PARAMETERS.md is generated from
it, so there is one set of defaults and one validator.

Each part of the pipeline gets a frozen dataclass that validates itself in ``__post_init__``,
so a config built by hand through the Python API is checked as strictly as a params file.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Mapping

from domplane_ros.errors import ConfigError
from domplane_ros.parameters import (check_value, default_params_yaml, FEATURE_KINDS,
                                     flatten_params, PARAMETERS, PARAMETERS_BY_NAME,
                                     parameters_markdown, ParamSpec, POTENTIAL_NAMES,
                                     unknown_parameter_message)

__all__ = [
    'ConfigError', 'EstimatorConfig', 'FEATURE_KINDS', 'FeatureConfig', 'HeadConfig',
    'ImageConfig', 'MaskConfig', 'PARAMETERS', 'PARAMETERS_BY_NAME', 'ParamSpec', 'PipelineConfig',
    'PlaneNodeConfig', 'POTENTIAL_NAMES', 'PriorConfig', 'SyncConfig', 'TrackingConfig',
    'TransportConfig', 'VerificationSettings', 'check_value', 'default_params_yaml',
    'flatten_params', 'one_shot_search', 'parameters_markdown',
    'unknown_parameter_message',
]


class _Section:
    """Base of the per-part configs: every field is ``<section>.<field>`` in the table."""

    section: ClassVar[str] = ''

    def __post_init__(self) -> None:
        """Validate every field against :data:`PARAMETERS`."""
        _validate_section(self, self.section)


@dataclass(frozen=True)
class FeatureConfig(_Section):
    """Corner and line detection settings (see ``features.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'features'

    max_points: int = 400
    quality_level: float = 0.01
    min_distance_px: float = 8.0
    block_size: int = 5
    grid_rows: int = 4
    grid_cols: int = 4
    roi: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    max_width: int = 1280
    max_megapixels: float = 0.6
    kind: str = 'points'
    max_lines: int = 150
    min_line_length_px: float = 25.0
    line_scale: float = 0.8

    def __post_init__(self) -> None:
        """Validate every field, and that the region of interest is not empty."""
        super().__post_init__()
        x0, y0, x1, y1 = self.roi
        if not (x0 < x1 and y0 < y1):
            raise ConfigError(f"parameter 'features.roi': empty region {list(self.roi)!r}")


@dataclass(frozen=True)
class EstimatorConfig(_Section):
    """Two-step iteration settings (see ``estimator.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'estimator'

    potential: str = 'truncated_quadratic'
    lambda_weight: float = 0.8
    threshold_px: float = 3.0
    line_weight: float = 3.0
    gnc_start_px: float = 24.0
    gnc_factor: float = 0.5
    max_iterations: int = 60
    tolerance_px: float = 0.05
    energy_tolerance: float = 1e-7
    euclidean_refinement: bool = True
    min_inliers: int = 12


@dataclass(frozen=True)
class PriorConfig(_Section):
    """Camera set-up ranges (see ``prior.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'prior'

    focal_px: tuple[float, float] = (400.0, 900.0)
    baseline_over_height: tuple[float, float] = (0.05, 0.4)
    tilt_deg: tuple[float, float] = (10.0, 50.0)
    vergence_deg: tuple[float, float] = (-2.0, 4.0)
    principal_point_px: tuple[float, ...] = ()
    samples: int = 5
    refine_best: int = 6
    screen_threshold_px: float = 12.0


@dataclass(frozen=True)
class MaskConfig(_Section):
    """Dense mask settings (see ``mask.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'mask'

    scale: float = 0.5
    window_px: int = 5
    ncc_threshold: float = 0.7
    min_texture: float = 3.0
    morph_px: int = 5
    parallax_threshold_px: float = 1.0
    min_obstacle_height: float = 0.1


@dataclass(frozen=True)
class VerificationSettings(_Section):
    """Plane verification settings (see ``verification.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'verification'

    min_score: float = 0.22
    plane: str = 'ground'
    scale: float = 0.25
    drop_ratio: float = 0.5
    challenge_period: int = 10
    coarse_candidates: bool = True
    coarse_width_px: int = 320
    max_ground_roll_deg: float = 10.0
    prior_slope_margin: float = 0.5
    max_near_obstacle: float = 0.5
    covisible: bool = True


@dataclass(frozen=True)
class PipelineConfig(_Section):
    """Frame-to-frame policy (see ``pipeline.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'pipeline'

    max_energy_ratio: float = 4.0
    warm_gnc_start_px: float = 6.0
    check_prior_bounds: bool = True
    min_inlier_spread: float = 0.02
    max_clipped_fraction: float = 0.6
    max_stamp_jump_s: float = 10.0
    max_tracking_frames: int = 2
    search_candidates_per_frame: int = 6
    fast_joint_velocity: float = 0.5


@dataclass(frozen=True)
class TrackingConfig(_Section):
    """Temporal prediction settings (see ``tracking.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'tracking'

    enabled: bool = True
    max_points: int = 150
    window_px: int = 11
    pyramid_levels: int = 3
    forward_backward_px: float = 0.0
    min_tracks: int = 20
    min_inlier_ratio: float = 0.5
    threshold_px: float = 2.0
    reuse_pairs: int = 0


@dataclass(frozen=True)
class HeadConfig(_Section):
    """Optional head joint input of the node (see ``head.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'head'

    joint_states_topic: str = ''
    max_age_s: float = 0.5
    max_joint_velocity: float = 20.0


@dataclass(frozen=True)
class ImageConfig(_Section):
    """Image decoding settings (see ``image.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'image'

    mono16_bits: int = 16


@dataclass(frozen=True)
class SyncConfig(_Section):
    """Approximate-time pairing settings (see ``sync.*`` in :data:`PARAMETERS`)."""

    section: ClassVar[str] = 'sync'

    slop_s: float = 0.01
    queue_size: int = 5


@dataclass(frozen=True)
class TransportConfig:
    """Input and diagnostics settings of the node.

    ``qos.*``, ``diagnostics.*``, ``image_transport`` and ``camera_info.*``; the replay
    ignores them.
    """

    reliable: bool = False
    depth: int = 2
    diagnostics_period_s: float = 1.0
    silence_s: float = 1.0
    image_transport: str = 'raw'
    camera_info_topic: str = ''
    camera_info_focal_tolerance: float = 0.1

    _NAMES: ClassVar[dict[str, str]] = {
        'reliable': 'qos.reliable', 'depth': 'qos.depth',
        'diagnostics_period_s': 'diagnostics.period_s', 'silence_s': 'diagnostics.silence_s',
        'image_transport': 'image_transport', 'camera_info_topic': 'camera_info.topic',
        'camera_info_focal_tolerance': 'camera_info.focal_tolerance'}

    def __post_init__(self) -> None:
        """Validate every field against :data:`PARAMETERS`."""
        for attribute, name in self._NAMES.items():
            check_value(PARAMETERS_BY_NAME[name], getattr(self, attribute))

    @classmethod
    def from_flat(cls, values: Mapping[str, Any]) -> TransportConfig:
        """Build the settings from a flat mapping of dotted names to checked values."""
        return cls(**{attribute: values[name] for attribute, name in cls._NAMES.items()})


def _validate_section(obj: Any, section: str) -> None:
    for f in fields(obj):
        spec = PARAMETERS_BY_NAME[f'{section}.{f.name}']
        value = getattr(obj, f.name)
        checked = check_value(spec, list(value) if isinstance(value, tuple) else value)
        if isinstance(checked, list):
            checked = tuple(checked)
        object.__setattr__(obj, f.name, checked)


@dataclass(frozen=True)
class PlaneNodeConfig:
    """The whole configuration of a plane_node or plane_replay run."""

    features: FeatureConfig = field(default_factory=FeatureConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    prior: PriorConfig = field(default_factory=PriorConfig)
    mask: MaskConfig = field(default_factory=MaskConfig)
    verification: VerificationSettings = field(default_factory=VerificationSettings)
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    head: HeadConfig = field(default_factory=HeadConfig)
    image: ImageConfig = field(default_factory=ImageConfig)
    sync: SyncConfig = field(default_factory=SyncConfig)
    transport: TransportConfig = field(default_factory=TransportConfig)
    initial_homography: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        """Validate the initial homography."""
        values = check_value(PARAMETERS_BY_NAME['initial_homography'],
                             list(self.initial_homography))
        object.__setattr__(self, 'initial_homography', tuple(values))

    @classmethod
    def from_ros_params(cls, params: Mapping[str, Any]) -> PlaneNodeConfig:
        """Build a config from a ``plane_node: ros__parameters:`` block.

        Missing parameters take their defaults.

        Args:
            params: The ``ros__parameters`` mapping, nested or with dotted names.

        Returns:
            The validated configuration.

        Raises:
            ConfigError: On an unknown parameter, a wrong type, an out-of-range value or an
                inverted ``[min, max]`` range; the message names the parameter.

        """
        flat = flatten_params(params)
        unknown = sorted(set(flat) - set(PARAMETERS_BY_NAME))
        if unknown:
            raise ConfigError(unknown_parameter_message(unknown[0])
                              + (f' (and {len(unknown) - 1} more)' if len(unknown) > 1 else ''))
        values = {spec.name: spec.default for spec in PARAMETERS}
        for name, value in flat.items():
            values[name] = check_value(PARAMETERS_BY_NAME[name], value)
        return cls.from_flat(values)

    @classmethod
    def from_flat(cls, values: Mapping[str, Any]) -> PlaneNodeConfig:
        """Build a config from a complete flat mapping of dotted names to checked values.

        Args:
            values: One value per name in :data:`PARAMETERS`.

        Returns:
            The validated configuration.

        Raises:
            ConfigError: If a value is invalid.

        """
        def section(prefix: str) -> dict[str, Any]:
            out = {}
            for name, value in values.items():
                if name.startswith(prefix + '.'):
                    out[name[len(prefix) + 1:]] = tuple(value) if isinstance(
                        value, list) else value
            return out

        return cls(
            features=FeatureConfig(**section('features')),
            estimator=EstimatorConfig(**section('estimator')),
            prior=PriorConfig(**section('prior')),
            mask=MaskConfig(**section('mask')),
            verification=VerificationSettings(**section('verification')),
            pipeline=PipelineConfig(**section('pipeline')),
            tracking=TrackingConfig(**section('tracking')),
            head=HeadConfig(**section('head')),
            image=ImageConfig(**section('image')),
            sync=SyncConfig(**section('sync')),
            transport=TransportConfig.from_flat(values),
            initial_homography=tuple(values['initial_homography']),
        )


def one_shot_search(config: PlaneNodeConfig) -> PlaneNodeConfig:
    """Return ``config`` with the prior search done in one frame (all of ``prior.refine_best``).

    The live pipeline spreads a search over frames (``pipeline.search_candidates_per_frame``);
    a single pair, as in the evaluations and the tests, gets the whole search at once.
    """
    per_frame = max(config.pipeline.search_candidates_per_frame, config.prior.refine_best)
    return replace(config, pipeline=replace(config.pipeline,
                                            search_candidates_per_frame=per_frame))
