"""plane_replay's outputs never replace what is not a bag, and a refused output leaves nothing.

Found by the session-13 audit (docs/HARDENING.md, "Audit (session 13)"): ``--force`` deleted
any folder or file given as OUTPUT_BAG; a ``--csv`` file that could not be created left the
hidden partial bag folder behind; and a topic given as the node names it (``left/image_raw``)
was not found in a bag that records it as ``/left/image_raw``.
"""

from __future__ import annotations

from bag_helpers import read_bag, tree, write_bag
from domplane_ros.replay.cli import EXIT_OK, EXIT_REFUSED, main
import pytest


@pytest.fixture
def bag(tmp_path, frames):
    path = tmp_path / 'in'
    write_bag(path, frames[:2], 'sqlite3')
    return path


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith('plane_replay: error: '), captured.err
    assert 'Traceback' not in captured.err
    return lines[0]


@pytest.mark.parametrize('kind', ['folder', 'file'])
def test_force_does_not_replace_what_is_not_a_bag(tmp_path, bag, capsys, kind):
    out = tmp_path / 'data'
    if kind == 'folder':
        (out / 'sub').mkdir(parents=True)
        (out / 'notes.txt').write_text('mine')
        (out / 'sub' / 'more.txt').write_text('mine too')
    else:
        out.write_text('mine')
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--force', '--no-progress'])
    line = _one_error_line(capsys)
    assert rc == EXIT_REFUSED
    assert str(out) in line and '--force only replaces a bag' in line
    if kind == 'folder':
        assert "'notes.txt'" in line and (out / 'notes.txt').read_text() == 'mine'
    else:
        assert 'is a file' in line and out.read_text() == 'mine'
    assert tree(tmp_path) == before


def test_force_with_keep_partial_does_not_replace_what_is_not_a_bag(tmp_path, bag, capsys):
    out = tmp_path / 'out'
    (tmp_path / 'out.incomplete').mkdir()
    (tmp_path / 'out.incomplete' / 'notes.txt').write_text('mine')
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--force', '--keep-partial', '--no-progress'])
    assert rc == EXIT_REFUSED and 'out.incomplete' in _one_error_line(capsys)
    assert tree(tmp_path) == before


@pytest.mark.parametrize('which', ['csv', 'bag'])
def test_output_that_cannot_be_created_is_refused_and_leaves_nothing(tmp_path, bag, capsys,
                                                                     which):
    # A regular file where a folder should be: refused as a read-only folder is, also as root.
    (tmp_path / 'plain.txt').write_text('x')
    out = tmp_path / ('plain.txt' if which == 'bag' else '') / 'out'
    csv_path = tmp_path / ('plain.txt' if which == 'csv' else '') / 'pairs.csv'
    before = tree(tmp_path)
    capsys.readouterr()
    rc = main([str(bag), str(out), '--csv', str(csv_path), '--no-progress'])
    line = _one_error_line(capsys)
    assert rc == EXIT_REFUSED
    assert ('cannot create the CSV file' if which == 'csv'
            else 'cannot create the output bag') in line
    assert tree(tmp_path) == before   # no hidden .out.partial-* folder either


def test_relative_topic_names_find_the_bags_absolute_topics(tmp_path, bag, capsys):
    out = tmp_path / 'out'
    rc = main([str(bag), str(out), '--left-topic', 'left/image_raw',
               '--right-topic', 'right/image_raw', '--no-progress'])
    assert rc == EXIT_OK
    assert len(read_bag(out)['messages']['/plane/mask']) == 2
    # The diagnostics name the topics as the bag (and the node) does.
    diagnostics = read_bag(out)['messages']['/diagnostics'][-1][1]
    keys = [kv.key for kv in diagnostics.status[0].values]
    assert '/left/image_raw images received' in keys
    capsys.readouterr()
    rc = main([str(bag), str(tmp_path / 'out2'), '--left-topic', 'left/image_raw',
               '--right-topic', '/left/image_raw', '--no-progress'])
    assert rc == EXIT_REFUSED and 'the same' in _one_error_line(capsys)
