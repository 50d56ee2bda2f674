"""Real texture, rough rigs: KITTI 000046 perturbed by transformations of known effect.

Run ``python -m domplane_ros.tools.evaluate_real_rigs [--draws 24] [--first-seed 0]
[--out DIR] [--others] [--no-baselines] [--families crop,fixed]``. The reference is KITTI
2015 frame 000046's road homography ``H`` from its ground-truth disparity
(:func:`~domplane_ros.tools.evaluation.references.kitti_reference`); each draw perturbs
the pair by one transformation whose effect on ``H`` is exact
(:mod:`domplane_ros.tools.evaluation.real_rigs`: the right camera's rig errors, a
photometric change on one camera, crops of both images incl. the upper half, swapped cameras
after a rig error) and scores every method by the mean transfer error over the road's pixels,
as ``evaluate_kitti`` does. Four fixed pairs run once: the pair itself, pyrDown x1 and x2,
and the swapped pair. The product runs in the two configurations a user would have, on the
whole image (no ROI: one made from this frame's road would come from the truth): the
documented default prior (``default``) and ``KITTI_PRIOR`` (``kitti_prior``); OpenCV ORB +
MAGSAC++ and SIFT + MAGSAC++ run on the same pairs. A published plane is *correct* below 1 px,
*wrong* above 5 px; in a window with fewer than ``MIN_ROAD_PX`` road pixels every plane
published is wrong (the product must refuse there). Precision = correct / published, recall =
correct / pairs with road. ``--others`` also runs Aloe, books and graffiti (no ground plane)
through the default ground mode with every photometric kind.

Writes ``summary.md``, ``draws.csv`` and ``sheet.png`` (the worst draws and every wrong
plane: the left image with the road pixels coloured by error, green < 1 px, yellow 1-5,
red > 5, and the verdict) to ``--out`` (default ``eval_output/real_rigs``).
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import dataclass
import math
from pathlib import Path
import re
import sys
import time
from typing import Sequence

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.mask import overlay
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import machine_name, one_core, progress
from domplane_ros.tools.evaluation.datasets import FULL_IMAGE, kitti_config
from domplane_ros.tools.evaluation.methods import run_orb_magsac
from domplane_ros.tools.evaluation.real_rigs import (downscale, draw, DRAW_FAMILIES,
                                                     draw_value, MIN_ROAD_PX, Perturbed,
                                                     photometric, PHOTOMETRIC_KINDS, swap)
from domplane_ros.tools.evaluation.references import (default_data_dir, KITTI_DIR,
                                                      kitti_reference, OPENCV_DIR, read_gray)
import numpy as np

CORRECT_PX = 1.0
WRONG_PX = 5.0
CONFIGS = ('default', 'kitti_prior')
METHODS = ('ours default', 'ours kitti_prior', 'orb_magsac', 'sift_magsac')
SHEET_TILES = 12
# The name of the fixed pairs (the pair itself, pyrDown x1 and x2, swapped) for --families.
FIXED = 'fixed'
OTHER_PAIRS = (('aloe', 'aloeL.jpg', 'aloeR.jpg'), ('books', 'left.jpg', 'right.jpg'),
               ('graffiti', 'graf1.png', 'graf3.png'))


@dataclass
class Row:
    """One method on one perturbed pair."""

    family: str
    seed: int
    detail: str
    method: str
    road_px: int
    published: bool
    error_px: float  # mean over the road pixels; NaN when refused or without road
    reason: str
    time_ms: float

    @property
    def verdict(self) -> str:
        """Return ``refused``, ``correct``, ``1-5 px``, ``wrong`` or ``wrong (no road)``."""
        if not self.published:
            return 'refused'
        if self.road_px < MIN_ROAD_PX:
            return 'wrong (no road)'
        if self.error_px < CORRECT_PX:
            return 'correct'
        return '1-5 px' if self.error_px <= WRONG_PX else 'wrong'


def kitti_base(data_dir: Path | None = None) -> Perturbed:
    """Return KITTI 000046 as the unperturbed pair: truth ``H``, the road's pixels."""
    folder = (data_dir or default_data_dir()) / KITTI_DIR
    ref = kitti_reference(folder)
    ys, xs = np.nonzero(ref.road)
    return Perturbed('original', '', read_gray(folder / 'left.png'),
                     read_gray(folder / 'right.png'), ref.plane.homography(),
                     np.stack([xs, ys], axis=1).astype(np.float64))


def configs() -> dict[str, PlaneNodeConfig]:
    """Return the two configurations: the documented default and ``KITTI_PRIOR``, whole image."""
    return {'default': one_shot_search(PlaneNodeConfig()),
            'kitti_prior': one_shot_search(kitti_config(FULL_IMAGE))}


def run_pair(pair: Perturbed, seed: int, settings: dict[str, PlaneNodeConfig],
             baselines: bool = True) -> tuple[list[Row], dict[str, np.ndarray | None]]:
    """Run every method on one pair; return its rows and each method's homography."""
    rows, found = [], {}
    for name, config in settings.items():
        start = time.perf_counter()
        result = PlanePipeline(config).process(pair.left, pair.right, 0)
        elapsed = 1e3 * (time.perf_counter() - start)
        found[f'ours {name}'] = result.homography if result.ok else None
        rows.append(_row(pair, seed, f'ours {name}', found[f'ours {name}'], result.reason,
                         elapsed))
    if baselines:
        for sift in (False, True):
            run = run_orb_magsac(pair.left, pair.right, repeats=1, sift=sift)
            found[run.method] = run.homography
            rows.append(_row(pair, seed, run.method, run.homography, run.reason, run.time_ms))
    return rows, found


def _row(pair: Perturbed, seed: int, method: str, homography: np.ndarray | None, reason: str,
         time_ms: float) -> Row:
    error = math.nan
    if homography is not None and pair.has_road:
        error = float(np.mean(pair.errors_px(homography)))
    return Row(pair.family, seed, pair.detail, method, int(pair.points.shape[0]),
               homography is not None, error, '' if homography is not None else reason,
               time_ms)


def fixed_pairs(base: Perturbed) -> list[Perturbed]:
    """Return the pairs without a draw: the pair itself, pyrDown x1 and x2, swapped."""
    return [base, downscale(base, 1), downscale(base, 2), swap(base)]


def evaluate(draws: Sequence[int], base: Perturbed, baselines: bool = True,
             families: Sequence[str] = (*DRAW_FAMILIES, FIXED)
             ) -> tuple[list[Row], list[tuple[Row, Perturbed, np.ndarray | None]]]:
    """Run the fixed pairs and every family's draws; return the rows and the sheet's tiles.

    ``families``: the draw families run (of :data:`DRAW_FAMILIES`) and, if it holds
    :data:`FIXED`, the fixed pairs.
    """
    settings = configs()
    drawn = [f for f in DRAW_FAMILIES if f in families]
    fixed = fixed_pairs(base) if FIXED in families else []
    jobs = [(pair, -1) for pair in fixed]
    jobs += [(None, seed) for seed in draws]
    rows: list[Row] = []
    kept: list[tuple[Row, Perturbed, np.ndarray | None]] = []
    bar = progress(None, 'real rigs', total=len(fixed) + len(draws) * len(drawn))
    for pair, seed in jobs:
        pairs = [pair] if pair is not None else [draw(base, f, seed) for f in drawn]
        for one in pairs:
            new, found = run_pair(one, seed, settings, baselines)
            rows += new
            kept += [(row, one, found[row.method]) for row in new
                     if row.method.startswith('ours') and _sheet_worthy(row)]
            bar.update()
    bar.close()
    return rows, kept


def _sheet_worthy(row: Row) -> bool:
    return row.verdict != 'correct'


def tally(rows: Sequence[Row]) -> dict[str, float]:
    """Return pairs, road pairs, published, correct, 1-5 px, wrong, precision and recall."""
    road = [r for r in rows if r.road_px >= MIN_ROAD_PX]
    verdicts = [r.verdict for r in rows]
    published = sum(r.published for r in rows)
    correct = verdicts.count('correct')
    errors = [r.error_px for r in rows if r.published and math.isfinite(r.error_px)]
    return {'pairs': len(rows), 'road': len(road), 'published': published,
            'correct': correct, 'mid': verdicts.count('1-5 px'),
            'wrong': verdicts.count('wrong') + verdicts.count('wrong (no road)'),
            'precision': correct / published if published else math.nan,
            'recall': correct / len(road) if road else math.nan,
            'median_px': float(np.median(errors)) if errors else math.nan}


def _pct(value: float) -> str:
    return '-' if math.isnan(value) else f'{100 * value:.0f} %'


def table(rows: Sequence[Row], key: str = 'family') -> list[str]:
    """Return the markdown table: one row per group (``family`` or photometric kind) and method."""
    lines = [f'| {key} | method | pairs | with road | published | correct | 1-5 px | wrong | '
             'precision | recall | median px |', '|' + '---|' * 11]
    groups: dict[str, list[Row]] = {}
    for row in rows:
        name = row.family if key == 'family' else row.detail.split('=')[0]
        groups.setdefault(name, []).append(row)
    for name, members in groups.items():
        for method in METHODS:
            chosen = [r for r in members if r.method == method]
            if not chosen:
                continue
            t = tally(chosen)
            median = '-' if math.isnan(t['median_px']) else f'{t["median_px"]:.2f}'
            lines.append(f'| {name} | {method} | {t["pairs"]} | {t["road"]} | '
                         f'{t["published"]} | {t["correct"]} | {t["mid"]} | {t["wrong"]} | '
                         f'{_pct(t["precision"])} | {_pct(t["recall"])} | {median} |')
    return lines


def refusals(rows: Sequence[Row]) -> list[str]:
    """Return the product's refusals on pairs with road, counted by reason (up to the colon)."""
    counts: dict[tuple[str, str], int] = {}
    for row in rows:
        if row.method.startswith('ours') and not row.published:
            where = 'with road' if row.road_px >= MIN_ROAD_PX else 'no road'
            reason = re.sub(r'-?\d+\.\d+', '#', row.reason.split(': ', 1)[-1].split(';')[0])
            key = (f'{row.method}, {where}', reason)
            counts[key] = counts.get(key, 0) + 1
    lines = ['| config, pair | reason | pairs |', '|---|---|---|']
    ordered = sorted(counts.items(), key=lambda item: (item[0][0], -item[1]))
    lines += [f'| {key[0]} | {key[1]} | {count} |' for key, count in ordered]
    return lines


def write_csv(path: Path, rows: Sequence[Row]) -> None:
    """Write one line per method and pair."""
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['family', 'seed', 'detail', 'method', 'road_px', 'published',
                         'error_px', 'verdict', 'reason', 'time_ms'])
        for r in rows:
            writer.writerow([r.family, r.seed, r.detail, r.method, r.road_px, int(r.published),
                             f'{r.error_px:.3f}', r.verdict, r.reason, f'{r.time_ms:.0f}'])


def error_tile(row: Row, pair: Perturbed, homography: np.ndarray | None,
               width: int = 620) -> np.ndarray:
    """Return the left image (BGR) with the road's pixels coloured by error and the verdict."""
    tile = cv2.cvtColor(pair.left, cv2.COLOR_GRAY2BGR)
    points = np.rint(pair.points).astype(int)
    if homography is not None and points.shape[0]:
        errors = pair.errors_px(homography)
        colours = np.where((errors < CORRECT_PX)[:, None], (0, 200, 0),
                           np.where((errors <= WRONG_PX)[:, None], (0, 220, 255),
                                    (0, 0, 255)))
        tile[points[:, 1], points[:, 0]] = colours
    elif points.shape[0]:
        tile[points[:, 1], points[:, 0]] = (255, 120, 0)  # refused: the road in blue
    scale = width / tile.shape[1]
    tile = cv2.resize(tile, (width, max(1, int(round(tile.shape[0] * scale)))),
                      interpolation=cv2.INTER_AREA)
    verdict = (f'{row.verdict} {row.error_px:.2f} px' if row.published
               and math.isfinite(row.error_px) else row.verdict)
    texts = [f'{row.family} seed {row.seed} {row.method}: {verdict}', row.detail[:95]]
    if homography is not None:
        texts.append(plane_note(homography, pair.left.shape))
    if row.reason:
        texts += [row.reason[i:i + 95] for i in range(0, min(len(row.reason), 190), 95)]
    band = np.full((16 * len(texts) + 4, width, 3), 255, np.uint8)
    for index, text in enumerate(texts):
        cv2.putText(band, text, (4, 14 + 16 * index), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([band, tile])


def plane_note(homography: np.ndarray, shape: tuple[int, int]) -> str:
    """Describe a plane by its disparity ``x - x'``: at the bottom centre, per row and its roll.

    The roll is ``atan((dd/dx) / (dd/dy))`` along the bottom row and the centre column: near
    0 for a ground plane of a level rig, the horizon's tilt otherwise.
    """
    rows, cols = shape

    def disparity(x: float, y: float) -> float:
        return x - float(apply_homography(homography, np.array([[x, y]]))[0, 0])

    bottom = disparity(cols / 2, rows - 1)
    per_row = (bottom - disparity(cols / 2, 0)) / max(1, rows - 1)
    per_col = (disparity(cols - 1, rows - 1) - disparity(0, rows - 1)) / max(1, cols - 1)
    roll = math.degrees(math.atan2(per_col, per_row))
    return (f'plane: disparity {bottom:.1f} px at the bottom centre, {per_row:+.4f} px per row, '
            f'roll {roll:+.0f} deg')


def write_sheet(path: Path, kept: Sequence[tuple[Row, Perturbed, np.ndarray | None]],
                tiles: int = SHEET_TILES) -> int:
    """Write every wrong plane, then the worst other draws, two columns; return the count."""
    def badness(item: tuple[Row, Perturbed, np.ndarray | None]) -> tuple[int, float]:
        row = item[0]
        rank = {'wrong (no road)': 3, 'wrong': 3, '1-5 px': 2, 'refused': 1}
        return rank.get(row.verdict, 0), row.error_px if math.isfinite(row.error_px) else 0.0
    ordered = sorted(kept, key=badness, reverse=True)
    wrong = [k for k in ordered if k[0].verdict.startswith('wrong')]
    chosen = wrong + [k for k in ordered if not k[0].verdict.startswith('wrong')][
        :max(0, tiles - len(wrong))]
    if not chosen:
        return 0
    images = [error_tile(*item) for item in chosen]
    height = max(i.shape[0] for i in images)
    images = [np.vstack([i, np.full((height - i.shape[0], i.shape[1], 3), 255, np.uint8)])
              for i in images]
    if len(images) % 2:
        images.append(np.full_like(images[0], 255))
    rows = [np.hstack(images[i:i + 2]) for i in range(0, len(images), 2)]
    cv2.imwrite(str(path), np.vstack(rows))
    return len(chosen)


def run_others(seeds: Sequence[int], folder: Path, out: Path) -> list[str]:
    """Run Aloe, books and graffiti (no ground plane) through the default ground mode.

    Each pair as it is and with each seed's photometric kind on the right camera; writes
    ``others_sheet.png`` (every plane published) and returns the table lines.
    """
    config = one_shot_search(PlaneNodeConfig())
    truth_graf = _graffiti_truth(folder)
    lines = ['| pair | change | published | inliers | graffiti wall error px | reason |',
             '|---|---|---|---|---|---|']
    tiles = []
    for name, left_file, right_file in progress(OTHER_PAIRS, 'others'):
        left, right = read_gray(folder / left_file), read_gray(folder / right_file)
        for seed in [-1, *seeds]:
            change, right_seen = 'none', right
            if seed >= 0:
                kind = PHOTOMETRIC_KINDS[seed % len(PHOTOMETRIC_KINDS)]
                rng = np.random.default_rng((seed, 99))
                value = draw_value(kind, rng)
                right_seen = photometric(right, kind, value, rng)
                change = f'{kind}={value:.2f} on right'
            result = PlanePipeline(config).process(left, right_seen, 0)
            wall = '-'
            if result.ok and name == 'graffiti' and truth_graf is not None:
                grid = np.stack(np.meshgrid(np.arange(0, left.shape[1], 16),
                                            np.arange(0, left.shape[0], 16)), -1).reshape(-1, 2)
                grid = grid.astype(np.float64)
                apart = (apply_homography(result.homography, grid)
                         - apply_homography(truth_graf, grid))
                wall = f'{np.mean(np.linalg.norm(apart, axis=1)):.2f}'
            lines.append(f'| {name} | {change} | {"yes" if result.ok else "no"} | '
                         f'{result.n_inliers if result.ok else "-"} | {wall} | '
                         f'{(result.reason or "")[:120]} |')
            if result.ok:
                rgb = overlay(left, result.mask)
                small = cv2.resize(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), (480, int(
                    480 * left.shape[0] / left.shape[1])), interpolation=cv2.INTER_AREA)
                cv2.putText(small, f'{name} {change}: {result.n_inliers} inliers', (4, 16),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 255, 255), 1, cv2.LINE_AA)
                tiles.append(small)
    if tiles:
        height = max(t.shape[0] for t in tiles)
        tiles = [np.vstack([t, np.zeros((height - t.shape[0], 480, 3), np.uint8)])
                 for t in tiles]
        while len(tiles) % 3:
            tiles.append(np.zeros_like(tiles[0]))
        cv2.imwrite(str(out / 'others_sheet.png'),
                    np.vstack([np.hstack(tiles[i:i + 3]) for i in range(0, len(tiles), 3)]))
    return lines


def _graffiti_truth(folder: Path) -> np.ndarray | None:
    path = folder / 'H1to3p.xml'
    if not path.exists():
        return None
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    matrix = storage.getNode('H13').mat()
    storage.release()
    return None if matrix is None else matrix / matrix[2, 2]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation, print and write its summary; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--draws', type=int, default=24, help='draws (seeds) per family')
    parser.add_argument('--first-seed', type=int, default=0,
                        help='first seed (0 on; 16000-16999 are held out, never use them)')
    parser.add_argument('--out', type=Path, default=Path('eval_output/real_rigs'))
    parser.add_argument('--no-baselines', action='store_true',
                        help='skip ORB + MAGSAC++ and SIFT + MAGSAC++')
    parser.add_argument('--others', action='store_true',
                        help='also run Aloe, books and graffiti with the photometric changes')
    parser.add_argument('--families', default=','.join((*DRAW_FAMILIES, FIXED)),
                        help='comma list of the draw families to run and "fixed" for the '
                        'fixed pairs (default: all)')
    args = parser.parse_args(argv)
    families = [f.strip() for f in args.families.split(',') if f.strip()]
    unknown = sorted(set(families) - {*DRAW_FAMILIES, FIXED})
    if unknown:
        parser.error(f'unknown families {unknown}; choose from {(*DRAW_FAMILIES, FIXED)}')
    seeds = list(range(args.first_seed, args.first_seed + args.draws))
    if any(16000 <= s <= 16999 for s in seeds):
        parser.error('seeds 16000-16999 are held out')
    args.out.mkdir(parents=True, exist_ok=True)
    with one_core():
        rows, kept = evaluate(seeds, kitti_base(), not args.no_baselines, families)
        others = (run_others(seeds[:len(PHOTOMETRIC_KINDS)], default_data_dir() / OPENCV_DIR,
                             args.out) if args.others else [])
    write_csv(args.out / 'draws.csv', rows)
    shown = write_sheet(args.out / 'sheet.png', kept)
    photo = [r for r in rows if r.family == 'photometric']
    lines = [f'machine: {machine_name()}',
             f'KITTI 2015 000046, draws: seeds {seeds[0]}..{seeds[-1]} per family '
             f'({", ".join(families)}); configs: '
             'documented default prior and KITTI_PRIOR, whole image; correct < 1 px, wrong > '
             '5 px (or any plane where the window has no road)', '',
             *table(rows), '', 'photometric, by kind:', '', *table(photo, key='kind'), '',
             "the product's refusals:", '', *refusals(rows), '',
             f'sheet.png: {shown} tiles (every wrong plane, then the worst other draws)']
    if others:
        lines += ['', 'Aloe, books, graffiti (no ground plane), default ground mode:', '',
                  *others]
    text = '\n'.join(lines)
    print(text)
    (args.out / 'summary.md').write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
