"""Evaluation on real stereo pairs and rendered scenes, beside an ORB + MAGSAC baseline.

Run ``python -m domplane_ros.tools.evaluate [--data DIR] [--out DIR] [--scenes N]``. Every data set
gets one table with two rows per pair or summary: the product (:class:`PlanePipeline`, cold
start from the data set's prior, and warm-started on the same pair) and a correspondence
baseline run in the same process on the same grey images: OpenCV ORB (2000 features),
brute-force Hamming matching with cross-check and ``cv2.findHomography`` with
``cv2.USAC_MAGSAC``. Both are single-threaded (BLAS and OpenCV pinned to one thread) and timed
as the median of a few repetitions. The baseline's error is computed exactly like ours.

Data sets (folders under ``--data``, as in ``../shared/data``; missing ones are skipped):

* ``kitti2015_000046``: the reference road homography comes from the ground-truth disparity
  (:func:`fit_disparity_plane`); road pixels are ground-truth pixels within 1 px of that
  plane, off-road pixels those farther than 3 px. Reported: mean transfer error on the road
  pixels, the mask's IoU with the road and its recall of off-road pixels (both over the road
  and off-road pixels).
* ``opencv_samples/leftNN.jpg, rightNN.jpg``: the reference is the 9 x 6 chessboard corners
  found in both images. Reported: the mean transfer error on the board corners
  (``||H(left_i) - right_i||``) and, as the floor set by lens distortion, the same error of the
  homography fitted to the corners.
* ``opencv_samples/left.jpg, right.jpg`` (books) and ``ensenso_fit_primitive``: no reference;
  inlier counts, mask coverage and how far apart the two methods' homographies are.
* Rendered scenes (:func:`domplane_ros.sim.generators.random_scene`): solved share (mean
  transfer error on the visible floor < 1 px), errors, mask scores and times, overall and per
  floor kind.
* Rendered sequences (:func:`domplane_ros.sim.generators.scene_sequence`): the warm start as
  the node uses it, from the previous frame rather than from the same pair.

Outputs: the tables on stdout and in ``summary.md``, one CSV per data set,
``contact_sheet.png`` (left images with the product's mask) and ``errors.png`` (errors and
times, ours vs baseline) in ``--out`` (default ``eval_output/``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
from typing import Callable

from domplane_ros.sim.generators import RENDERED_PRIOR
from domplane_ros.tools.common import add_output_argument, machine_name, one_core, tool_parser
from domplane_ros.tools.evaluation.datasets import (BOOKS_PRIOR, Case, CHESSBOARD_PRIOR,
                                                    ENSENSO_PRIOR, evaluate_books,
                                                    evaluate_chessboards, evaluate_ensenso,
                                                    evaluate_kitti, evaluate_rendered,
                                                    evaluate_streams, KITTI_PRIOR, KITTI_ROI)
from domplane_ros.tools.evaluation.methods import ORB_FEATURES, ORB_THRESHOLD_PX
from domplane_ros.tools.evaluation.plots import contact_sheet, error_plot, pick_rendered
from domplane_ros.tools.evaluation.references import (default_data_dir, ENSENSO_DIR,
                                                      ENSENSO_STEM, KITTI_DIR, OPENCV_DIR,
                                                      SHARED_DATA, TEST_DATA)
from domplane_ros.tools.evaluation.tables import (chessboard_table, kitti_table, prior_text,
                                                  qualitative_table, rendered_table, speed_line,
                                                  targets, write_csv)

Emit = Callable[[str], None]


def _parser() -> argparse.ArgumentParser:
    parser = tool_parser(__doc__)
    parser.add_argument('--data', type=Path, default=None,
                        help=f'data folder (default: {SHARED_DATA} if it exists, else '
                             f'{TEST_DATA})')
    add_output_argument(parser, 'eval_output', 'the CSVs and pictures')
    parser.add_argument('--scenes', type=int, default=100, help='rendered scenes (0: none)')
    parser.add_argument('--sequences', type=int, default=3,
                        help='rendered sequences of 10 frames for the frame-to-frame warm start '
                             '(0: none)')
    parser.add_argument('--repeats', type=int, default=3,
                        help='timing repetitions per real pair (rendered scenes: 1)')
    parser.add_argument('--no-pictures', action='store_true',
                        help='skip the contact sheet and the error plot')
    return parser


def _real_data(data: Path, repeats: int) -> list[tuple[str, Path, Callable[[], list[Case]], str]]:
    """Return ``(name, marker file, evaluation, prior text)`` of every real data set."""
    opencv = data / OPENCV_DIR
    return [
        ('kitti', data / KITTI_DIR / 'disp_occ_left.png',
         lambda: evaluate_kitti(data / KITTI_DIR, repeats), prior_text(KITTI_PRIOR, KITTI_ROI)),
        ('chessboards', opencv / 'left01.jpg',
         lambda: evaluate_chessboards(opencv, repeats),
         prior_text(CHESSBOARD_PRIOR) + ', verification.plane any'),
        ('books', opencv / 'left.jpg', lambda: evaluate_books(opencv, repeats),
         prior_text(BOOKS_PRIOR)),
        ('ensenso', data / ENSENSO_DIR / f'{ENSENSO_STEM}_left.png',
         lambda: evaluate_ensenso(data / ENSENSO_DIR, repeats), prior_text(ENSENSO_PRIOR)),
    ]


def _run_real(data: Path, out: Path, repeats: int, groups: dict[str, list[Case]],
              emit: Emit) -> None:
    """Evaluate the real data sets found in ``data``: tables, speed lines, CSVs."""
    tables = {'kitti': kitti_table, 'chessboards': chessboard_table}
    for name, marker, job, text in _real_data(data, repeats):
        if not marker.exists():
            emit(f'\n## {name}: not in {data}, skipped')
            continue
        cases = job()
        for case in cases:
            groups.setdefault(case.dataset, []).append(case)
        emit(f'\n## {name}\n{text}')
        emit(tables.get(name, qualitative_table)(cases))
        for dataset in dict.fromkeys(c.dataset for c in cases):
            emit(speed_line(dataset, [c for c in cases if c.dataset == dataset]))
        write_csv(out / f'{name}.csv', cases)


def _run_rendered(n_scenes: int, out: Path, groups: dict[str, list[Case]], emit: Emit) -> None:
    """Evaluate ``n_scenes`` rendered scenes (cold starts)."""
    cases = evaluate_rendered(n_scenes)
    groups['rendered'] = cases
    emit(f'\n## rendered scenes (seeds 0..{n_scenes - 1}, random_scene defaults)\n'
         f"{prior_text(RENDERED_PRIOR)} (= generators.SETUP_RANGES, the scenes' range)")
    emit(rendered_table(cases))
    emit(speed_line('rendered', cases))
    write_csv(out / 'rendered.csv', cases)


def _run_streams(n_sequences: int, out: Path, groups: dict[str, list[Case]],
                 emit: Emit) -> None:
    """Evaluate ``n_sequences`` rendered sequences frame to frame (warm starts)."""
    cases = evaluate_streams(n_sequences)
    groups['rendered_stream'] = cases
    emit(f'\n## rendered sequences, frame to frame (seeds 0..{n_sequences - 1}, '
         f'scene_sequence(10, seed); frames 1-9, each warm-started from the previous one)'
         f'\n{prior_text(RENDERED_PRIOR)} (first frames only)')
    emit(rendered_table(cases))
    reinit = sum(c.info['reinitialised'] for c in cases)
    emit(f're-initialisations from the prior after the first frame: {reinit}')
    emit(speed_line('rendered_stream', cases))
    write_csv(out / 'rendered_stream.csv', cases)


def _pictures(out: Path, groups: dict[str, list[Case]], emit: Emit) -> None:
    """Write the contact sheet and the error plot."""
    sheet = (groups.get('kitti', []) + groups.get('chessboards', [])[:3]
             + groups.get('books', []) + groups.get('ensenso', [])
             + pick_rendered(groups.get('rendered', [])))
    contact_sheet(out / 'contact_sheet.png', sheet)
    error_plot(out / 'errors.png', groups)
    emit(f'\npictures: {out / "contact_sheet.png"}, {out / "errors.png"}')


def main(argv: list[str] | None = None) -> int:
    """Run the evaluation, print the tables and write the CSVs and pictures."""
    args = _parser().parse_args(argv)
    data = args.data if args.data is not None else default_data_dir()
    args.out.mkdir(parents=True, exist_ok=True)
    report: list[str] = []

    def emit(text: str) -> None:
        print(text, flush=True)
        report.append(text)

    emit(f'machine: {machine_name()}')
    emit(f'data: {data.resolve()}{" (default)" if args.data is None else ""}; '
         f'output: {args.out.resolve()}')
    emit(f'baseline: ORB {ORB_FEATURES} features per image, BFMatcher Hamming cross-check, '
         f'findHomography USAC_MAGSAC {ORB_THRESHOLD_PX:g} px; its mask (not timed) comes from '
         f"the product's mask stage. Times: median of {args.repeats} runs, 1 thread; ours "
         f'= whole PlanePipeline.process (features, estimate, mask), cold = prior search, '
         f'warm = same pair again.')
    groups: dict[str, list[Case]] = {}
    with one_core():
        _run_real(data, args.out, args.repeats, groups, emit)
        if args.scenes > 0:
            _run_rendered(args.scenes, args.out, groups, emit)
        if args.sequences > 0:
            _run_streams(args.sequences, args.out, groups, emit)
    emit('\n## targets')
    emit('\n'.join(targets(groups)))
    (args.out / 'summary.md').write_text('\n'.join(report) + '\n', encoding='utf-8')
    if not args.no_pictures and groups:
        _pictures(args.out, groups, emit)
    return 0


if __name__ == '__main__':
    sys.exit(main())
