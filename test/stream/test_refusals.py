"""Refusals and lock losses counted by kind: the keys and lines of /diagnostics and the replay.

The pipeline's behaviour is tested in test_lock_reference.py and test_trust.py (a lock refused
by its reference, or lost at a cut, and re-found in the same pair); here the bookkeeping.
"""

from __future__ import annotations

import csv
import io
import json

from domplane_ros.stream.refusals import (LOCK_LOSS_KINDS, Refusal, REFUSAL_KINDS,
                                          RefusalCounts, refusals_text)
from domplane_ros.stream.status import plane_status


def test_counts_by_kind_and_refound_only_after_a_refusal():
    counts = RefusalCounts()
    reference = Refusal('reference', 'plane not verified: score 0.31 fell below 0.7 x 0.58')
    counts.add(reference, [reference], published=True)
    counts.add(Refusal('challenger', 'a challenger explained clearly more'), [], True)
    counts.add(Refusal('cut', 'lost track'), [Refusal('cut', 'lost track'),
                                              Refusal('search', 'prior search found no plane')],
               published=False)
    counts.add(None, [Refusal('estimate', 'energy jumped')], published=False)
    assert counts.locks_lost == {**dict.fromkeys(LOCK_LOSS_KINDS, 0), 'reference': 1,
                                 'challenger': 1, 'cut': 1}
    assert counts.planes_refused == {**dict.fromkeys(REFUSAL_KINDS, 0), 'reference': 1,
                                     'cut': 1, 'search': 1, 'estimate': 1}
    # A challenger always publishes: that is no lock re-found.
    assert counts.refound == 1
    assert counts.last_lock_lost == Refusal('cut', 'lost track')
    assert counts.summary_lines() == [
        '  locks lost:      3 (reference 1, cut 1, challenger 1), re-found in the same pair 1',
        '  planes refused:  4 (reference 1, estimate 1, cut 1, search 1)']
    assert RefusalCounts().summary_lines() == [
        '  locks lost:      0, re-found in the same pair 0', '  planes refused:  0']


def test_every_key_is_present_from_the_start_and_in_the_status():
    values = dict(RefusalCounts().diagnostic_values(None))
    assert values.pop('lock lost (last frame)') == 'none'
    assert values.pop('last lock lost') == 'none'
    assert values.pop('locks re-found in the same pair') == 0
    assert values == {**{f'locks lost ({k})': 0 for k in LOCK_LOSS_KINDS},
                      **{f'planes refused ({k})': 0 for k in REFUSAL_KINDS}}
    counts = RefusalCounts()
    drop = Refusal('drop', "score 0.20 fell below verification.drop_ratio 0.5 x the lock's 0.55")
    counts.add(drop, [drop], published=False)

    class Last:
        ok, reason, lock_lost, warm_start, confidence, candidates = False, 'x', drop, '', 0, 0
        n_inliers = 0

    _, _, status = plane_status(
        rate=1.0, latencies_ms=[1.0], pairs=1, processed=1, dropped_busy=0, dropped_sync=0,
        decode_errors=0, lock_state='searching', reinitialisations=1, consecutive_failures=1,
        last_result=Last(), last_error='', refusals=counts)
    keys = [key for key, _ in status]
    shown = dict(status)
    assert shown['lock lost (last frame)'] == shown['last lock lost'] == str(drop)
    assert shown['locks lost (drop)'] == shown['planes refused (drop)'] == '1'
    # Right after re-initialisations (the searches started), in a fixed order.
    start = keys.index('re-initialisations') + 1
    assert keys[start:start + 2] == ['lock lost (last frame)', 'last lock lost']
    # Without counts (an adapter that keeps none), no keys.
    _, _, bare = plane_status(
        rate=1.0, latencies_ms=[1.0], pairs=1, processed=1, dropped_busy=0, dropped_sync=0,
        decode_errors=0, lock_state='searching', reinitialisations=1, consecutive_failures=1,
        last_result=None, last_error='')
    assert not [key for key, _ in bare if 'lock' in key and key != 'lock state']


def test_the_csv_column_survives_commas_quotes_and_semicolons():
    refusals = [Refusal('gate', 'not the ground: 4 % beyond (> 3 %); a plane "through" boxes?'),
                Refusal('search', 'search found no verified plane: ambiguous, a distinct plane')]
    text = refusals_text(refusals)
    stream = io.StringIO()
    csv.writer(stream).writerow(['1', text, 'last'])
    row = next(csv.reader(io.StringIO(stream.getvalue())))
    assert row[2] == 'last' and json.loads(row[1]) == [str(r) for r in refusals]
    assert json.loads(row[1])[0].startswith('gate: not the ground')
    assert refusals_text([]) == '[]'
