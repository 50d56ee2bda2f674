"""Why the chessboard pairs get no plane: the board's true plane before the product's gate.

Run ``python -m domplane_ros.tools.diagnose_chessboards [--data DIR] [--out DIR]``. For every
``leftNN.jpg`` / ``rightNN.jpg`` pair of ``DIR/opencv_samples`` whose board is found in both
images, the reference homography is fitted to the board's inner corners (as
:func:`~domplane_ros.tools.evaluation.datasets.evaluate_chessboards` does) and printed with:

* the verification gate's verdict on it (:meth:`~domplane_ros.stream.trust.TrustGate.judge`):
  its disparity slope (the swap and ground check), score and reason;
* the best score of its look-alikes one board square off (the truth moved by one square in
  the right image, either way along both board axes);
* the nearest of the evaluation's prior candidates (``CHESSBOARD_PRIOR``), mean corner error;
* the product's cold start on the pair (error or reason).

It draws ``chessboards.jpg`` (the left images, the board corners, the gate's verdict on the
truth). Nothing of the reference is given to the product.
"""

from __future__ import annotations

from pathlib import Path
import sys

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.core.ground_slope import swap_evidence
from domplane_ros.core.homography import fit_homography
from domplane_ros.core.prior import prior_candidates
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import Verdict
from domplane_ros.tools.common import tool_parser
from domplane_ros.tools.evaluation.datasets import CHESSBOARD_PRIOR
from domplane_ros.tools.evaluation.references import (CHESSBOARD_PATTERN, chessboards,
                                                      default_data_dir, mean_transfer_px,
                                                      OPENCV_DIR)
import numpy as np

TILE = (320, 240)


def _look_alikes(gate: TrustGate, left: np.ndarray, right: np.ndarray, truth: np.ndarray,
                 dst: np.ndarray) -> float:
    """Return the best score of the truth moved by one board square in the right image."""
    grid = dst.reshape(CHESSBOARD_PATTERN[1], CHESSBOARD_PATTERN[0], 2)
    along = np.median(grid[:, 1:] - grid[:, :-1], axis=(0, 1))
    down = np.median(grid[1:] - grid[:-1], axis=(0, 1))
    scores = []
    for d in (along, -along, down, -down):
        moved = np.array([[1.0, 0.0, d[0]], [0.0, 1.0, d[1]], [0.0, 0.0, 1.0]]) @ truth
        scores.append(gate.judge(left, right, moved).score)
    return max(scores)


def _why(verdict: Verdict) -> str:
    if verdict.accepted:
        return 'accepted'
    if verdict.swapped:
        return 'refused: swapped?'
    if not verdict.ground:
        return 'refused: no ground'
    return 'refused: score'


def _tile(left: np.ndarray, src: np.ndarray, lines: list[str], accepted: bool) -> np.ndarray:
    image = cv2.cvtColor(left, cv2.COLOR_GRAY2BGR)
    for x, y in src:
        cv2.circle(image, (int(round(x)), int(round(y))), 3, (0, 255, 0), -1)
    cv2.rectangle(image, (0, 0), (image.shape[1], 100), (0, 0, 0), -1)
    colour = (0, 255, 0) if accepted else (0, 255, 255)
    for i, text in enumerate(lines):
        cv2.putText(image, text, (8, 30 + 30 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.9, colour, 2)
    return cv2.resize(image, TILE, interpolation=cv2.INTER_AREA)


def diagnose(folder: Path) -> tuple[list[str], list[np.ndarray]]:
    """Return one printed line and one picture tile per chessboard pair of ``folder``."""
    config = one_shot_search(PlaneNodeConfig(prior=CHESSBOARD_PRIOR))
    lines, tiles = [], []
    for number, left, right, src, dst in chessboards(folder, report_skipped=True):
        truth = fit_homography(src, dst)
        gate = TrustGate(config.verification)
        verdict = gate.judge(left, right, truth)
        slope = swap_evidence(truth, left.shape[1], left.shape[0]).disparity_slope
        look = _look_alikes(gate, left, right, truth, dst)
        nearest = min(mean_transfer_px(h, src, dst)
                      for h in prior_candidates(config.prior, left.shape[1], left.shape[0]))
        result = PlanePipeline(config).process(left, right, 0)
        product = (f'{mean_transfer_px(result.homography, src, dst):.2f} px' if result.ok
                   else f'refused ({result.reason[:70]})')
        lines.append(f'{number}: truth slope {slope:+.3f} score {verdict.score:.3f} '
                     f'{_why(verdict)}; one square off {look:.3f}; prior nearest '
                     f'{nearest:.1f} px; product {product}')
        tiles.append(_tile(left, src, [f'pair {number}: truth {_why(verdict)}',
                                       f'slope {slope:+.3f} score {verdict.score:.2f}',
                                       f'1 square off: {look:.2f}'], verdict.accepted))
    return lines, tiles


def main(argv: list[str] | None = None) -> int:
    """Print the diagnosis and write the picture; see the module docstring."""
    parser = tool_parser(__doc__)
    parser.add_argument('--data', type=Path, default=default_data_dir())
    parser.add_argument('--out', type=Path, default=Path('eval_output'))
    args = parser.parse_args(argv)
    lines, tiles = diagnose(args.data / OPENCV_DIR)
    print('\n'.join(lines))
    if not tiles:
        print('no chessboard pair found', file=sys.stderr)
        return 1
    while len(tiles) % 5:
        tiles.append(np.zeros_like(tiles[0]))
    sheet = np.vstack([np.hstack(tiles[i:i + 5]) for i in range(0, len(tiles), 5)])
    args.out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out / 'chessboards.jpg'), sheet, [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(f'wrote {args.out / "chessboards.jpg"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
