"""plane_replay and the audit's findings 13 (mono16 range) and 17 (no plane in any pair).

docs/HARDENING.md, "Audit (session 13)": a bag whose every pair was refused exited 0, where
plane_pair exits 4 for a pair without a plane; a 12-bit camera's mono16 bag gave no plane and
no hint about the image.
"""

from __future__ import annotations

from types import SimpleNamespace

from bag_helpers import _header, LEFT, left_stamp, read_bag, RIGHT, T, TS, write_bag
import cv2
from domplane_ros.replay.cli import EXIT_NO_PLANE, EXIT_OK, main
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer


def test_a_bag_without_a_plane_in_any_pair_exits_5_with_its_output(tmp_path, frames, capsys):
    # The right camera at half size: every pair refused (left/right sizes differ).
    small = [SimpleNamespace(left=f.left, right=cv2.resize(f.right, None, fx=0.5, fy=0.5))
             for f in frames[:3]]
    write_bag(tmp_path / 'in', small, 'sqlite3')
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--no-progress'])
    captured = capsys.readouterr()
    assert rc == EXIT_NO_PLANE == 5
    (line,) = [text for text in captured.err.splitlines() if text.strip()]
    assert line.startswith('plane_replay: no plane: none of the 3 processed pairs gave a plane')
    assert 'differ in size' in line and line.endswith('the output was written')
    assert 'plane found:     0 (0.0 %)' in captured.out
    # The output is complete: one mask and one result per pair, as with a plane.
    assert len(read_bag(tmp_path / 'out')['messages']['/plane/mask']) == 3
    # A bag with planes still exits 0.
    write_bag(tmp_path / 'good', frames[:2], 'sqlite3')
    assert main([str(tmp_path / 'good'), str(tmp_path / 'out2'), '--no-progress']) == EXIT_OK


def _mono16_bag(path, frames) -> None:
    """Write a 12-bit camera's mono16 bag: grey << 4, every value below 4096."""
    kind = 'sensor_msgs/msg/Image'
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns = {LEFT: writer.add_connection(LEFT, kind, typestore=TS),
                 RIGHT: writer.add_connection(RIGHT, kind, typestore=TS)}
        for i, frame in enumerate(frames):
            for topic, gray in ((LEFT, frame.left), (RIGHT, frame.right)):
                height, width = gray.shape
                data = np.frombuffer((gray.astype('<u2') << 4).tobytes(), np.uint8)
                msg = T[kind](header=_header(left_stamp(i), topic), height=height,
                              width=width, encoding='mono16', is_bigendian=0, step=2 * width,
                              data=data.copy())
                writer.write(conns[topic], left_stamp(i) + 5_000_000,
                             TS.serialize_cdr(msg, kind))


def _diagnostics(path):
    msgs = read_bag(path)['messages']['/diagnostics']
    return [{kv.key: kv.value for kv in msg.status[0].values} for _, msg in msgs]


def test_a_12_bit_mono16_bag_gets_a_note_and_its_plane_with_mono16_bits(tmp_path, frames,
                                                                        capsys):
    _mono16_bag(tmp_path / 'in', frames[:3])
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--no-progress'])
    out = capsys.readouterr().out
    notes = [line for line in out.splitlines() if line.startswith('  note: ')]
    assert len(notes) == 1 and 'image.mono16_bits' in notes[0], out
    assert '(12 fit the data)' in notes[0]
    assert rc in (EXIT_OK, EXIT_NO_PLANE)
    assert 'image.mono16_bits' in _diagnostics(tmp_path / 'out')[-1]['image warning']
    # The sensor's bits: the replay of the 8-bit bag, no note.
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    image:\n      mono16_bits: 12\n')
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out12'), '--no-progress',
               '--params-file', str(params)])
    out12 = capsys.readouterr().out
    write_bag(tmp_path / 'eight', frames[:3], 'sqlite3')
    assert main([str(tmp_path / 'eight'), str(tmp_path / 'out8'), '--no-progress']) == rc
    out8 = capsys.readouterr().out
    assert rc == EXIT_OK and 'note:' not in out12
    found = [line for line in out12.splitlines() if 'plane found' in line]
    assert found == [line for line in out8.splitlines() if 'plane found' in line]
    assert not found[0].startswith('  plane found:     0 ')   # measured: 2 of 3
    h12 = [m.data for _, m in read_bag(tmp_path / 'out12')['messages']['/plane/homography']]
    h8 = [m.data for _, m in read_bag(tmp_path / 'out8')['messages']['/plane/homography']]
    assert len(h12) == len(h8) >= 2 and all(np.array_equal(a, b) for a, b in zip(h12, h8))
    assert _diagnostics(tmp_path / 'out12')[-1]['image warning'] == 'none'
