"""What a replay reports: one CSV row per processed pair, and the summary of the run."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
import os
from pathlib import Path
import tempfile
from typing import TextIO

from domplane_ros.core.estimator import PlaneEstimate
from domplane_ros.stream.candidates import PHOTOMETRIC
from domplane_ros.stream.pipeline import FrameResult
from domplane_ros.stream.refusals import lock_lost_text, RefusalCounts, refusals_text
import numpy as np

PROG = 'plane_replay'

CSV_COLUMNS = (
    'stamp_ns', 'ok', 'reinitialised', 'n_left', 'n_right', 'n_inliers', 'iterations',
    'final_energy', 'converged',
    'h00', 'h01', 'h02', 'h10', 'h11', 'h12', 'h20', 'h21', 'h22',
    'features_ms', 'estimate_ms', 'mask_ms', 'total_ms', 'state', 'warm_start', 'confidence',
    'reason', 'fast_motion', 'lock_lost', 'refusals',
)
# lock_lost: why the lock held before the pair was lost in it ('kind: reason', '' if not);
# refusals: every refusal that turned the pair's course, and a challenger refused (the lock
# stays), a JSON list of 'kind: reason' (the kinds: domplane_ros.stream.refusals).


class CsvOutput:
    """One row per processed pair, written to a temporary file renamed at commit."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        """Open the temporary file next to ``path`` and write the header row."""
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f'.{self.path.name}.', suffix='.partial',
                                   dir=self.path.parent)
        self._tmp = Path(tmp)
        self._stream: TextIO = os.fdopen(fd, 'w', newline='', encoding='utf-8')
        self._csv = csv.writer(self._stream)
        self._csv.writerow(CSV_COLUMNS)
        self.rows = 0

    def write(self, result: FrameResult) -> None:
        """Write the row of one processed pair."""
        estimate = result.estimate
        h = (result.homography.reshape(9).tolist() if result.homography is not None
             else [''] * 9)
        # A failed estimate has no energy and did not converge; it may say how far it got. A
        # photometric plane (too few corners) has no point energy either.
        solved = isinstance(estimate, PlaneEstimate)
        energy = solved and estimate.potential != PHOTOMETRIC
        timings = result.timings_ms
        self._csv.writerow([
            result.stamp_ns, int(result.ok), int(result.reinitialised),
            # Features: corners plus line segments (features.kind lines or both).
            result.left_points.shape[0] + result.left_lines.shape[0],
            result.right_points.shape[0] + result.right_lines.shape[0], result.n_inliers,
            int(getattr(estimate, 'iterations', 0)),
            repr(float(estimate.final_energy)) if energy else '',
            int(solved and bool(estimate.converged)),
            *[repr(float(v)) if v != '' else '' for v in h],
            *[f'{timings.get(k, float("nan")):.3f}'
              for k in ('features', 'estimate', 'mask', 'total')],
            result.state, result.warm_start, f'{result.confidence:.3f}', result.reason,
            int(result.fast_motion),
            lock_lost_text(result.lock_lost),
            refusals_text(result.refusals),
        ])
        self.rows += 1

    def commit(self, path: Path | None = None) -> None:
        """Close the file and move it into place (to ``path`` instead, if given)."""
        self._stream.close()
        # mkstemp makes the file private; give it the permissions open() would have.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self._tmp, 0o666 & ~umask)
        os.replace(self._tmp, path if path is not None else self.path)

    def abort(self) -> None:
        """Drop the partial file (never raises: it runs while another error is handled)."""
        try:
            self._stream.close()
        except OSError:
            pass   # a full disk cannot flush what is about to be removed anyway
        self._tmp.unlink(missing_ok=True)


@dataclass
class ReplaySummary:
    """What a replay did.

    Attributes:
        input_bag: The input bag.
        output_bag: The output bag.
        storage: Storage of the output bag.
        left_messages: Left image messages read.
        right_messages: Right image messages read.
        pairs: Pairs made by the synchroniser.
        processed: Pairs that went through the pipeline.
        plane_found: Processed pairs with a plane.
        converged: Processed pairs whose estimator met its tolerance.
        dropped_sync: Messages the synchroniser dropped.
        unpaired_at_end: Messages still waiting for a partner at the end of the bag.
        decode_errors: Pairs whose images could not be decoded.
        undecodable_messages: Messages that could not be deserialised.
        reinitialisations: Prior searches started.
        latency_ms: Decode plus processing time of every processed pair, ms.
        wall_s: Wall time of the run, seconds.
        written: Messages written per output topic.
        first_errors: The first few decode errors, for the report.
        input_problems: Input problems seen, by diagnostics key (only the non-zero ones).
        no_pairs: Why the bag gave no pair to process ('' if it gave some); then nothing
            was written.
        notes: What the run did with the node's inputs beside the images (the prior from
            ``camera_info.topic``, a topic it could not replay, mono16 data far below
            ``image.mono16_bits``).
        last_reason: The last processed pair's reason for having no plane ('' if it had one).
        refusals: Locks lost and planes refused by kind (:mod:`domplane_ros.stream.refusals`).

    """

    input_bag: str
    output_bag: str
    storage: str
    left_messages: int = 0
    right_messages: int = 0
    pairs: int = 0
    processed: int = 0
    plane_found: int = 0
    converged: int = 0
    dropped_sync: int = 0
    unpaired_at_end: int = 0
    decode_errors: int = 0
    undecodable_messages: int = 0
    reinitialisations: int = 0
    latency_ms: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    written: dict[str, int] = field(default_factory=dict)
    first_errors: list[str] = field(default_factory=list)
    input_problems: dict[str, int] = field(default_factory=dict)
    no_pairs: str = ''
    notes: list[str] = field(default_factory=list)
    last_reason: str = ''
    refusals: RefusalCounts = field(default_factory=RefusalCounts)

    @property
    def rate_pairs_per_s(self) -> float:
        """Return processed pairs per second of wall time."""
        return self.processed / self.wall_s if self.wall_s > 0 else 0.0

    def percent(self, count: int) -> float:
        """Return ``count`` as a percentage of the processed pairs (0 if none)."""
        return 100.0 * count / self.processed if self.processed else 0.0

    def latency_percentile(self, q: float) -> float:
        """Return a latency percentile in ms (NaN if nothing was processed)."""
        return float(np.percentile(self.latency_ms, q)) if self.latency_ms else float('nan')

    def lines(self) -> list[str]:
        """Return the human-readable summary."""
        out = [
            f'{PROG}: {self.input_bag} -> {self.output_bag} ({self.storage})',
            f'  messages read:   {self.left_messages} left, {self.right_messages} right',
            f'  pairs processed: {self.processed} of {self.pairs} paired '
            f'(dropped by sync: {self.dropped_sync} messages, unpaired at end: '
            f'{self.unpaired_at_end}, decode errors: {self.decode_errors} pairs + '
            f'{self.undecodable_messages} messages)',
            f'  plane found:     {self.plane_found} ({self.percent(self.plane_found):.1f} %), '
            f'converged {self.converged} ({self.percent(self.converged):.1f} %), '
            f're-initialisations {self.reinitialisations}',
            *self.refusals.summary_lines(),
            (f'  latency:         median {self.latency_percentile(50):.1f} ms, '
             f'p95 {self.latency_percentile(95):.1f} ms; ' if self.latency_ms
             else '  latency:         n/a (no pair processed); ')
            + f'{self.rate_pairs_per_s:.1f} pairs/s over {self.wall_s:.1f} s',
            ('  written:         ' + ', '.join(f'{topic} {count}'
                                               for topic, count in self.written.items())
             if not self.no_pairs else f'  written:         nothing ({self.no_pairs})'),
        ]
        if self.input_problems:
            out.append('  input problems:  ' + ', '.join(
                f'{key} {count}' for key, count in self.input_problems.items()))
        out += [f'  note: {text}' for text in self.notes]
        out += [f'  error: {text}' for text in self.first_errors]
        return out
