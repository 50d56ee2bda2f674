"""plane_pair: find the dominant plane in stereo image files, without ROS or a bag.

::

    plane_pair LEFT RIGHT [--params-file config/plane_node.yaml]
               [--focal-px MIN MAX] [--baseline-over-height MIN MAX] [--tilt-deg MIN MAX]
               [--vergence-deg MIN MAX] [--roi X0 Y0 X1 Y1] [--out DIR] [--force] [--fps HZ]

LEFT and RIGHT are two image files, or two folders of frames paired by sorted file name. Every
pair goes through the node's :class:`~domplane_ros.stream.pipeline.PlanePipeline` with the
whole prior search in one pair (:func:`~domplane_ros.config.one_shot_search`); the frames of
two folders are one stream (each warm-starts from the last, as live), ``--fps`` apart.

For each pair it prints the left-to-right homography (3x3, ``H[2][2] == 1``), the lock state,
the verification confidence and, without a plane, the reason (the node's reason, whose hint
for swapped cameras names the LEFT and RIGHT arguments instead of the image topics).
``--out DIR`` writes ``NAME_overlay.png`` (the left image with the mask tint, the corners and
a legend) and ``NAME_mask.png`` (mono8: 255 plane, 127 obstacle, 0 undecided, as
``plane/mask``) per pair. 16-bit image files are scaled by ``image.mono16_bits`` (from
``--params-file``) as the node scales mono16 messages.

Exit codes: 0 when every pair gave a plane; 4 when every pair was processed but at least one
gave none (the reason is printed); 3 when pairs of two folders could not be read and were
skipped (named on stderr); 2 when the run is refused before anything is written (a missing
file, a file that is not an image, images of two sizes, folders with different numbers of
images, an invalid params file or range, existing outputs without ``--force``); 1 when
writing an output fails; 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
import os
from pathlib import Path
import sys
import tempfile
from typing import Sequence

import cv2
from domplane_ros.config import (check_value, ConfigError, one_shot_search, PARAMETERS_BY_NAME,
                                 PlaneNodeConfig)
from domplane_ros.core.legend import with_legend
from domplane_ros.pair.files import image_pairs, ImagePair, PairInputError, read_pair
from domplane_ros.params_file import load_params_file, node_name_hint
from domplane_ros.stream.frame import debug_overlay, FrameResult
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.status import reason_for_arguments
import numpy as np

PROG = 'plane_pair'

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_REFUSED = 2
EXIT_SKIPPED = 3
EXIT_NO_PLANE = 4
EXIT_INTERRUPTED = 130

# The first pair's stamp (any positive time; pairs of a folder follow --fps apart).
_STAMP0_NS = 1_000_000_000
# Command-line options that set a parameter of the table: option -> parameter name.
RANGE_OPTIONS = {'focal_px': 'prior.focal_px',
                 'baseline_over_height': 'prior.baseline_over_height',
                 'tilt_deg': 'prior.tilt_deg', 'vergence_deg': 'prior.vergence_deg',
                 'roi': 'features.roi'}


@dataclass(frozen=True)
class PairOutcome:
    """What one pair gave.

    Attributes:
        pair: The image files.
        result: The pipeline's result (None if the pair could not be read).
        error: Why the pair could not be read ('' if it was).
        written: Files written for it.

    """

    pair: ImagePair
    result: FrameResult | None
    error: str = ''
    written: tuple[Path, ...] = ()


def configure(params_file: str | None = None,
              overrides: dict[str, Sequence[float]] | None = None,
              node_name: str = 'plane_node') -> PlaneNodeConfig:
    """Return the configuration of a run: a params file's (or the defaults), then overrides.

    Args:
        params_file: ROS 2 parameters YAML file (``/**:``, ``plane_node:``), or None.
        overrides: Parameter name (``prior.focal_px``, ``features.roi``, ...) to value.
        node_name: The node whose blocks of the file are read (a renamed node's name).

    Returns:
        The validated configuration, with the whole prior search in one pair.

    Raises:
        ConfigError: If the file or a value is invalid (the message names the parameter).

    """
    config = (load_params_file(params_file, node_name) if params_file
              else PlaneNodeConfig())
    for name, value in (overrides or {}).items():
        checked = check_value(PARAMETERS_BY_NAME[name], list(value))
        section, field = name.split('.')
        part = replace(getattr(config, section), **{field: tuple(checked)})
        config = replace(config, **{section: part})
    return one_shot_search(config)


def output_paths(out: Path, pair: ImagePair) -> tuple[Path, Path]:
    """Return the overlay and mask PNG paths of a pair in ``out``."""
    return out / f'{pair.name}_overlay.png', out / f'{pair.name}_mask.png'


def run_pairs(pairs: Sequence[ImagePair], config: PlaneNodeConfig, out: Path | None = None,
              fps: float = 10.0) -> list[PairOutcome]:
    """Run the pipeline over the pairs in order, as one stream, and write the pictures.

    Args:
        pairs: The pairs (from :func:`~domplane_ros.pair.files.image_pairs`).
        config: The configuration (see :func:`configure`).
        out: Folder for the overlay and mask PNGs, or None.
        fps: Frame rate of the stream, for the pairs' stamps.

    Returns:
        One outcome per pair; a pair that cannot be read has ``result`` None and its error.

    Raises:
        OSError: If a PNG cannot be written.

    """
    pipeline = PlanePipeline(config)
    period_ns = int(round(1e9 / fps))
    outcomes = []
    for index, pair in enumerate(pairs):
        try:
            left, right, image_warning = read_pair(pair, config.image.mono16_bits)
        except PairInputError as err:
            outcomes.append(PairOutcome(pair, None, str(err)))
            continue
        result = pipeline.process(left, right, _STAMP0_NS + index * period_ns)
        if image_warning:
            result = replace(result, warnings=(image_warning, *result.warnings))
        written: tuple[Path, ...] = ()
        if out is not None:
            written = _write_pictures(out, pair, left, result)
        outcomes.append(PairOutcome(pair, result, written=written))
    return outcomes


def _write_pictures(out: Path, pair: ImagePair, left: np.ndarray,
                    result: FrameResult) -> tuple[Path, Path]:
    overlay_path, mask_path = output_paths(out, pair)
    picture = with_legend(debug_overlay(left, result), title=pair.name,
                          caption=_summary(result))
    _write_png(overlay_path, cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    _write_png(mask_path, result.mask)
    return overlay_path, mask_path


def _write_png(path: Path, image: np.ndarray) -> None:
    """Write a PNG through a temporary file, so a failed write leaves no half file."""
    ok, data = cv2.imencode('.png', image)
    if not ok:
        raise OSError(f'cannot encode {str(path)!r} as PNG')
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as stream:
            stream.write(data.tobytes())
        os.chmod(tmp, 0o666 & ~_umask())   # as open() would make it, not mkstemp's 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _summary(result: FrameResult) -> str:
    corners = result.left_points.shape[0]
    if result.ok:
        return (f'plane found: state {result.state}, confidence {result.confidence:.2f}, '
                f'{result.n_inliers} of {corners} left corners matched on the plane')
    return (f'no plane: state {result.state}, confidence {result.confidence:.2f}; '
            f'{reason_for_arguments(result.reason)}')


def format_outcome(outcome: PairOutcome) -> list[str]:
    """Return the lines printed for one pair."""
    if outcome.result is None:
        return [f'{outcome.pair.name}: skipped: {outcome.error}']
    result = outcome.result
    lines = [f'{outcome.pair.name}: {_summary(result)} '
             f'({result.timings_ms.get("total", 0.0):.0f} ms)']
    if result.homography is not None:
        rows = [', '.join(f'{v:14.8g}' for v in row) for row in result.homography]
        lines.append(f'  H = [[{rows[0]}],')
        lines.append(f'       [{rows[1]}],')
        lines.append(f'       [{rows[2]}]]')
    lines += [f'  warning: {text}' for text in result.warnings]
    lines += [f'  wrote {path}' for path in outcome.written]
    return lines


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of plane_pair."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Find the dominant plane (floor, road) in a stereo pair of image files, '
                    'or in two folders of frames paired by sorted name, with the pipeline of '
                    'plane_node and the whole prior search; print the left-to-right '
                    'homography, the lock state, the confidence and the reason.',
        epilog='Exit codes: 0 every pair gave a plane; 4 a pair gave none; 3 pairs that could '
               'not be read were skipped; 2 refused (nothing written); 1 writing failed; '
               '130 Ctrl-C.')
    parser.add_argument('left', metavar='LEFT', help='left image file, or folder of frames')
    parser.add_argument('right', metavar='RIGHT', help='right image file, or folder of frames')
    parser.add_argument('--params-file', metavar='YAML',
                        help='ROS 2 parameters file with a "/**:" or "plane_node:" '
                             "ros__parameters block (default: the node's defaults)")
    parser.add_argument('--node-name', default='plane_node', metavar='NAME',
                        help='read the blocks of --params-file for this node name, as '
                             "'-r __node:=NAME' renames the node (default: %(default)s)")
    for option, metavar, what in (
            ('focal_px', ('MIN', 'MAX'), 'focal length range in pixels, '
                                         'f = (W/2)/tan(HFOV/2)'),
            ('baseline_over_height', ('MIN', 'MAX'), 'camera baseline / height above the '
                                                     'plane'),
            ('tilt_deg', ('MIN', 'MAX'), 'downward tilt of the cameras from horizontal, deg'),
            ('vergence_deg', ('MIN', 'MAX'), 'toe-in between the two cameras, deg'),
            ('roi', ('X0', 'Y0', 'X1', 'Y1'), 'left-image region for features, fractions of '
                                              'width and height')):
        parser.add_argument('--' + option.replace('_', '-'), dest=option, nargs=len(metavar),
                            type=float, metavar=metavar,
                            help=f'{what} (sets {RANGE_OPTIONS[option]})')
    parser.add_argument('--out', metavar='DIR',
                        help='write NAME_overlay.png and NAME_mask.png for each pair to DIR')
    parser.add_argument('--force', action='store_true',
                        help='replace existing PNGs in --out')
    parser.add_argument('--fps', type=float, default=10.0,
                        help='frame rate of two folders of frames (default: %(default)s)')
    return parser


def _error(message: str) -> None:
    print(f'{PROG}: error: {" ".join(message.split())}', file=sys.stderr)


def _prepare(args: argparse.Namespace) -> tuple[list[ImagePair], PlaneNodeConfig,
                                                Path | None]:
    """Check everything that can be checked before a pair is processed.

    Raises:
        PairInputError: On bad files or outputs.
        ConfigError: On a bad params file or range.

    """
    if not (args.fps > 0 and np.isfinite(args.fps)):
        raise ConfigError(f'--fps must be a positive number, got {args.fps}')
    overrides = {RANGE_OPTIONS[k]: getattr(args, k) for k in RANGE_OPTIONS
                 if getattr(args, k) is not None}
    config = configure(args.params_file, overrides, args.node_name)
    pairs = image_pairs(args.left, args.right)
    read_pair(pairs[0])   # a first pair that cannot be read refuses the run
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise PairInputError(f'--out {str(out)!r} exists and is not a folder')
        existing = [p for pair in pairs for p in output_paths(out, pair) if p.exists()]
        if existing and not args.force:
            raise PairInputError(f'{str(existing[0])!r} exists'
                                 + (f' (and {len(existing) - 1} more)' if existing[1:] else '')
                                 + '; use --force to replace')
        out.mkdir(parents=True, exist_ok=True)
    return pairs, config, out


def main(argv: list[str] | None = None) -> int:
    """Run plane_pair.

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).

    Returns:
        The exit code (see the module docstring).

    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed by argparse
        return int(exc.code) if isinstance(exc.code, int) else EXIT_REFUSED
    try:
        pairs, config, out = _prepare(args)
    except ConfigError as err:
        where = f'params file {args.params_file!r}: ' if (
            args.params_file and args.params_file not in str(err)) else ''
        _error(where + str(err) + node_name_hint(err))
        return EXIT_REFUSED
    except (PairInputError, OSError) as err:
        _error(str(err))
        return EXIT_REFUSED
    try:
        outcomes = run_pairs(pairs, config, out, args.fps)
    except OSError as err:
        _error(f'writing the pictures failed: {err}')
        return EXIT_FAILED
    except KeyboardInterrupt:
        _error('interrupted')
        return EXIT_INTERRUPTED
    try:
        return _report(outcomes)
    except BrokenPipeError:   # the reader went away (| head): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILED


def _report(outcomes: list[PairOutcome]) -> int:
    for outcome in outcomes:
        print('\n'.join(format_outcome(outcome)))
    skipped = [o for o in outcomes if o.result is None]
    found = sum(1 for o in outcomes if o.result is not None and o.result.ok)
    if len(outcomes) > 1:
        processed = len(outcomes) - len(skipped)
        print(f'{PROG}: {len(outcomes)} pairs, {processed} processed, plane found in {found}'
              + (f', {len(skipped)} skipped' if skipped else ''))
    if skipped:
        _error(f'{len(skipped)} pair(s) could not be read and were skipped (first: '
               f'{skipped[0].error})')
        return EXIT_SKIPPED
    return EXIT_OK if found == len(outcomes) else EXIT_NO_PLANE


if __name__ == '__main__':
    sys.exit(main())
