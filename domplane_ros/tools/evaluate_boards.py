"""Non-ground dominant planes: wrong planes published, precision and recall per plane mode.

Run ``python -m domplane_ros.tools.evaluate_boards [--pairs 40] [--held-out] [--chessboards]
[--lens] [--small]``.
Rendered boards and walls in front of the head (:func:`~domplane_ros.sim.boards.board_scene`:
tilted up to 30 degrees both ways, noise, checker and tile textures, clutter behind), one
pair per seed, a fresh :class:`~domplane_ros.stream.pipeline.PlanePipeline` and the whole
search in that pair, with ``verification.plane`` ``ground`` (the default) and ``any``. The
prior is the evaluation's ``CHESSBOARD_PRIOR`` (a plane facing the head: tilt 45-89 degrees,
rough focal and baseline ranges), the same for every seed, never set from a scene's truth.
``--lens`` renders the boards through radial lenses (the truth is then the least-squares
homography of the board's true correspondences), ``--small`` small boards in a textured room.

A published plane is *correct* when its mean transfer error over the visible board is below
1 px, *wrong* when above 5 px. Precision = correct / published; recall = correct / pairs.
Tuning seeds are 0-129 (``--first-seed`` below 1000); ``--held-out`` uses seeds from 1000, run
once for the report; ``--first-seed 2000`` a second held-out range.

``--chessboards`` also runs the OpenCV chessboard pairs of ``--data``/opencv_samples (the
check, not a tuning set): per pair the error against the homography fitted to the board's
inner corners, or the reason nothing was published.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
import sys
import time
from typing import Sequence

from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.core.homography import fit_homography
from domplane_ros.sim.boards import board_scene, BOARD_TEXTURES
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import machine_name, one_core, progress, tool_parser
from domplane_ros.tools.evaluation.datasets import CHESSBOARD_PRIOR, CHESSBOARD_TARGET_PX
from domplane_ros.tools.evaluation.references import (chessboards, default_data_dir,
                                                      mean_transfer_px, OPENCV_DIR)

CORRECT_PX = 1.0
WRONG_PX = 5.0
MODES = ('ground', 'any')


def board_config(plane: str, min_score: float | None = None) -> PlaneNodeConfig:
    """Return the evaluation's configuration for ``verification.plane`` ``plane``."""
    config = PlaneNodeConfig(prior=CHESSBOARD_PRIOR)  # as datasets.evaluate_chessboards
    verification = replace(config.verification, plane=plane)
    if min_score is not None:
        verification = replace(verification, min_score=min_score)
    return one_shot_search(replace(config, verification=verification))


def _row(case: str, mode: str, errors: list[float | None]) -> str:
    published = [e for e in errors if e is not None]
    correct = sum(e < CORRECT_PX for e in published)
    wrong = sum(e > WRONG_PX for e in published)
    precision = f'{100 * correct / len(published):.0f} %' if published else '-'
    worst = f'{max(published):.1f}' if published else '-'
    return (f'| {case} | {mode} | {len(errors)} | {len(published)} | {correct} | {wrong} | '
            f'{precision} | {100 * correct / max(len(errors), 1):.0f} % | {worst} |')


def rendered_rows(seeds: Sequence[int], modes: Sequence[str] = MODES,
                  min_score: float | None = None, lens: bool = False,
                  small: bool = False) -> list[str]:
    """Return the table rows of the rendered boards, per texture and mode, and the totals.

    ``lens``, ``small``: the boards seen through radial lenses, small boards in a textured
    room (:func:`~domplane_ros.sim.boards.board_scene`).
    """
    errors: dict[tuple[str, str], list[float | None]] = {}
    for seed in progress(seeds, 'boards'):
        frame = board_scene(seed, lens=lens, small=small)
        for mode in modes:
            config = board_config(mode, min_score)
            result = PlanePipeline(config).process(frame.left, frame.right, 0)
            error = plane_error_px(frame, result.homography) if result.ok else None
            errors.setdefault((frame.floor, mode), []).append(error)
            if error is not None and error > WRONG_PX:
                print(f'seed {seed} ({frame.floor}, {mode}): wrong plane {error:.1f} px',
                      file=sys.stderr)
    rows = [_row(kind, mode, errors.get((kind, mode), []))
            for mode in modes for kind in BOARD_TEXTURES]
    rows += [_row('all', mode, [e for (_, m), v in errors.items() if m == mode for e in v])
             for mode in modes]
    return rows


def chessboard_lines(folder: Path, modes: Sequence[str] = MODES,
                     min_score: float | None = None) -> list[str]:
    """Return one line per chessboard pair and mode: the error or why nothing was published."""
    lines = []
    for number, left, right, src, dst in chessboards(folder):
        fit_homography(src, dst)  # the reference is fitted; a failure raises
        for mode in modes:
            start = time.perf_counter()
            result = PlanePipeline(board_config(mode, min_score)).process(left, right, 0)
            ms = 1e3 * (time.perf_counter() - start)
            if result.ok:
                error = mean_transfer_px(result.homography, src, dst)
                verdict = ('correct' if error < CHESSBOARD_TARGET_PX else
                           'WRONG' if error > WRONG_PX else 'off')
                text = f'{error:.2f} px ({verdict})'
            else:
                text = f'refused: {result.reason[:110]}'
            lines.append(f'{number} {mode}: {text} [{ms:.0f} ms]')
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation and print its table; return the exit code."""
    parser = tool_parser(__doc__)
    parser.add_argument('--pairs', type=int, default=40, help='rendered seeds')
    parser.add_argument('--held-out', action='store_true', help='seeds from 1000')
    parser.add_argument('--first-seed', type=int, default=None,
                        help='first seed (overrides --held-out; 2000 on: a second held-out '
                        'range)')
    parser.add_argument('--chessboards', action='store_true',
                        help='also run the OpenCV chessboard pairs')
    parser.add_argument('--data', type=Path, default=default_data_dir())
    parser.add_argument('--modes', nargs='+', choices=MODES, default=list(MODES),
                        help='verification.plane values run')
    parser.add_argument('--min-score', type=float, default=None,
                        help='verification.min_score (default: the parameter default)')
    parser.add_argument('--lens', action='store_true',
                        help='the rendered boards seen through radial lenses (k1)')
    parser.add_argument('--small', action='store_true',
                        help='small rendered boards (15-40 %% of the image) in a textured room')
    args = parser.parse_args(argv)
    first = 1000 if args.held_out else 0
    if args.first_seed is not None:
        first = args.first_seed
    seeds = list(range(first, first + args.pairs))
    with one_core():
        rows = (rendered_rows(seeds, args.modes, args.min_score, args.lens, args.small)
                if args.pairs > 0 else [])
        boards = (chessboard_lines(args.data / OPENCV_DIR, args.modes, args.min_score)
                  if args.chessboards else [])
    print(f'machine: {machine_name()}')
    if rows:
        score = 'default' if args.min_score is None else f'{args.min_score:g}'
        kinds = [name for name, on in (('lens', args.lens), ('small', args.small)) if on]
        boards_kind = ', '.join(kinds or ['plain'])
        kind = 'held out' if first >= 1000 else 'tuning'
        print(f'seeds {seeds[0]}..{seeds[-1]} ({kind}); boards: {boards_kind}; prior: '
              f'CHESSBOARD_PRIOR; verification.min_score {score}; correct < 1 px, wrong > 5 px'
              '\n')
        print('| texture | verification.plane | pairs | published | correct | wrong | '
              'precision | recall | worst px |\n' + '|---' * 9 + '|')
        print('\n'.join(rows))
    if boards:
        print('\nchessboards (target < 2 px):\n' + '\n'.join(boards))
    return 0


if __name__ == '__main__':
    sys.exit(main())
