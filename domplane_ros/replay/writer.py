"""Writing plane_node's outputs into a bag that appears only when it is complete.

:class:`BagOutput` writes ``/plane/homography``, ``/plane/mask``, ``/plane/result`` and
``/diagnostics`` (rosbags message types; on request ``/plane/debug_image`` and
``/plane/parallax``) into a hidden temporary folder next to the output
and renames it into place at :meth:`BagOutput.commit`; :func:`keep_partial` commits what a
failed run wrote as ``OUTPUT_BAG.incomplete`` instead. :class:`DiagnosticsClock` says when a
diagnostics message is due, in bag time.
"""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path
import shutil
import sqlite3
import tempfile
from typing import Any, Iterator

from domplane_ros.core.image import gray_to_image_fields, rgb_to_image_fields
from domplane_ros.errors import BagError, clip_text
from domplane_ros.replay.reader import BagReadError, IMAGE_TYPE, ReplayedFrame, typestore
from domplane_ros.stream.frame import debug_overlay, parallax_image
from domplane_ros.stream.status import result_status, RESULT_STATUS_NAME, STATUS_NAME
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

HOMOGRAPHY_TYPE = 'std_msgs/msg/Float64MultiArray'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

HOMOGRAPHY_TOPIC = '/plane/homography'
MASK_TOPIC = '/plane/mask'
RESULT_TOPIC = '/plane/result'
DEBUG_IMAGE_TOPIC = '/plane/debug_image'
PARALLAX_TOPIC = '/plane/parallax'
DIAGNOSTICS_TOPIC = '/diagnostics'

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}

_DIAGNOSTICS_NAME = STATUS_NAME
_DIAGNOSTICS_HARDWARE_ID = 'plane_replay'


class BagWriteError(BagError):
    """Writing the output failed (a full disk, a read-only or vanished folder)."""


def _write_problem(err: BaseException) -> str:
    """Return a write error in words (``'No space left on device (disk full)'``)."""
    if isinstance(err, OSError):
        text = err.strerror or str(err)
        full = err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
    else:   # sqlite3 says 'database or disk is full' for every short write
        text = str(err)
        full = 'full' in text
    return clip_text(' '.join(text.split()), 200) + (' (disk full)' if full else '')


class BagOutput:
    """Writes the node's outputs into a bag that appears only when it is complete.

    The bag is written into a hidden temporary folder next to ``path``; :meth:`commit`
    closes it and renames it into place (replacing an existing ``path`` only if ``replace``),
    :meth:`abort` removes it.

    Args:
        path: Where the finished bag goes.
        storage: ``'sqlite3'`` or ``'mcap'``.
        replace: Replace an existing ``path`` at commit.
        debug_images: Also write ``/plane/debug_image`` (rgb8, the node's debug overlay) for
            every processed pair.
        parallax: Also write ``/plane/parallax`` (32FC1, the node's residual parallax image)
            for every processed pair.

    """

    def __init__(self, path: str | os.PathLike[str], storage: str, replace: bool,
                 debug_images: bool = False, parallax: bool = False) -> None:
        """Create the temporary bag and its connections."""
        self.path = Path(path)
        self.replace = replace
        self.typestore = ts = typestore()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-',
                                             dir=self.path.parent))
        self.counts = {HOMOGRAPHY_TOPIC: 0, MASK_TOPIC: 0, RESULT_TOPIC: 0, DIAGNOSTICS_TOPIC: 0}
        self._closed = False
        try:
            self._writer = Writer(self._tmpdir / self.path.name, version=9,
                                  storage_plugin=STORAGES[storage])
            with self._writing():
                self._writer.open()
            self._conn_h = self._writer.add_connection(HOMOGRAPHY_TOPIC, HOMOGRAPHY_TYPE,
                                                       typestore=ts)
            self._conn_mask = self._writer.add_connection(MASK_TOPIC, IMAGE_TYPE, typestore=ts)
            self._conn_result = self._writer.add_connection(RESULT_TOPIC, DIAGNOSTICS_TYPE,
                                                            typestore=ts)
            self._conn_diag = self._writer.add_connection(DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE,
                                                          typestore=ts)
            self._conn_debug = self._conn_parallax = None
            if debug_images:
                self._conn_debug = self._writer.add_connection(DEBUG_IMAGE_TOPIC, IMAGE_TYPE,
                                                               typestore=ts)
                self.counts[DEBUG_IMAGE_TOPIC] = 0
            if parallax:
                self._conn_parallax = self._writer.add_connection(PARALLAX_TOPIC, IMAGE_TYPE,
                                                                  typestore=ts)
                self.counts[PARALLAX_TOPIC] = 0
        except BaseException:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise
        t = ts.types
        self._Time = t['builtin_interfaces/msg/Time']
        self._Header = t['std_msgs/msg/Header']
        self._Image = t[IMAGE_TYPE]
        self._Float64MultiArray = t[HOMOGRAPHY_TYPE]
        self._MultiArrayLayout = t['std_msgs/msg/MultiArrayLayout']
        self._MultiArrayDimension = t['std_msgs/msg/MultiArrayDimension']
        self._DiagnosticArray = t[DIAGNOSTICS_TYPE]
        self._DiagnosticStatus = t['diagnostic_msgs/msg/DiagnosticStatus']
        self._KeyValue = t['diagnostic_msgs/msg/KeyValue']

    @contextlib.contextmanager
    def _writing(self) -> Iterator[None]:
        """Turn the storage's write errors (a full disk, say) into :class:`BagWriteError`."""
        try:
            yield
        except (OSError, sqlite3.Error) as err:
            raise BagWriteError(f'writing the output bag {str(self.path)!r} failed: '
                                f'{_write_problem(err)}') from err

    def _write(self, connection: Any, topic: str, stamp_ns: int, msg: Any) -> None:
        data = self.typestore.serialize_cdr(msg, connection.msgtype)
        with self._writing():
            self._writer.write(connection, stamp_ns, data)
        self.counts[topic] += 1

    def write_frame(self, frame: ReplayedFrame) -> None:
        """Write a processed pair: homography (with a plane), result, mask, debug image, parallax.

        All are written at the left image's header stamp; the result, the mask, the debug
        image (only with ``debug_images``) and the parallax (only with ``parallax``) carry the
        left header, as the node publishes them.
        """
        header = frame.pair.left.header
        stamp = frame.pair.left_stamp_ns
        result = frame.result
        if result.ok:
            self._write(self._conn_h, HOMOGRAPHY_TOPIC, stamp,
                        self.homography_msg(result.homography))
        fields = gray_to_image_fields(result.mask, 'mono8')
        mask = self._Image(
            header=self._Header(stamp=self._Time(sec=int(header.stamp.sec),
                                                 nanosec=int(header.stamp.nanosec)),
                                frame_id=str(header.frame_id)),
            height=fields['height'], width=fields['width'], encoding=fields['encoding'],
            is_bigendian=fields['is_bigendian'], step=fields['step'],
            data=np.frombuffer(fields['data'], np.uint8))
        self._write(self._conn_mask, MASK_TOPIC, stamp, mask)
        level, message, values = result_status(frame)
        self._write(self._conn_result, RESULT_TOPIC, stamp, self._DiagnosticArray(
            header=mask.header, status=[self._DiagnosticStatus(
                level=level, name=RESULT_STATUS_NAME, message=message,
                hardware_id=_DIAGNOSTICS_HARDWARE_ID,
                values=[self._KeyValue(key=k, value=v) for k, v in values])]))
        if self._conn_debug is not None:
            fields = rgb_to_image_fields(debug_overlay(frame.left, frame.result), 'rgb8')
            self._write(self._conn_debug, DEBUG_IMAGE_TOPIC, stamp,
                        self._image(fields, mask.header))
        if self._conn_parallax is not None:
            fields = gray_to_image_fields(parallax_image(frame.result), '32FC1')
            self._write(self._conn_parallax, PARALLAX_TOPIC, stamp,
                        self._image(fields, mask.header))

    def _image(self, fields: dict[str, Any], header: Any) -> Any:
        """Return a rosbags sensor_msgs/Image of image fields with the given header."""
        return self._Image(header=header, height=fields['height'], width=fields['width'],
                           encoding=fields['encoding'], is_bigendian=fields['is_bigendian'],
                           step=fields['step'], data=np.frombuffer(fields['data'], np.uint8))

    def homography_msg(self, homography: np.ndarray) -> Any:
        """Return the node's Float64MultiArray for a (3, 3) homography (rosbags message)."""
        dim = self._MultiArrayDimension
        layout = self._MultiArrayLayout(dim=[dim(label='rows', size=3, stride=9),
                                             dim(label='cols', size=3, stride=3)],
                                        data_offset=0)
        data = np.asarray(homography, dtype=np.float64).reshape(9).copy()
        return self._Float64MultiArray(layout=layout, data=data)

    def write_diagnostics(self, stamp_ns: int, level: int, message: str,
                          values: list[tuple[str, str]]) -> None:
        """Write one DiagnosticArray with one status at ``stamp_ns``."""
        status = self._DiagnosticStatus(
            level=level, name=_DIAGNOSTICS_NAME, message=message,
            hardware_id=_DIAGNOSTICS_HARDWARE_ID,
            values=[self._KeyValue(key=k, value=v) for k, v in values])
        msg = self._DiagnosticArray(
            header=self._Header(stamp=self._Time(sec=stamp_ns // 1_000_000_000,
                                                 nanosec=stamp_ns % 1_000_000_000),
                                frame_id=''),
            status=[status])
        self._write(self._conn_diag, DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def set_custom_data(self, key: str, value: str) -> None:
        """Record a key/value string in the output bag's metadata.yaml ``custom_data``."""
        with self._writing():
            self._writer.set_custom_data(key, value)

    def close(self) -> None:
        """Finish the storage in the temporary folder (idempotent); nothing is moved yet.

        Raises:
            BagWriteError: If the storage cannot be completed (a full disk).

        """
        if not self._closed:
            with self._writing():
                self._writer.close()
            self._closed = True

    def commit(self, path: str | os.PathLike[str] | None = None) -> None:
        """Close the bag and move it into place (to ``path`` instead, if given).

        Raises:
            BagWriteError: If the storage cannot be completed (a full disk); the bag stays in
                its temporary folder for :meth:`abort`.

        """
        self.close()
        finished = self._tmpdir / self.path.name
        target = Path(path) if path is not None else self.path
        if target.exists() or target.is_symlink():
            if not self.replace:
                raise BagError(f'output {str(target)!r} appeared while replaying; '
                               f'the result is left in {str(finished)!r}')
            # Move the old one aside first, so the rename below is atomic.
            os.replace(target, self._tmpdir / 'replaced')
        os.replace(finished, target)
        shutil.rmtree(self._tmpdir, ignore_errors=True)

    def abort(self) -> None:
        """Drop the partial bag (never raises: it runs while another error is handled)."""
        try:
            if not self._closed and self._writer.storage is not None:
                self._writer.abort()
        except Exception:  # noqa: B902 - a full disk cannot flush what is removed anyway
            pass
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)


def set_run_metadata(output: BagOutput, input_bag: Path, skipped: int, complete: bool,
                     error: str = '') -> None:
    """Record the run in the output's metadata.yaml ``custom_data`` (``plane_replay.*``)."""
    output.set_custom_data('plane_replay.input_bag', str(input_bag))
    output.set_custom_data('plane_replay.skipped_messages', str(skipped))
    output.set_custom_data('plane_replay.complete', 'true' if complete else 'false')
    if error:
        output.set_custom_data('plane_replay.error', error)


def keep_partial(output: BagOutput, table: Any, input_bag: Path, skipped: int,
                 err: BagReadError, incomplete: Path,
                 csv_incomplete: Path | None) -> BagReadError:
    """Keep what a run wrote before a read failure, marked incomplete.

    Args:
        output: The output bag, still open.
        table: The CSV output (with ``commit(path)``), or None.
        input_bag: The input bag, recorded in the metadata.
        skipped: Messages skipped so far, recorded in the metadata.
        err: The read failure, recorded in the metadata.
        incomplete: Where the bag goes (``OUTPUT_BAG.incomplete``).
        csv_incomplete: Where the CSV file goes, or None.

    Returns:
        The error to raise: ``err``'s message plus where the output went, with
        :attr:`BagReadError.kept` set.

    """
    set_run_metadata(output, input_bag, skipped, complete=False, error=str(err))
    output.commit(incomplete)
    if table is not None:
        table.commit(csv_incomplete)
    kept = BagReadError(f'{err}; the output up to the failure is in {str(incomplete)!r} '
                        '(incomplete)')
    kept.kept = str(incomplete)
    return kept


class DiagnosticsClock:
    """Decides when a diagnostics message is due, in bag time (the pairs' left stamps)."""

    def __init__(self, period_s: float) -> None:
        self.period_ns = max(1, int(round(period_s * 1e9)))
        self.start_ns: int | None = None
        self.pairs = 0
        self.last_ns: int | None = None

    def due(self, stamp_ns: int) -> list[tuple[int, float]]:
        """Return ``(stamp, rate)`` of the diagnostics to write before a pair at ``stamp_ns``.

        A gap in the bag gives one message with the pairs before it and, if the gap is longer
        than a period, one more with rate 0 (the node would send one per period).
        """
        out: list[tuple[int, float]] = []
        if self.start_ns is None or (self.last_ns is not None and stamp_ns < self.last_ns):
            # First pair, or the stamps went back (a bag loop): start a new period.
            self.start_ns, self.pairs = stamp_ns, 0
        else:
            out = self.tick(stamp_ns)
        self.pairs += 1
        self.last_ns = stamp_ns
        return out

    def tick(self, stamp_ns: int) -> list[tuple[int, float]]:
        """Return ``(stamp, rate)`` of the periods that ended before a message at ``stamp_ns``.

        Called for every image message, so that a camera drop-out (images on one side only)
        gets a diagnostics message per period, as the node sends.
        """
        out: list[tuple[int, float]] = []
        if self.start_ns is None or stamp_ns < self.start_ns:
            return out
        end = self.start_ns + self.period_ns
        if stamp_ns >= end:
            out.append((end, self.pairs / (self.period_ns * 1e-9)))
            self.start_ns, self.pairs = end, 0
            periods = (stamp_ns - end) // self.period_ns
            if periods >= 1:
                end = self.start_ns + periods * self.period_ns
                out.append((end, 0.0))
                self.start_ns = end
        return out

    def final(self) -> tuple[int, float] | None:
        """Return the last diagnostics (the partial period up to the last pair), if any."""
        if self.start_ns is None or self.last_ns is None or self.pairs == 0:
            return None
        span_ns = max(self.last_ns - self.start_ns, 0)
        # n pairs spread over span cover about span * n / (n - 1).
        rate = ((self.pairs - 1) / (span_ns * 1e-9) if span_ns > 0 and self.pairs > 1
                else self.pairs / (self.period_ns * 1e-9))
        return self.last_ns, rate
