"""A new ground plane's own mask must not call the near ground obstacle.

``verification.max_near_obstacle`` (session 22, round 23 of docs/BENCHMARKS.md): on real
texture (KITTI 2015 000046, its road homography from the ground-truth disparity) the window
``crop`` 191 of ``tools/evaluate_real_rigs`` (x37 y58 906 x 182) with the documented default
prior published a plane through distant structure, 7.3 px off the road at confidence 1, which
no other rule refused; its own parallax mask marks the whole measured bottom third obstacle.
"""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import one_shot_search, PlaneNodeConfig, VerificationSettings
from domplane_ros.core.pixel_decision import OBSTACLE, PLANE, UNKNOWN
from domplane_ros.sim.generators import ahead_scene, indoor_scene, random_scene
from domplane_ros.sim.rigs import plane_error_px, swapped
from domplane_ros.stream import near_field
from domplane_ros.stream.near_field import (ground_below_share, MIN_NEAR_MEASURED,
                                            near_obstacle_share)
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.trust import TrustGate
from domplane_ros.tools.evaluate_real_rigs import configs, kitti_base
from domplane_ros.tools.evaluation.real_rigs import draw
import numpy as np
import pytest
from truth import real_rig_result, transfer_error_px


@pytest.fixture(scope='module')
def base():
    return kitti_base()


def _with_share(config: PlaneNodeConfig, share: float) -> PlaneNodeConfig:
    return replace(config, verification=replace(config.verification, max_near_obstacle=share))


def test_the_share_is_read_over_the_bottom_third_of_the_roi():
    labels = np.zeros((90, 60), np.uint8)
    labels[60:, :20] = OBSTACLE           # the bottom third: 20 of 60 columns obstacle,
    labels[60:, 20:30] = PLANE            # 10 plane, 30 unknown
    labels[:60] = OBSTACLE                # above the band: not read
    measured, share = near_obstacle_share(labels)
    assert measured == pytest.approx(0.5) and share == pytest.approx(2 / 3)
    # The ROI's right half: only plane and unknown columns in it.
    measured, share = near_obstacle_share(labels, (0.5, 0.0, 1.0, 1.0))
    assert measured == 0.0 and share == 0.0
    # The ROI's top half: its bottom third is rows 30-44, all obstacle.
    assert near_obstacle_share(labels, (0.0, 0.0, 1.0, 0.5)) == (1.0, 1.0)
    # Nothing measured: no decision, whatever the share bound.
    empty = np.zeros((90, 60), np.uint8)
    assert near_obstacle_share(empty) == (0.0, 0.0) and MIN_NEAR_MEASURED > 0


def test_the_ground_below_is_read_at_each_columns_lowest_measured_pixel():
    labels = np.zeros((90, 60), np.uint8)
    labels[60:80, :40] = OBSTACLE         # a box in the band's upper rows ...
    labels[80:, :20] = PLANE              # ... with the ground below it in 20 columns,
    labels[85:, 20:30] = UNKNOWN          # unknown below it in 10: their lowest measured
    labels[:60] = OBSTACLE                # pixel is the box's; above the band: not read
    assert ground_below_share(labels) == pytest.approx(20 / 40)
    labels[80:, 30:40] = PLANE            # ground below the last 10 of the box's columns
    labels[85:, 30:40] = OBSTACLE         # but obstacle at the very bottom: ungrounded
    assert ground_below_share(labels) == pytest.approx(20 / 40)
    labels[80:, 20:40] = PLANE
    assert ground_below_share(labels) == 0.0
    # Only the ROI's columns; nothing measured: 0.
    assert ground_below_share(labels, (0.0, 0.0, 0.5, 1.0)) == 0.0
    assert ground_below_share(np.zeros((90, 60), np.uint8)) == 0.0
    labels[60:, :] = OBSTACLE
    assert ground_below_share(labels) == 1.0


@pytest.mark.parametrize('seed', [7])
def test_the_ground_in_front_of_a_wide_box_is_published(seed, monkeypatch):
    # The ``ahead`` case of evaluate_trust (tuning seeds 7 and 30, one run here for the test
    # time): a wide box in front of the head
    # fills 58-68 % of what the floor's own mask measures in the bottom third, which the rule
    # of session 22 refused; the floor is seen below the box in all but 0-12 % of the band's
    # columns.
    scene = ahead_scene(seed)
    config = one_shot_search(PlaneNodeConfig())
    result = PlanePipeline(config).process(scene.left, scene.right, 0)
    assert result.ok and plane_error_px(scene, result.homography) < 1.0, result.reason
    # Without the ground-below condition the same floor is refused: the test looks at it.
    monkeypatch.setattr(near_field, 'MAX_UNGROUNDED_COLUMNS', -1.0)
    result = PlanePipeline(config).process(scene.left, scene.right, 0)
    assert not result.ok and 'its own mask marks' in result.reason, result.reason


def test_a_plane_whose_mask_calls_the_near_road_obstacle_is_refused(base):
    pair = draw(base, 'crop', 191)
    config = configs()['default']
    result, _ = real_rig_result(pair, config)
    assert not result.ok and 'its own mask marks' in result.reason, result.reason
    assert not result.mask.any()
    # Without the rule the same pair publishes the wrong plane.
    result, error = real_rig_result(pair, _with_share(config, 1.0))
    assert result.ok and error > 5.0, (result.reason, error)


def test_a_window_of_the_road_keeps_its_plane(base, monkeypatch):
    # Crop 233 (x181 y38 582 x 285): the correct plane (0.27 px) whose mask marks the most of
    # its measured bottom third obstacle of the tuning crops 48-247 with session 24's exact
    # coverage (24 %: the kerb, the parked cars' bottoms; 6 % of the band's columns end in
    # obstacle). Until session 24 this was crop 200 (0.58 px, 24 %), which the exact
    # coverage leaves ambiguous (score 0.24 against a rival's 0.28: refused, not wrong).
    result, error = real_rig_result(draw(base, 'crop', 233), configs()['default'])
    assert result.ok and error < 1.0, (result.reason, error)
    # With the bound under its share the ground is still seen below its obstacles (the
    # lowest measured pixel of every column of the band is plane): kept ...
    result, error = real_rig_result(draw(base, 'crop', 233),
                                    _with_share(configs()['default'], 0.1))
    assert result.ok and error < 1.0, (result.reason, error)
    # ... and refused without that condition: the test looks at this plane.
    monkeypatch.setattr(near_field, 'MAX_UNGROUNDED_COLUMNS', -1.0)
    result, _ = real_rig_result(draw(base, 'crop', 233),
                                _with_share(configs()['default'], 0.1))
    assert not result.ok and 'its own mask marks' in result.reason, result.reason


@pytest.mark.parametrize('seed', [1, 3, 4])
def test_a_plane_hinged_off_the_floor_at_the_bottom_is_refused_by_its_mask(seed):
    # Round 23 (mutants): on indoor scenes a ground plane through the floor at 2/3 of the
    # height and tipped sideways (3.6-3.9 px off the floor) explains the far wall, scores
    # 0.48-0.58 against the floor's 0.31 at full confidence and passes the gate unlocked.
    # Its own mask marks 86-89 % of the measured bottom third obstacle, the floor's 8-14 %.
    scene = indoor_scene(seed)
    hinge = 2.0 * scene.left.shape[0] / 3.0
    hinged = np.array([[1.0, 0.05, -0.05 * hinge], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    hinged = hinged @ scene.homography
    assert plane_error_px(scene, hinged) > 3.0
    gate = TrustGate(VerificationSettings())
    assert gate.near_field_refusal(hinged) == ''      # no pair: no decision
    gate.begin_pair(scene.left, scene.right)
    assert 'no ground below it' in gate.near_field_refusal(hinged)
    assert gate.near_field_refusal(scene.homography) == ''
    gate.end_pair()


def test_a_held_lock_is_never_judged_by_its_near_field(monkeypatch):
    # An obstacle that comes close and fills the bottom of the view must not drop a lock:
    # with the rule made to refuse every plane, a fresh pipeline publishes nothing, but a
    # lock found before keeps its warm planes.
    scene = random_scene(3, floor='random', n_boxes=3)
    pipeline = PlanePipeline()
    first = pipeline.process(scene.left, scene.right, 0)
    assert first.ok and transfer_error_px(scene, first.homography) < 1.0

    def always(*args, **kwargs):
        return 'not the ground: refused by the test'

    monkeypatch.setattr('domplane_ros.stream.trust.near_field_refusal', always)
    assert near_field.near_field_refusal is not always
    for k in range(1, 4):
        result = pipeline.process(scene.left, scene.right, k * 33_000_000)
        assert result.ok and pipeline.state == 'locked', result.reason
    fresh = PlanePipeline().process(scene.left, scene.right, 0)
    assert not fresh.ok and 'refused by the test' in fresh.reason, fresh.reason


@pytest.mark.parametrize('seed', [29])
def test_a_box_face_filling_the_view_is_not_reported_as_swapped_cameras(seed, monkeypatch):
    # The ``ahead`` case (tuning seeds 0 and 29, one run here for the test time): the face of
    # a wide box close ahead explains more of
    # the image than the floor, and its disparity shrinks toward the image bottom as a floor
    # seen by swapped cameras does; it was reported as swapped cameras ("swap the image
    # topics"). Read with left and right exchanged its own mask sees no ground (it lies beyond
    # infinity there), while the floors of swapped cameras fill their near field.
    scene = ahead_scene(seed)
    config = one_shot_search(PlaneNodeConfig())
    result = PlanePipeline(config).process(scene.left, scene.right, 0)
    assert not result.ok and 'a surface facing the head' in result.reason, result.reason
    assert 'swap' not in result.reason
    # Without the test of the swapped reading the same pair says swap.
    monkeypatch.setattr('domplane_ros.stream.trust.MIN_SWAPPED_GROUND', 0.0)
    result = PlanePipeline(config).process(scene.left, scene.right, 0)
    assert not result.ok and 'appear swapped' in result.reason, result.reason


def test_the_floor_of_swapped_cameras_is_seen_read_swapped():
    scene = swapped(random_scene(0))
    gate = TrustGate(VerificationSettings())
    gate.begin_pair(scene.left, scene.right)
    assert gate.swap_seen(scene.homography)
    # A plane of this head facing it (the fronto-parallel plane 40 px of disparity away) is
    # not: read swapped it lies beyond infinity.
    facing = np.array([[1.0, 0.0, -40.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert not gate.swap_seen(facing)
    assert not gate.swap_seen(facing, pair=(scene.left, scene.right))
    # Other images than the pair begun: no evidence.
    assert gate.swap_seen(facing, pair=(scene.left.copy(), scene.right))
    gate.end_pair()
    assert gate.swap_seen(facing)      # no pair: no evidence against a swap
