"""The challenge queue: one bounded task per locked pair, starts moved with the cameras."""

from __future__ import annotations

from domplane_ros.core.homography import corner_distance_px
from domplane_ros.stream.challenge import (Challenge, COARSE, COARSE_START, COARSE_STEP,
                                           distinct_starts, NEAR_LOCK_PX, PRIOR_START, SCREEN,
                                           Task)
import numpy as np

SIZE = (640, 480)


def _shift(dx: float, dy: float = 0.0) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def _drain(challenge):
    kinds = []
    while (task := challenge.next_task()) is not None:
        kinds.append(task.kind)
    return kinds


def test_tasks_come_in_order_and_near_starts_are_dropped():
    lock = _shift(30.0)
    challenge = Challenge()
    assert challenge.next_task().kind == COARSE
    starts = [lock, _shift(30.0 + NEAR_LOCK_PX / 2), _shift(80.0), _shift(81.0), _shift(-40.0)]
    assert challenge.add_coarse_starts(starts, lock, SIZE) == 2  # 80 and -40 px
    challenge.add_prior_starts([_shift(5.0)])
    first = challenge.next_task()
    assert first.kind == COARSE_START and corner_distance_px(first.start, _shift(80.0),
                                                             *SIZE) < 1e-9
    assert _drain(challenge) == [COARSE_START, SCREEN, PRIOR_START]
    assert challenge.done and challenge.next_task() is None


def test_coarse_starts_follow_the_cameras_and_are_dropped_without_motion():
    challenge = Challenge()
    challenge.next_task()
    challenge.add_coarse_starts([_shift(80.0), _shift(-40.0)], np.eye(3), SIZE)
    challenge.add_prior_starts([_shift(5.0)])
    # The left camera moved 10 px right, the right camera 4 px down: H' = M_r H M_l^-1.
    challenge.follow((_shift(10.0), _shift(0.0, 4.0)))
    task = challenge.next_task()
    assert corner_distance_px(task.start, _shift(70.0, 4.0), *SIZE) < 1e-9
    challenge.follow(None)  # no motion: the remaining coarse start is stale
    assert _drain(challenge) == [SCREEN, PRIOR_START]


def test_distinct_starts_keep_the_first_of_each_neighbourhood():
    starts = [_shift(0.0), _shift(NEAR_LOCK_PX / 2), _shift(50.0), _shift(50.0, 3.0),
              _shift(-50.0)]
    kept = distinct_starts(starts, SIZE)
    assert [corner_distance_px(k, s, *SIZE) for k, s in zip(kept, starts[::2])] == [0, 0, 0]
    assert len(kept) == 3
    # With a lock at 50 px, its neighbours go too.
    assert len(distinct_starts(starts, SIZE, lock=_shift(49.0))) == 2


def test_the_challenge_time_is_reported_as_part_of_the_estimate():
    # A rendered sequence locked from its first pair; with challenge_period 1 the challenge
    # starts on the first locked pair, so a pair with a task reports its time (within the
    # estimate's), and without the challenge every pair reports 0.
    from dataclasses import replace

    from domplane_ros.config import PlaneNodeConfig
    from domplane_ros.sim.generators import scene_sequence
    from domplane_ros.stream.pipeline import PlanePipeline

    frames = scene_sequence(4, 3, width=320, height=240, floor='random')
    base = PlaneNodeConfig()
    reported = {}
    for period in (0, 1):
        config = replace(base, verification=replace(base.verification,
                                                    challenge_period=period))
        pipeline = PlanePipeline(config)
        results = [pipeline.process(f.left, f.right, i * 33_000_000)
                   for i, f in enumerate(frames)]
        assert all(r.ok for r in results)
        reported[period] = [(r.timings_ms['challenge'], r.timings_ms['estimate'])
                            for r in results[1:]]
    assert all(challenge == 0.0 for challenge, _ in reported[0])
    assert all(0.0 < challenge <= estimate for challenge, estimate in reported[1])


def test_the_alignment_runs_in_steps_and_its_planes_follow_the_cameras():
    def steps():  # an alignment of three steps whose planes are 80 and 30 px shifts
        yield
        yield
        return np.stack([_shift(80.0), _shift(30.0)])

    lock = _shift(-50.0)
    challenge = Challenge()
    assert challenge.next_task().kind == COARSE
    challenge.align(Task(COARSE_STEP, steps=steps()), lock, SIZE)
    for motion in ((_shift(10.0), _shift(0.0, 4.0)), (_shift(-2.0), np.eye(3))):
        challenge.follow(motion)
        task = challenge.next_task()
        assert task.kind == COARSE_STEP
        challenge.align(task, lock, SIZE)
    # Moved through both motions (H' = M_r2 M_r1 H M_l1^-1 M_l2^-1): 80 - 8 px, 4 px down;
    # the 30 px plane is now 22 px right, 4 px down.
    first = challenge.next_task()
    assert first.kind == COARSE_START
    assert corner_distance_px(first.start, _shift(72.0, 4.0), *SIZE) < 1e-9
    assert corner_distance_px(challenge.next_task().start, _shift(22.0, 4.0), *SIZE) < 1e-9
    # The pipeline runs the screening in the alignment's first pair: taken out of the queue.
    assert challenge.take(SCREEN) and not challenge.take(SCREEN) and challenge.done
    # Without a motion the alignment's planes would be stale: the task is dropped.
    challenge = Challenge()
    challenge.next_task()
    challenge.align(Task(COARSE_STEP, steps=steps()), lock, SIZE)
    challenge.follow(None)
    assert _drain(challenge) == [SCREEN]
