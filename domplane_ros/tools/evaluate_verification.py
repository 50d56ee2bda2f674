"""How well :func:`~domplane_ros.core.verification.verify_plane` separates true from wrong planes.

Run ``python -m domplane_ros.tools.evaluate_verification [--first-seed S] [--count N]
[--data DIR] [--cache DIR] [--out DIR]``. For every rendered scene
(:func:`~domplane_ros.sim.random_scene` with a random right-camera gain and offset) it
verifies the true plane and wrong planes of these kinds, and on the real pairs the reference
plane and shifted or swapped ones:

* ``true``: the ground-truth homography; ``true_1px``: its image corners moved by up to 1 px.
* ``shift5``, ``shift10_20``, ``shift40_80``: the true plane moved by that many pixels along x
  (the epipolar direction) or y in the right image.
* ``period``: the true plane moved by one texture period *on the floor* (one tile, plank or
  checker square; only for the periodic floors). This is the exact look-alike: on a perfectly
  periodic floor it matches the whole floor as well as the truth does.
* ``cut``: the true plane of the next seed's scene (the plane held before a cut).
* ``prior``: three random candidates of the default prior more than 5 px from the truth.
* ``inverse``: the plane a swapped pair gives (``H^-1``), on the correctly ordered pair.
* ``swap_ok``: ``H^-1`` on the swapped pair (a *correct* plane for that pair: the
  verification must accept it and :func:`swap_evidence` must flag it); ``swap_wrong``:
  ``H`` on the swapped pair.

A hypothesis counts as wrong when its mean transfer error on the visible floor exceeds 5 px.
The table gives, per kind, the score's min / median / max, how many were accepted, and the
swap detector's verdicts. The picture ``verification_maps.png`` shows the agreement maps of
the true plane and a look-alike on one scene.

The readers and references of the real pairs come from
:mod:`domplane_ros.tools.evaluation.references`.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import sys
import time
from typing import Any, Iterator, Sequence

import cv2
from domplane_ros.config import PriorConfig
from domplane_ros.core import ground_slope, prior, verification
from domplane_ros.core.homography import apply_homography, fit_homography
from domplane_ros.sim.generators import random_boxes, random_scene, random_setup
from domplane_ros.sim.model import BACKGROUNDS
from domplane_ros.sim.textures import FLOOR_KINDS
from domplane_ros.tools.common import machine_name, one_core, progress, tool_parser
from domplane_ros.tools.evaluation.references import (chessboards, default_data_dir, KITTI_DIR,
                                                      kitti_reference, OPENCV_DIR, read_gray)
from domplane_ros.tools.evaluation.tables import markdown_table
import numpy as np

WRONG_PX = 5.0
SHIFTS_PX = (5, 10, 20, 40, 80)
# Floor periods in world units (camera height 1), along the texture's own axes, as rendered
# by sim/textures.py: tiles 64 texels of 0.005, planks 32 texels wide, checker colour period 2 x 64
# texels (a diagonal step of one square also keeps the colour), plain tiles 128 texels.
FLOOR_PERIODS = {
    'tiles': ((0.32, 0.0), (0.0, 0.32), (-0.32, 0.0), (0.0, -0.32)),
    'checker': ((0.64, 0.0), (0.0, 0.64), (0.32, 0.32), (0.32, -0.32)),
    'planks': ((0.16, 0.0), (-0.16, 0.0), (0.0, 0.16), (0.0, -0.16)),
    'tiles_plain': ((0.64, 0.0), (0.0, 0.64), (-0.64, 0.0), (0.0, -0.64)),
    'planks_plain': ((0.16, 0.0), (-0.16, 0.0), (0.0, 0.16), (0.0, -0.16)),
}
TRUE_KINDS = ('true', 'true_1px', 'swap_ok')


# --------------------------------------------------------------------------------------------
# Rendered scenes and their hypotheses.


def _frame_arrays(seed: int, floor: str | None, cache: Path | None) -> dict[str, Any]:
    """Render (or read from ``cache``) one scene: images, truth, set-up, head yaw."""
    name = f'{floor or "any"}_{seed}.npz'
    if cache is not None and (cache / name).exists():
        with np.load(cache / name) as data:
            arrays = {key: data[key] for key in data.files}
    else:
        frame = random_scene(seed, floor=floor, gain=None, offset=None)
        s = frame.setup
        arrays = {'left': frame.left, 'right': frame.right, 'H': frame.homography,
                  'plane': frame.plane_left, 'vis': frame.visible_in_right,
                  'floor': np.array(frame.floor),
                  'setup': np.array([s.focal_px, s.baseline_over_height, s.tilt_deg,
                                     s.vergence_deg])}
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(cache / name, **arrays)
    arrays['yaw_deg'] = _head_yaw(seed, floor, *arrays['left'].shape[::-1])
    return arrays


def _head_yaw(seed: int, floor: str | None, width: int, height: int) -> float:
    """Replay ``random_scene``'s draws up to the head pose and return its yaw in degrees."""
    rng = np.random.default_rng((int(seed), 4242))
    setup = random_setup(rng, width, height)
    if floor is None:
        rng.integers(len(FLOOR_KINDS))
    rng.integers(len(BACKGROUNDS))
    random_boxes(rng, setup, int(rng.integers(1, 6)))
    rng.uniform(0, 100)
    rng.uniform(0, 100)
    return float(rng.uniform(0, 360))


def floor_shift_homography(setup: Sequence[float], delta_level: tuple[float, float],
                           width: int, height: int) -> np.ndarray:
    """Return the plane homography that pairs each floor point with one ``delta`` away.

    Left pixel of floor point ``X`` goes to the right pixel of ``X + delta`` (``delta`` in
    the head's level frame: x right, z forward; camera height 1). This is the true homography
    of a right camera moved by ``-delta``, so on a floor with period ``delta`` it is an exact
    look-alike.
    """
    focal, baseline, tilt_deg, verg_deg = (float(v) for v in setup)
    k = prior.intrinsics(focal, width, height)
    tilt, verg = math.radians(tilt_deg), math.radians(verg_deg)
    normal = np.array([0.0, math.cos(tilt), math.sin(tilt)])
    forward = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    centre = np.array([baseline, 0.0, 0.0]) - delta_level[0] * np.array(
        [1.0, 0.0, 0.0]) - delta_level[1] * forward
    r_v = np.array([[math.cos(verg), 0.0, math.sin(verg)], [0.0, 1.0, 0.0],
                    [-math.sin(verg), 0.0, math.cos(verg)]])
    hom = k @ r_v @ (np.eye(3) - np.outer(centre, normal)) @ np.linalg.inv(k)
    return hom / hom[2, 2]


def floor_error_px(homography: np.ndarray, reference: np.ndarray, plane: np.ndarray) -> float:
    """Mean distance between two homographies' transfers over the (H, W) bool floor pixels."""
    ys, xs = np.nonzero(plane[::8, ::8])
    points = np.stack([xs * 8, ys * 8], axis=1).astype(np.float64)
    if points.shape[0] == 0:
        return math.nan
    diff = apply_homography(homography, points) - apply_homography(reference, points)
    return float(np.mean(np.linalg.norm(diff, axis=1)))


def _translate(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def _shift_kind(shift: int) -> str:
    return 'shift5' if shift == 5 else ('shift10_20' if shift <= 20 else 'shift40_80')


def scene_hypotheses(seed: int, data: dict[str, Any], other_h: np.ndarray
                     ) -> Iterator[tuple[str, np.ndarray, np.ndarray, np.ndarray, float]]:
    """Yield ``(kind, H, left, right, error_px)`` for one rendered scene (see module doc)."""
    left, right, truth, plane = data['left'], data['right'], data['H'], data['plane']
    height, width = left.shape
    rng = np.random.default_rng(seed)
    inverse = np.linalg.inv(truth)
    inverse /= inverse[2, 2]

    def error(hom: np.ndarray) -> float:
        return floor_error_px(hom, truth, plane)

    yield 'true', truth, left, right, 0.0
    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]],
                       np.float64)
    moved = apply_homography(truth, corners) + rng.uniform(-1.0, 1.0, (4, 2))
    near = fit_homography(corners, moved)
    yield 'true_1px', near, left, right, error(near)
    for shift in SHIFTS_PX:
        for dx, dy in ((shift, 0), (-shift, 0), (0, shift), (0, -shift)):
            hom = _translate(dx, dy) @ truth
            yield _shift_kind(shift), hom, left, right, error(hom)
    yaw = math.radians(float(data['yaw_deg']))
    for dxw, dzw in FLOOR_PERIODS.get(str(data['floor']), ()):
        delta = (math.cos(yaw) * dxw - math.sin(yaw) * dzw,
                 math.sin(yaw) * dxw + math.cos(yaw) * dzw)
        hom = floor_shift_homography(data['setup'], delta, width, height)
        yield 'period', hom, left, right, error(hom)
    yield 'cut', other_h, left, right, error(other_h)
    candidates = prior.prior_candidates(PriorConfig(), width, height)
    errors = np.array([error(c) for c in candidates])
    far = np.nonzero(errors > WRONG_PX)[0]
    for index in rng.choice(far, min(3, far.size), replace=False):
        yield 'prior', candidates[index], left, right, float(errors[index])
    yield 'inverse', inverse, left, right, error(inverse)
    yield 'swap_ok', inverse, right, left, 0.0
    yield 'swap_wrong', truth, right, left, floor_error_px(truth, inverse, plane)


# --------------------------------------------------------------------------------------------
# Real pairs.


def real_hypotheses(data_dir: Path
                    ) -> Iterator[tuple[str, str, np.ndarray, np.ndarray, np.ndarray, float]]:
    """Yield ``(pair, kind, H, left, right, error_px)`` for KITTI and the chessboard pairs.

    The reference planes are :func:`kitti_reference` (the road, from the
    ground-truth disparity) and a homography fitted to the chessboard corners. Wrong planes
    are the reference shifted by 5 to 80 px and its inverse; ``swap_ok`` is the inverse on
    the swapped pair.
    """
    pairs = []
    kitti = data_dir / KITTI_DIR
    if kitti.exists():
        ref = kitti_reference(kitti)
        pairs.append(('kitti_000046', read_gray(kitti / 'left.png'),
                      read_gray(kitti / 'right.png'), ref.plane.homography()))
    boards = data_dir / OPENCV_DIR
    if boards.exists():
        for number, left, right, src, dst in chessboards(boards):
            hom = fit_homography(src, dst)
            if isinstance(hom, np.ndarray):
                pairs.append((f'chessboard_{number}', left, right, hom))
    for name, left, right, hom in pairs:
        inverse = np.linalg.inv(hom)
        inverse /= inverse[2, 2]
        yield name, 'true', hom, left, right, 0.0
        for shift in SHIFTS_PX:
            for dx, dy in ((shift, 0), (-shift, 0), (0, shift), (0, -shift)):
                yield name, _shift_kind(shift), _translate(dx, dy) @ hom, left, right, shift
        yield name, 'inverse', inverse, left, right, math.inf
        yield name, 'swap_ok', inverse, right, left, 0.0


# --------------------------------------------------------------------------------------------
# Tables, timing and the picture.


def _row(kind: str, results: Sequence[tuple[verification.PlaneVerification, Any]]) -> list[Any]:
    scores = np.array([r.score for r, _ in results])
    accepted = sum(r.accepted for r, _ in results)
    swapped = sum(s.swapped for _, s in results)
    return [kind, len(results), f'{scores.min():.3f}', f'{np.median(scores):.3f}',
            f'{scores.max():.3f}', accepted, swapped]


def separation_table(rows: dict[str, list]) -> str:
    """Return a markdown table: per kind, n, score min/median/max, accepted, swap flagged."""
    header = ['kind', 'n', 'score min', 'median', 'max', 'accepted', 'swap flagged']
    order = [k for k in ('true', 'true_1px', 'swap_ok', 'shift5', 'shift10_20', 'shift40_80',
                         'period', 'cut', 'prior', 'inverse', 'swap_wrong') if k in rows]
    return markdown_table(header, [_row(k, rows[k]) for k in order])


def ranking_line(records: Sequence[tuple]) -> str:
    """Return how often the true plane outscored every wrong plane of its own scene."""
    best_wrong: dict[int, float] = {}
    true: dict[int, float] = {}
    for seed, _, kind, _, score, *_ in records:
        if kind == 'true':
            true[seed] = score
        elif kind not in TRUE_KINDS:
            best_wrong[seed] = max(best_wrong.get(seed, 0.0), score)
    ratios = np.array([true[s] / max(best_wrong.get(s, 0.0), 1e-6) for s in true])
    return (f'same-pair ranking: the true plane outscored every wrong plane of its scene in '
            f'{int(np.sum(ratios > 1))} of {ratios.size} scenes; smallest ratio '
            f'{ratios.min():.2f}, 5th percentile {np.percentile(ratios, 5):.2f}')


def timing(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
           config: verification.VerificationConfig, calls: int = 500) -> dict[str, float]:
    """Return median and p95 wall and thread-CPU milliseconds of ``verify_plane`` calls."""
    wall, cpu = [], []
    for _ in range(calls):
        start, start_cpu = time.perf_counter(), time.thread_time()
        verification.verify_plane(left, right, homography, config)
        wall.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - start_cpu)
    wall_ms, cpu_ms = 1000 * np.array(wall), 1000 * np.array(cpu)
    return {'median_ms': float(np.median(wall_ms)), 'p95_ms': float(np.percentile(wall_ms, 95)),
            'cpu_median_ms': float(np.median(cpu_ms)),
            'cpu_p95_ms': float(np.percentile(cpu_ms, 95))}


def agreement_picture(path: Path, left: np.ndarray, right: np.ndarray,
                      planes: Sequence[tuple[str, np.ndarray]],
                      config: verification.VerificationConfig) -> None:
    """Draw, per plane, the left image with its support and the warped right image.

    Green: pixels supporting the plane uniquely; red: NCC above the threshold but not a sharp
    peak; the second row is the right image warped into the left view by the plane.
    """
    columns = []
    for name, hom in planes:
        maps = verification.agreement_maps(left, right, hom, config)
        rgb = cv2.cvtColor(maps.left, cv2.COLOR_GRAY2RGB)
        matched = maps.textured & maps.inside & (maps.ncc >= config.ncc_threshold)
        for mask, colour in ((matched, (200, 0, 0)), (maps.support, (0, 190, 0))):
            rgb[mask] = (0.4 * rgb[mask] + 0.6 * np.array(colour)).astype(np.uint8)
        column = np.vstack([rgb, cv2.cvtColor(maps.warped, cv2.COLOR_GRAY2RGB)])
        column = cv2.resize(column, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        result = verification.verify_plane(left, right, hom, config)
        cv2.putText(column, f'{name}: score {result.score:.2f}', (4, 14),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1, cv2.LINE_AA)
        columns.append(column)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(np.hstack(columns), cv2.COLOR_RGB2BGR))


def _evaluate_rendered(seeds: Sequence[int], floor: str | None, cache: Path | None,
                       config: verification.VerificationConfig, records: list[tuple]
                       ) -> dict[str, list]:
    rows: dict[str, list] = {}
    datas = {}
    for seed in progress(seeds, 'scenes'):
        datas[seed] = _frame_arrays(seed, floor, cache)
    for index, seed in enumerate(seeds):
        data = datas[seed]
        other = datas[seeds[(index + 1) % len(seeds)]]['H']
        for kind, hom, left, right, error in scene_hypotheses(seed, data, other):
            wrong = error > WRONG_PX
            if kind not in TRUE_KINDS and not wrong:
                continue  # a "wrong" plane that happens to be near the truth
            result = verification.verify_plane(left, right, hom, config)
            swap = ground_slope.swap_evidence(hom, *left.shape[::-1])
            rows.setdefault(kind, []).append((result, swap))
            records.append((seed, str(data['floor']), kind, error, result.score,
                            result.support_fraction, result.accepted, swap.disparity_slope))
    return rows


def main(argv: list[str] | None = None) -> int:
    """Run the evaluation and print the tables; see the module docstring."""
    parser = tool_parser(__doc__)
    parser.add_argument('--first-seed', type=int, default=0)
    parser.add_argument('--count', type=int, default=20)
    parser.add_argument('--floor', default=None, help='floor kind (default: random)')
    parser.add_argument('--data', type=Path, default=default_data_dir())
    parser.add_argument('--cache', type=Path, default=None,
                        help='folder to keep rendered scenes in (.npz)')
    parser.add_argument('--out', type=Path, default=Path('eval_output'))
    parser.add_argument('--no-real', action='store_true', help='skip the real pairs')
    args = parser.parse_args(argv)
    with one_core():
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    config = verification.VerificationConfig()
    print(f'machine: {machine_name()}')
    print(f'config: {config}')
    seeds = list(range(args.first_seed, args.first_seed + args.count))
    records: list[tuple] = []
    rows = _evaluate_rendered(seeds, args.floor, args.cache, config, records)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / f'verification_{seeds[0]}_{args.floor or "any"}.csv', 'w') as file:
        file.write('seed,floor,kind,error_px,score,support,accepted,disparity_slope\n')
        file.writelines(','.join(str(v) for v in record) + '\n' for record in records)
    print(f'\nRendered scenes, seeds {seeds[0]}-{seeds[-1]}, floor {args.floor or "random"}:')
    print(separation_table(rows))
    print(ranking_line(records))
    if not args.no_real:
        real: dict[str, list] = {}
        for pair, kind, hom, left, right, _ in real_hypotheses(args.data):
            result = verification.verify_plane(left, right, hom, config)
            swap = ground_slope.swap_evidence(hom, *left.shape[::-1])
            real.setdefault(kind, []).append((result, swap))
            if kind in ('true', 'swap_ok'):
                print(f'{pair} {kind}: score {result.score:.3f} accepted {result.accepted} '
                      f'swap slope {swap.disparity_slope:+.4f}')
        print(f'\nReal pairs ({args.data}):')
        print(separation_table(real))
    data = _frame_arrays(seeds[0], args.floor, args.cache)
    print('\ntiming at 640 x 480 (one thread):', {
        key: round(value, 3) for key, value in timing(data['left'], data['right'], data['H'],
                                                      config).items()})
    planes = [('true', data['H'])]
    planes += [(kind, hom) for kind, hom, *_ in scene_hypotheses(
        seeds[0], data, data['H']) if kind == 'period'][:1]
    planes.append(('shift 20 px', _translate(20.0, 0.0) @ data['H']))
    picture = args.out / 'verification_maps.png'
    agreement_picture(picture, data['left'], data['right'], planes, config)
    print(f'picture: {picture}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
