"""Checks of the input stream, shared by the live node and the offline replay (no ROS imports).

Bad input must give a clear reason, be counted, and never reach the output as a confident
result. Two objects hold the checks' state:

* :class:`PairChecks`, owned by the :class:`~domplane_ros.stream.pipeline.PlanePipeline`, looks at
  every decoded stereo pair: left and right of different sizes (refused), a size change
  mid-stream (warm start dropped), one camera frozen while the other changes (refused), black
  or saturated frames (refused), header stamps that go backwards or jump forward (warm start
  dropped). The pipeline adds the checks that need its features and estimate: too few
  features (:func:`texture_note` says why) and inliers with too little spread
  (:func:`inlier_spread`).
* :class:`StampChecks`, owned by the :class:`~domplane_ros.stream.session.StreamSession` next
  to its synchroniser, looks at every message before pairing: zero stamps (a driver that does
  not stamp its images) and left/right stamps that differ by more than the slop (the
  synchroniser can never pair them).

Neither copies configuration: each call is given the limits in force. Every input problem of
one stream is counted in one :class:`InputCounts` (the session's; the checks, the pipeline
and the decoder add to it); :func:`input_diagnostic_values` turns counts into the
``/diagnostics`` key/values.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Iterator, Mapping

import cv2
from domplane_ros.config import PipelineConfig
from domplane_ros.errors import DECODE_ERROR_KINDS
import numpy as np

# Grey levels at or beyond these count as clipped (black or saturated).
_DARK, _BRIGHT = 2, 253
# Images larger than this many pixels are checked on a regular grid of about this many.
_SAMPLED_PIXELS = 500_000
# Stamps kept per side to find each message's closest partner.
_SKEW_WINDOW = 8

# Counter name -> diagnostics key, in the order diagnostics show them.
INPUT_COUNTER_NAMES: dict[str, str] = {
    **{f'decode_{kind}': f'decode errors ({kind})' for kind in DECODE_ERROR_KINDS},
    'size_mismatch': 'pairs refused: left/right sizes differ',
    'size_changes': 'image size changes',
    'frozen_camera': 'pairs refused: camera frozen',
    'clipped': 'pairs refused: black or saturated',
    'too_few_features': 'pairs failed: too few features',
    'degenerate_geometry': 'pairs failed: degenerate geometry',
    'outside_prior': 'pairs failed: homography outside the prior',
    'invalid_homography': 'pairs failed: invalid homography',
    'unverified_plane': 'pairs failed: no plane verified',
    'swapped_cameras': 'pairs failed: left and right swapped',
    'stamp_zero': 'stamps zero',
    'stamp_backwards': 'stamps backwards',
    'stamp_jumps': 'stamp jumps forward',
    'sync_skew': 'frames unpaired: stamp skew > slop',
}


def new_counts() -> dict[str, int]:
    """Return a zero count for every name in :data:`INPUT_COUNTER_NAMES`."""
    return dict.fromkeys(INPUT_COUNTER_NAMES, 0)


class InputCounts(Mapping[str, int]):
    """The input problems of one stream, one count per name of :data:`INPUT_COUNTER_NAMES`.

    A read-only mapping for everyone but :meth:`add`: the checks, the pipeline and the
    session's decoder add to one instance, and diagnostics read it.
    """

    def __init__(self) -> None:
        """Start with every count zero."""
        self._counts = new_counts()

    def add(self, name: str, n: int = 1) -> None:
        """Count ``n`` more problems of kind ``name``.

        Raises:
            KeyError: If ``name`` is not in :data:`INPUT_COUNTER_NAMES`.

        """
        if name not in self._counts:
            raise KeyError(f'unknown input counter {name!r}')
        self._counts[name] += n

    def __getitem__(self, name: str) -> int:
        """Return the count of ``name``."""
        return self._counts[name]

    def __iter__(self) -> Iterator[str]:
        """Iterate over the names, in :data:`INPUT_COUNTER_NAMES` order."""
        return iter(self._counts)

    def __len__(self) -> int:
        """Return the number of names."""
        return len(self._counts)

    def __repr__(self) -> str:
        """Show the non-zero counts."""
        return f'InputCounts({ {k: v for k, v in self._counts.items() if v} })'


@dataclass(frozen=True)
class PairCheck:
    """What :meth:`PairChecks.check` found in one pair.

    Attributes:
        refused: Why the pair must not be estimated ('' if it may be).
        reset: Whether the warm start must be dropped before this pair.
        warnings: Problems worth a warning that do not refuse the pair.

    """

    refused: str = ''
    reset: bool = False
    warnings: tuple[str, ...] = ()


class PairChecks:
    """Per-stream checks of decoded stereo pairs; see the module docstring.

    Args:
        counts: Where the problems are counted (default: a new :class:`InputCounts`).

    """

    def __init__(self, counts: InputCounts | None = None) -> None:
        """Start with no previous pair."""
        self.counts = counts if counts is not None else InputCounts()
        self._last_stamp_ns: int | None = None
        self._last_shapes: tuple[tuple[int, ...], tuple[int, ...]] | None = None
        self._last_images: tuple[np.ndarray, np.ndarray] | None = None

    def check(self, left: np.ndarray, right: np.ndarray, stamp_ns: int,
              limits: PipelineConfig, stream_gap_ns: int | None = None) -> PairCheck:
        """Check one pair and remember it for the next.

        Args:
            left: (H, W) uint8 left grey image.
            right: (H', W') uint8 right grey image.
            stamp_ns: The pair's stamp, nanoseconds.
            limits: The ``pipeline.*`` configuration in force: ``max_clipped_fraction`` (a
                frame with more of its pixels black (<= 2) or saturated (>= 253) is refused;
                1.0 never refuses) and ``max_stamp_jump_s`` (a stamp more than this after the
                last pair's drops the warm start).
            stream_gap_ns: The longest gap between consecutive pairs the cameras delivered
                since the last pair checked (:attr:`~domplane_ros.stream.sync.Pair.gap_ns`),
                when the caller drops pairs (a newest-wins hand-over behind a slow search): it
                is the forward jump, so a gap the processing made is not taken for the
                cameras'. None: the jump is measured from the last pair checked.

        Returns:
            The :class:`PairCheck`.

        """
        warnings: list[str] = []
        reset = self._check_stamp(stamp_ns, limits.max_stamp_jump_s, warnings, stream_gap_ns)
        shapes = (left.shape, right.shape)
        if self._last_shapes is not None and shapes != self._last_shapes:
            self.counts.add('size_changes')
            reset = True
            warnings.append(f'image size changed from {_sizes(self._last_shapes)} to '
                            f'{_sizes(shapes)}: warm start dropped')
        self._last_shapes = shapes
        refused = ''
        if left.shape != right.shape:
            self.counts.add('size_mismatch')
            refused = (f'left and right images differ in size: left {_size(left.shape)}, '
                       f'right {_size(right.shape)}')
        if not refused:
            for gray, side in ((left, 'left'), (right, 'right')):
                refused = clipped_reason(gray, side, limits.max_clipped_fraction)
                if refused:
                    self.counts.add('clipped')
                    break
        # A frozen camera: compared with the previous pair that passed the checks above.
        previous, self._last_images = self._last_images, None
        if not refused:
            # Compared exactly (faster than hashing: 0.1 ms for two 1280x720 images): a copy,
            # or the array itself if it is read-only (the session's decoded images, often
            # views of the messages: a 4K copy is 0.6 ms an image).
            self._last_images = (_kept(left), _kept(right))
            refused = self._frozen_reason(previous, left, right)
        return PairCheck(refused, reset, tuple(warnings))

    def _check_stamp(self, stamp_ns: int, max_jump_s: float, warnings: list[str],
                     stream_gap_ns: int | None) -> bool:
        """Return whether the stamp (backwards, or a jump forward) drops the warm start."""
        last, self._last_stamp_ns = self._last_stamp_ns, stamp_ns
        if last is not None and stamp_ns < last:
            self.counts.add('stamp_backwards')
            warnings.append(f'stamp went backwards by {(last - stamp_ns) * 1e-9:.3f} s: '
                            'warm start dropped')
            return True
        jump_ns = stamp_ns - last if last is not None else 0
        if stream_gap_ns is not None and last is not None:
            # Pairs delivered since the last one checked were dropped: the jump is the
            # stream's own longest gap, not the time the processing took.
            jump_ns = min(jump_ns, stream_gap_ns)
        if jump_ns > max_jump_s * 1e9:
            self.counts.add('stamp_jumps')
            warnings.append(f'stamp jumped forward by {jump_ns * 1e-9:.1f} s '
                            f'(> pipeline.max_stamp_jump_s {max_jump_s:g} s): '
                            'warm start dropped')
            return True
        return False

    def _frozen_reason(self, previous: tuple[np.ndarray, np.ndarray] | None,
                       left: np.ndarray, right: np.ndarray) -> str:
        """Return why one camera is frozen while the other changed ('' if it is not)."""
        same = previous is not None and [_identical(previous[i], image)
                                         for i, image in enumerate((left, right))]
        if not same or same[0] == same[1]:
            return ''
        self.counts.add('frozen_camera')
        frozen, moving = ('left', 'right') if same[0] else ('right', 'left')
        return (f'{frozen} camera frozen: its image is identical to its previous '
                f'one while the {moving} image changed')


def _kept(image: np.ndarray) -> np.ndarray:
    """Return what to compare the next pair with: ``image`` if read-only, else a copy.

    A read-only array is taken not to change while it is kept (the session's images are
    read-only views of messages that nothing changes).
    """
    return image if not image.flags.writeable else image.copy()


def _identical(a: np.ndarray, b: np.ndarray) -> bool:
    """Return whether two images are identical, comparing every 16th row first.

    Successive frames of a live camera differ almost everywhere (noise), so the rows settle
    it without reading the whole image (an 8 MB comparison at 3840 x 2160); whole rows are
    compared as fast as memory is read (0.01 ms at 4K, a grid of every 8th pixel 0.1 ms).
    """
    if a.shape != b.shape:
        return False
    if a.size > _SAMPLED_PIXELS and not np.array_equal(a[::16], b[::16]):
        return False
    return bool(np.array_equal(a, b))


def clipped_reason(gray: np.ndarray, side: str, max_fraction: float) -> str:
    """Return why a frame is too black or too saturated to use ('' if it is not).

    Args:
        gray: (H, W) uint8 image.
        side: ``'left'`` or ``'right'`` (named in the reason).
        max_fraction: Largest admissible fraction of black (<= 2) or saturated (>= 253)
            pixels; 1.0 never refuses.

    Returns:
        The reason, or ''.

    """
    if max_fraction >= 1.0:
        return ''
    # Above _SAMPLED_PIXELS the fractions are counted on a regular grid of about that many
    # pixels (every k-th row and column): 4x cheaper at 3840 x 2160, and a fraction of
    # half a million samples is within a fraction of a percent of the whole image's.
    stride = max(1, int(np.sqrt(gray.size / _SAMPLED_PIXELS)))
    if stride > 1:
        gray = gray[::stride, ::stride]
    total = float(gray.size)
    dark = np.count_nonzero(gray <= _DARK) / total
    bright = np.count_nonzero(gray >= _BRIGHT) / total
    if dark > max_fraction:
        return (f'{side} image is black: {100 * dark:.0f} % of its pixels are <= {_DARK} '
                f'(> pipeline.max_clipped_fraction {max_fraction:g})')
    if bright > max_fraction:
        return (f'{side} image is saturated: {100 * bright:.0f} % of its pixels are >= '
                f'{_BRIGHT} (> pipeline.max_clipped_fraction {max_fraction:g})')
    return ''


def texture_note(gray: np.ndarray) -> str:
    """Describe an image's contrast, for a too-few-features reason.

    Args:
        gray: (H, W) uint8 image.

    Returns:
        ``'textureless: grey std 0.4'`` below a standard deviation of 2 grey levels, else
        ``'grey std 35.1'``.

    """
    std = float(cv2.meanStdDev(gray)[1][0, 0])
    return f'textureless: grey std {std:.1f}' if std < 2.0 else f'grey std {std:.1f}'


def inlier_spread(points: np.ndarray, region_area_px: float) -> float:
    """Return the area of the points' convex hull as a fraction of a region's area.

    Inliers that are collinear or packed in a small patch leave the homography unconstrained
    across the image; their hull area is then (close to) zero.

    Args:
        points: (N, 2) float64 points.
        region_area_px: Area of the region the points were detected in, pixels (> 0).

    Returns:
        The fraction, >= 0 (0 for fewer than 3 points).

    """
    if points.shape[0] < 3 or region_area_px <= 0:
        return 0.0
    hull = cv2.convexHull(np.ascontiguousarray(points, dtype=np.float32))
    return float(cv2.contourArea(hull)) / float(region_area_px)


def homography_problem(matrix: np.ndarray | None) -> str:
    """Return why a homography must not be published as good ('' if it may be).

    Args:
        matrix: (3, 3) float64 homography, or None.

    Returns:
        The reason: missing, wrong shape, non-finite values, or ``H[2, 2] != 1``.

    """
    if matrix is None:
        return 'no homography'
    h = np.asarray(matrix)
    if h.shape != (3, 3):
        return f'homography has shape {h.shape}, not (3, 3)'
    if not np.all(np.isfinite(h)):
        return 'homography has non-finite values'
    if abs(float(h[2, 2]) - 1.0) > 1e-9:
        return f'homography is not normalised: H[2, 2] = {float(h[2, 2]):.3g}'
    return ''


class StampChecks:
    """Per-message stamp checks before pairing; see the module docstring.

    A message's skew is the distance from its stamp to the closest stamp among the other
    side's recent messages (both those that came before and after it). When a message leaves
    the window with a skew above the slop while the other side has moved past its stamp, the
    synchroniser could never have paired it: it is counted in ``sync_skew`` and the skew is
    kept in :attr:`last_skew_ns`. (A message whose other side has gone silent is a drop-out,
    not a skew, and is not counted here.)

    Args:
        slop_ns: The synchroniser's slop, nanoseconds (a synchroniser with another slop comes
            with new stamp checks: see :meth:`StreamSession.update_config
            <domplane_ros.stream.session.StreamSession.update_config>`).
        counts: Where the problems are counted (default: a new :class:`InputCounts`).

    """

    def __init__(self, slop_ns: int, counts: InputCounts | None = None) -> None:
        """Start with no messages seen."""
        self.slop_ns = int(slop_ns)
        self.counts = counts if counts is not None else InputCounts()
        self.last_skew_ns = 0
        # Per side: [stamp, closest distance to the other side] of recent messages.
        self._recent: dict[str, deque[list[int]]] = {
            side: deque() for side in ('left', 'right')}

    def observe(self, side: str, stamp_ns: int) -> list[str]:
        """Check one message's stamp.

        Args:
            side: ``'left'`` or ``'right'``.
            stamp_ns: Its header stamp, nanoseconds.

        Returns:
            Warnings (usually none): a zero stamp, or a message that left the window without a
            partner within the slop.

        """
        warnings = []
        if stamp_ns == 0:
            self.counts.add('stamp_zero')
            warnings.append(f'{side} image header stamp is zero: the camera driver does not '
                            'stamp its images, so they cannot be paired by time')
        other = self._recent['right' if side == 'left' else 'left']
        closest = _FAR
        for entry in other:
            distance = abs(entry[0] - stamp_ns)
            entry[1] = min(entry[1], distance)
            closest = min(closest, distance)
        own = self._recent[side]
        own.append([stamp_ns, closest])
        if len(own) > _SKEW_WINDOW:
            old_stamp, skew = own.popleft()
            moved_on = bool(other) and other[-1][0] > old_stamp
            if skew > self.slop_ns and moved_on:
                self.counts.add('sync_skew')
                self.last_skew_ns = skew
                warnings.append(
                    f'{side} image at {old_stamp * 1e-9:.3f} s had no partner: the closest '
                    f'other stamp differs by {skew * 1e-6:.1f} ms > sync.slop_s '
                    f'{self.slop_ns * 1e-6:g} ms')
        return warnings


_FAR = 1 << 62


class Throttle:
    """Rate-limit messages per key (each kind of problem has its own clock).

    Args:
        period_s: Shortest time between two messages of one key, seconds.

    """

    def __init__(self, period_s: float) -> None:
        """Start with every key due."""
        self.period_s = period_s
        self._last: dict[str, float] = {}

    def due(self, key: str, now_s: float) -> bool:
        """Return whether a message of ``key`` may go out at ``now_s`` (and note it if so)."""
        last = self._last.get(key)
        if last is not None and now_s - last < self.period_s:
            return False
        self._last[key] = now_s
        return True


def problem_key(message: str) -> str:
    """Return a message's throttling key: its text up to the first colon, without numbers."""
    head = message.split(':', 1)[0]
    return ' '.join(''.join(ch for ch in head if ch not in '0123456789.+-').split())


def input_diagnostic_values(*counts: Mapping[str, int]) -> list[tuple[str, str]]:
    """Return the ``/diagnostics`` key/values of input problem counts.

    Args:
        *counts: Count mappings (names of :data:`INPUT_COUNTER_NAMES`); they are summed.

    Returns:
        One ``(key, value)`` per counter, in :data:`INPUT_COUNTER_NAMES` order.

    """
    return [(key, str(sum(int(c.get(name, 0)) for c in counts)))
            for name, key in INPUT_COUNTER_NAMES.items()]


def _size(shape: tuple[int, ...]) -> str:
    return f'{shape[1]}x{shape[0]}'


def _sizes(shapes: tuple[tuple[int, ...], tuple[int, ...]]) -> str:
    return f'{_size(shapes[0])}/{_size(shapes[1])}'
