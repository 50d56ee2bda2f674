"""plane_replay: run the plane pipeline over a rosbag2 file and record what plane_node would.

This is the offline adapter of the house-style picture: it reads stereo image messages from a
rosbag2 bag (sqlite3 or MCAP storage, ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``)
with the pure-Python ``rosbags`` library, pairs them with the node's
:class:`~domplane_ros.stream.sync.ApproximateTimeSync`, runs the node's
:class:`~domplane_ros.stream.pipeline.PlanePipeline` on every pair (dropping the warm start on the
same resets), and writes a new bag with the node's outputs::

    plane_replay INPUT_BAG OUTPUT_BAG [--params-file config/plane_node.yaml]
                 [--node-name plane_node]
                 [--left-topic /left/image_raw] [--right-topic /right/image_raw]
                 [--storage sqlite3|mcap] [--force] [--csv FILE] [--no-progress]
                 [--strict] [--keep-partial] [--debug-images] [--parallax]

Output topics, each written with the bag timestamp of the left image's header stamp:

* ``/plane/homography`` (``std_msgs/msg/Float64MultiArray``): 3x3 row-major, layout dims
  ``rows`` (size 3, stride 9) and ``cols`` (size 3, stride 3), ``H[2][2] == 1``; only for
  pairs where a plane was found, as the node publishes it.
* ``/plane/mask`` (``sensor_msgs/msg/Image``, mono8, the left image's header): for every
  processed pair; all 0 when no plane was found.
* ``/diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``): the node's keys, once per
  ``diagnostics.period_s`` of bag time (1 s by default) and once at the end.
* ``/plane/debug_image`` (``sensor_msgs/msg/Image``, rgb8, the left image's header), only with
  ``--debug-images``: the node's ``plane/debug_image`` for every processed pair (mask tint,
  corners matched on the plane in cyan, unmatched ones in magenta), to review a recording frame
  by frame in Foxglove or rqt_image_view.
* ``/plane/parallax`` (``sensor_msgs/msg/Image``, 32FC1, the left image's header), only with
  ``--parallax``: the node's ``plane/parallax`` for every processed pair (the residual parallax
  after the plane warp in pixels, -1 where not measured, everywhere without a plane), to look up
  what a region's parallax was when setting ``mask.parallax_threshold_px`` for a rig.

Exit codes: 0 on success; 3 when the output is complete except for messages the bag could
not give (undecodable payloads: skipped, counted, named on stderr and recorded in the output's
``metadata.yaml`` ``custom_data``; ``--strict`` makes them fatal); 4 when the bag was read to
the end but gave no pair to process (no messages on a topic, none paired, none decoded): the
summary says "no pairs" and why, and nothing is written; 5 when the output is complete and
written but no processed pair gave a plane (one line on stderr with the last pair's reason;
``plane_pair`` likewise exits non-zero, 4, for a pair without a plane; 3 takes precedence);
2 when the run is refused before anything is written (missing, unreadable or truncated
bag, a folder without metadata.yaml, unknown topic, existing output without ``--force`` or,
with it, one that is not a bag, an output inside the input bag's folder or in one that
cannot be written, invalid params file); 1 when reading or writing fails part-way (a damaged
bag, a full disk): the partial output is removed, or on a read failure with ``--keep-partial``
kept as ``OUTPUT_BAG.incomplete`` (``plane_replay.complete: 'false'`` in its metadata); 130 on
Ctrl-C and 143 on SIGTERM, the partial output removed. Every error is one line on stderr.

The output is written into a hidden temporary folder next to ``OUTPUT_BAG`` and renamed into
place only when it is complete, so an interrupted run never leaves a bag that looks complete.

The package imports ``rosbags`` but not ``rclpy``: :mod:`~domplane_ros.replay.reader` reads
and pairs, :mod:`~domplane_ros.replay.paths` checks where the run writes,
:mod:`~domplane_ros.replay.writer` writes the bag, :mod:`~domplane_ros.replay.report` the CSV
file and the summary; the session, pipeline, pairing and decoding are the ones the live
node uses. This module parses the command line and runs the replay.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from typing import Any, Callable

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.errors import BagError, ConfigError
from domplane_ros.params_file import load_params_file, node_name_hint
from domplane_ros.replay.paths import (create_output, missing_folders, remove_empty_folders,
                                       RunPaths)
from domplane_ros.replay.reader import (BagInput, BagReadError, CAMERA_INFO, describe_error,
                                        header_stamp_ns, JOINT_STATES, ReplayedFrame,
                                        ReplaySession)
from domplane_ros.replay.report import CsvOutput, PROG, ReplaySummary
from domplane_ros.replay.writer import (BagOutput, BagWriteError, DiagnosticsClock,
                                        keep_partial, set_run_metadata, STORAGES)
from domplane_ros.stream.health import INPUT_COUNTER_NAMES
from domplane_ros.stream.sync import Side

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_REFUSED = 2
EXIT_SKIPPED = 3          # complete, but messages the bag could not give were skipped
EXIT_NO_PAIRS = 4         # read to the end, but no pair to process: nothing written
EXIT_NO_PLANE = 5         # complete and written, but no processed pair gave a plane
EXIT_INTERRUPTED = 130    # Ctrl-C
EXIT_TERMINATED = 143     # SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised like Ctrl-C so that the partial output is removed."""


class NoPairsError(BagError):
    """The bag was read to the end but gave no pair to process; nothing was written.

    Attributes:
        summary: The run's summary (it says "no pairs" and why), set by :func:`run_replay`.

    """

    summary: ReplaySummary | None = None


# --------------------------------------------------------------------------------------------
# A whole run.


def run_replay(input_bag: str | os.PathLike[str], output_bag: str | os.PathLike[str],
               config: PlaneNodeConfig | None = None, left_topic: str = '/left/image_raw',
               right_topic: str = '/right/image_raw', storage: str | None = None,
               force: bool = False, csv_path: str | os.PathLike[str] | None = None,
               progress: bool = False,
               on_frame: Callable[[ReplayedFrame], None] | None = None,
               strict: bool = False, keep_partial: bool = False,
               debug_images: bool = False, parallax: bool = False) -> ReplaySummary:
    """Replay a bag through the pipeline and write the node's outputs to a new bag.

    Everything that can be checked up front is checked before anything is written.

    Args:
        input_bag: Input rosbag2 folder, or a single ``.db3`` / ``.mcap`` file.
        output_bag: Output bag folder; it must not exist unless ``force``.
        config: Configuration (default: the node's defaults).
        left_topic: Left image topic.
        right_topic: Right image topic.
        storage: ``'sqlite3'`` or ``'mcap'``; default: the input's storage.
        force: Replace an existing output bag (and CSV file).
        csv_path: If given, write one CSV row per processed pair there.
        progress: Show a progress bar on stderr.
        on_frame: Called with every processed pair, after it is written.
        strict: Fail (``BagReadError``, partial output removed) on the first message that
            cannot be deserialised, instead of skipping and counting it.
        keep_partial: On a read failure part-way, keep the output up to it as
            ``OUTPUT_BAG.incomplete`` (and ``CSV.incomplete``), marked
            ``plane_replay.complete: 'false'`` in its metadata, instead of removing it.
        debug_images: Also write ``/plane/debug_image`` (the node's debug overlay, rgb8).
        parallax: Also write ``/plane/parallax`` (the node's residual parallax, 32FC1).

    Returns:
        The summary.

    Raises:
        BagReadError: If reading fails part-way (or, with ``strict``, a message cannot be
            deserialised); the partial output is removed (or kept, see ``keep_partial``).
        BagError: If the run is refused (missing or unreadable bag, unknown topic, existing
            output); nothing is written.
        ValueError: If ``storage`` is not one of the names in :data:`STORAGES`.

    """
    if storage is not None and storage not in STORAGES:
        raise ValueError(f'storage must be one of {", ".join(STORAGES)}, got {storage!r}')
    paths = RunPaths.check(input_bag, output_bag, csv_path, force, keep_partial)
    t_start = time.perf_counter()
    config = config if config is not None else PlaneNodeConfig()
    with BagInput(paths.input_bag, left_topic, right_topic,
                  config.transport.camera_info_topic, config.head.joint_states_topic) as bag:
        run = _Run(bag, paths, config, bag.sides_topics(), storage or bag.storage, force,
                   progress,
                   debug_images, parallax)
        try:
            run.execute(on_frame, strict, keep_partial)
        except NoPairsError as err:
            err.summary = run.summarise(time.perf_counter() - t_start)
            err.summary.no_pairs = str(err)
            raise
    return run.summarise(time.perf_counter() - t_start)


class _Run:
    """One replay's open outputs and its session, from the first message to the summary."""

    def __init__(self, bag: BagInput, paths: RunPaths, config: PlaneNodeConfig,
                 topics: tuple[str, str], storage: str, force: bool, progress: bool,
                 debug_images: bool = False, parallax: bool = False) -> None:
        self.bag = bag
        self.paths = paths
        self.summary = ReplaySummary(str(paths.input_bag), str(paths.output_bag), storage)
        self.session = ReplaySession(config, topics)
        self.clock = DiagnosticsClock(config.transport.diagnostics_period_s)
        # Folders the outputs create: removed again (if empty) when nothing is written.
        self._new_folders = missing_folders(paths.output_bag.parent) + (
            missing_folders(paths.csv.parent) if paths.csv is not None else [])
        self.output = create_output(paths.output_bag, 'output bag', lambda: BagOutput(
            paths.output_bag, storage, replace=force, debug_images=debug_images,
            parallax=parallax))
        self.table = None
        if paths.csv is not None:
            try:
                self.table = create_output(paths.csv, 'CSV file', lambda: CsvOutput(paths.csv))
            except BaseException:
                self.output.abort()   # no hidden partial bag left behind
                remove_empty_folders(self._new_folders)
                raise
        self.bar = _progress_bar(bag.counts['left'], progress)
        self.latencies_ms: list[float] = []
        self._noted = 0     # undecodable messages given to the session so far
        self._image_warned = False
        self.summary.notes = list(bag.notes)

    def execute(self, on_frame: Callable[[ReplayedFrame], None] | None, strict: bool,
                keep: bool) -> None:
        """Replay every message and commit the outputs; on failure remove or keep them."""
        try:
            for item in self.bag.messages():
                self._take_undecodable(strict)
                if item.side == CAMERA_INFO:
                    self._note(self.session.apply_camera_info(item.msg))
                    continue
                if item.side == JOINT_STATES:
                    self._note(self.session.add_joint_state(item.msg, item.bag_time_ns))
                    continue
                self._write_diagnostics(self.clock.tick(header_stamp_ns(item.msg)))
                self._count_message(item.side)
                for frame in self.session.add(item.side, item.msg, item.bag_time_ns):
                    self._write_frame(frame, on_frame)
                self._show_progress()
            self._take_undecodable(strict)
            self._check_pairs()
            self._commit()
        except BagReadError as err:
            self.bar.close()
            if not keep:
                self._abort()
                raise
            raise keep_partial(self.output, self.table, self.paths.input_bag,
                               len(self.bag.undecodable), err, self.paths.incomplete,
                               self.paths.csv_incomplete) from err
        except BaseException:
            self.bar.close()
            self._abort()
            raise

    def _note(self, note: str) -> None:
        """Keep a note for the summary (each text once, at most 5)."""
        if note and note not in self.summary.notes and len(self.summary.notes) < 5:
            self.summary.notes.append(note)

    def _check_pairs(self) -> None:
        """Refuse to commit an output that holds no processed pair (NoPairsError)."""
        counters, summary = self.session.counters, self.summary
        if counters.processed:
            return
        left, right = self.bag.sides_topics()
        if not summary.left_messages or not summary.right_messages:
            reason = (f'the bag has {summary.left_messages} readable messages on {left} and '
                      f'{summary.right_messages} on {right}')
        elif not counters.pairs:
            reason = (f'{summary.left_messages} left and {summary.right_messages} right '
                      'messages, none within sync.slop_s '
                      f'{self.session.config.sync.slop_s:g} s of a partner')
        else:
            reason = (f'none of the {counters.pairs} pairs could be decoded (last: '
                      f'{self.session.last_error})')
        raise NoPairsError(f'no pairs: {reason}')

    def _take_undecodable(self, strict: bool) -> None:
        """Count the messages the bag could not give since the last call (fatal if strict)."""
        undecodable = self.bag.undecodable
        if strict and undecodable:
            raise BagReadError(f'bag {str(self.paths.input_bag)!r}: {undecodable[0]} '
                               '(--strict)')
        for error in undecodable[self._noted:]:
            self.session.note_undecodable(error)
        self._noted = len(undecodable)

    def _write_diagnostics(self, due: list[tuple[int, float]]) -> None:
        for stamp_ns, rate in due:
            self.output.write_diagnostics(stamp_ns,
                                          *self.session.diagnostic_values(rate, stamp_ns))

    def _count_message(self, side: Side) -> None:
        if side == 'left':
            self.summary.left_messages += 1
            self.bar.update(1)
        else:
            self.summary.right_messages += 1

    def _write_frame(self, frame: ReplayedFrame,
                     on_frame: Callable[[ReplayedFrame], None] | None) -> None:
        self._write_diagnostics(self.clock.due(frame.pair.left_stamp_ns))
        self.output.write_frame(frame)
        if frame.image_warning and not self._image_warned:
            self._image_warned = True   # the text changes with the brightest grey: once
            self._note(frame.image_warning)
        if self.table is not None:
            self.table.write(frame.result)
        self.latencies_ms.append(frame.latency_ms)
        if on_frame is not None:
            on_frame(frame)

    def _show_progress(self) -> None:
        counters = self.session.counters
        if counters.processed and self.bar.enabled:
            found = 100.0 * counters.plane_found / counters.processed
            self.bar.set_postfix_str(f'plane {found:.0f} %', refresh=False)

    def _commit(self) -> None:
        last = self.clock.final()
        if last is not None:
            self._write_diagnostics([last])
        set_run_metadata(self.output, self.paths.input_bag, len(self.bag.undecodable),
                         complete=True)
        self.bar.close()
        # Everything that can fail on a full disk (closing the bag, flushing the CSV file)
        # before anything is moved into place: both outputs appear, or neither.
        self.output.close()
        if self.table is not None:
            self.table.commit()
        self.output.commit()

    def _abort(self) -> None:
        self.output.abort()
        if self.table is not None:
            self.table.abort()
        remove_empty_folders(self._new_folders)

    def summarise(self, wall_s: float) -> ReplaySummary:
        """Return the summary of the finished run."""
        summary, session = self.summary, self.session
        counters, stats = session.counters, session.sync.stats()
        summary.pairs = counters.pairs
        summary.processed = counters.processed
        summary.plane_found = counters.plane_found
        summary.converged = counters.converged
        summary.dropped_sync = stats.dropped
        summary.unpaired_at_end = stats.queued_left + stats.queued_right
        summary.decode_errors = counters.decode_errors
        summary.undecodable_messages = counters.undecodable_messages
        summary.reinitialisations = session.pipeline.stats.reinitialisations
        summary.refusals = session.pipeline.stats.refusals
        summary.latency_ms = list(self.latencies_ms)
        summary.input_problems = {INPUT_COUNTER_NAMES[name]: count
                                  for name, count in session.counts.items() if count}
        summary.wall_s = wall_s
        last = session.last_result
        summary.last_reason = ((last.reason or 'no plane') if last is not None and not last.ok
                               else session.last_error if last is None else '')
        summary.written = dict(self.output.counts)
        if counters.decode_errors or counters.undecodable_messages:
            summary.first_errors = (self.bag.undecodable[:3] + (
                [session.last_error] if counters.decode_errors else []))
        return summary


class _NoBar:
    enabled = False

    def update(self, n: int) -> None:
        pass

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, enabled: bool) -> Any:
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    bar = tqdm(total=total or None, unit='frame', desc=PROG, file=sys.stderr,
               dynamic_ncols=True, smoothing=0.1)
    bar.enabled = True
    return bar


# --------------------------------------------------------------------------------------------
# Command line.


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of plane_replay."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Run the dominant-plane pipeline over a rosbag2 bag (sqlite3 or MCAP) and '
                    'write what plane_node would publish (/plane/homography, /plane/mask, '
                    '/diagnostics) to a new bag.')
    parser.add_argument('input_bag', metavar='INPUT_BAG',
                        help='input bag folder, or a single .db3 or .mcap file')
    parser.add_argument('output_bag', metavar='OUTPUT_BAG', help='output bag folder')
    parser.add_argument('--params-file', metavar='YAML',
                        help='ROS 2 parameters file with a "plane_node: ros__parameters:" '
                             "block (default: the node's defaults)")
    parser.add_argument('--node-name', default='plane_node', metavar='NAME',
                        help='read the blocks of --params-file for this node name, as '
                             "'-r __node:=NAME' renames the node (default: %(default)s)")
    parser.add_argument('--left-topic', default='/left/image_raw',
                        help='left image topic (default: %(default)s)')
    parser.add_argument('--right-topic', default='/right/image_raw',
                        help='right image topic (default: %(default)s)')
    parser.add_argument('--storage', choices=sorted(STORAGES),
                        help="output storage (default: the input's)")
    parser.add_argument('--force', action='store_true',
                        help='replace an existing OUTPUT_BAG (only a bag: metadata.yaml and '
                             '.db3/.mcap files) and --csv file')
    parser.add_argument('--csv', metavar='FILE',
                        help='write one CSV row per processed pair to FILE')
    parser.add_argument('--keep-partial', action='store_true',
                        help='if reading fails part-way, keep the output up to the failure as '
                             'OUTPUT_BAG.incomplete (marked incomplete in its metadata) '
                             'instead of removing it')
    parser.add_argument('--strict', action='store_true',
                        help='fail (exit 1, output removed) on the first message that cannot '
                             'be deserialised, instead of skipping it (exit 3)')
    parser.add_argument('--debug-images', action='store_true',
                        help='also write /plane/debug_image (rgb8: mask tint, matched and '
                             'unmatched corners) for every pair, to review in Foxglove')
    parser.add_argument('--parallax', action='store_true',
                        help='also write /plane/parallax (32FC1: residual parallax after the '
                             'plane warp in pixels, -1 where not measured) for every pair')
    bar = parser.add_mutually_exclusive_group()
    bar.add_argument('--no-progress', dest='progress', action='store_false', default=None,
                     help='no progress bar (the default when stderr is not a terminal)')
    bar.add_argument('--progress', dest='progress', action='store_true',
                     help='show the progress bar even when stderr is not a terminal')
    return parser


def _error(message: str) -> None:
    print(f'{PROG}: error: {" ".join(message.split())}', file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run plane_replay.

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).

    Returns:
        0 on success; 3 when the output is complete except for messages the bag could not
        give (skipped, counted and named on stderr); 4 if the bag gave no pair (nothing
        written); 5 if the output is complete but no processed pair gave a plane; 2 if the
        run was refused (nothing written); 1 if it failed part-way (the partial output
        removed); 130 on Ctrl-C and 143 on SIGTERM (the partial output removed).

    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed by argparse
        return int(exc.code) if isinstance(exc.code, int) else EXIT_REFUSED
    try:
        config = (load_params_file(args.params_file, args.node_name) if args.params_file
                  else PlaneNodeConfig())
    except ConfigError as err:
        _error((str(err) if args.params_file in str(err)
                else f'params file {args.params_file!r}: {err}') + node_name_hint(err))
        return EXIT_REFUSED
    progress = args.progress if args.progress is not None else sys.stderr.isatty()
    installed, previous = _terminate_like_ctrl_c()
    try:
        summary = run_replay(args.input_bag, args.output_bag, config,
                             left_topic=args.left_topic, right_topic=args.right_topic,
                             storage=args.storage, force=args.force, csv_path=args.csv,
                             progress=progress, strict=args.strict,
                             keep_partial=args.keep_partial,
                             debug_images=args.debug_images, parallax=args.parallax)
    except Terminated:
        _error('terminated (SIGTERM); the partial output was removed')
        return EXIT_TERMINATED
    except BagReadError as err:
        _error(str(err) if err.kept else f'{err}; the partial output was removed')
        return EXIT_FAILED
    except BagWriteError as err:
        _error(f'{err}; the partial output was removed')
        return EXIT_FAILED
    except NoPairsError as err:
        if err.summary is not None:
            print('\n'.join(err.summary.lines()))
        _error(f'{err}; nothing was written')
        return EXIT_NO_PAIRS
    except BagError as err:
        _error(str(err))
        return EXIT_REFUSED
    except OSError as err:
        _error(f'{describe_error(err)} (no output bag was written)')
        return EXIT_FAILED
    except KeyboardInterrupt:
        _error('interrupted; the partial output was removed')
        return EXIT_INTERRUPTED
    finally:
        if installed:
            signal.signal(signal.SIGTERM, previous)
    print('\n'.join(summary.lines()))
    if summary.undecodable_messages:
        print(f'{PROG}: warning: {summary.undecodable_messages} message(s) of '
              f'{summary.input_bag!r} could not be read and were skipped (first: '
              f'{summary.first_errors[0]}); {summary.output_bag!r} records the count in '
              'metadata.yaml custom_data plane_replay.skipped_messages', file=sys.stderr)
        return EXIT_SKIPPED
    if summary.processed and not summary.plane_found:
        print(f'{PROG}: no plane: none of the {summary.processed} processed pairs gave a plane '
              f'(last: {summary.last_reason or "no plane"}); the output was written',
              file=sys.stderr)
        return EXIT_NO_PLANE
    return EXIT_OK


def _terminate_like_ctrl_c() -> tuple[bool, Any]:
    """Make SIGTERM raise :class:`Terminated` (main thread only).

    Returns:
        ``(installed, previous handler)``.

    """
    def on_sigterm(signum: int, frame: Any) -> None:
        raise Terminated()

    try:
        return True, signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:   # not the main thread: leave SIGTERM alone
        return False, None


if __name__ == '__main__':
    sys.exit(main())
