"""bench_pipeline: rows print with and without timed pairs."""

from __future__ import annotations

from domplane_ros.tools import bench_pipeline


def test_a_row_with_nothing_timed_prints_nan(capsys):
    # --cold-pairs 0 leaves the cold row empty: it crashed in np.percentile before round 9.
    bench_pipeline.print_row(bench_pipeline.Row('cold'))
    assert capsys.readouterr().out.split()[1:3] == ['nan', 'nan']


def test_a_timed_row_prints_its_median_and_the_ratio(capsys):
    row = bench_pipeline.Row('warm', ours=[0.010, 0.012, 0.014], base=[0.030, 0.030, 0.030])
    bench_pipeline.print_row(row)
    out = capsys.readouterr().out
    assert out.split()[1] == '12.00'
    assert 'x 2.50' in out
