"""The demo renders, records, replays and draws its outputs."""

from __future__ import annotations

from bag_helpers import read_bag
import cv2


def test_demo_writes_its_outputs(tmp_path, capsys):
    from domplane_ros.tools.demo import DEMO_OUTPUTS, main as demo_main

    out = tmp_path / 'demo'
    out.mkdir()
    (out / 'notes.txt').write_text('not from the demo')
    (out / 'overlay.png').write_text('stale')
    argv = ['--output', str(out), '--frames', '4', '--width', '192', '--height', '144']
    assert demo_main(argv) == 0
    printed = capsys.readouterr().out
    assert 'Refreshing the previous demo outputs' in printed
    assert 'plane found in' in printed and 'mean transfer error' in printed
    assert (out / 'notes.txt').read_text() == 'not from the demo'
    for name in DEMO_OUTPUTS:
        assert (out / name).exists(), name
    assert cv2.imread(str(out / 'overlay.png')).shape[1] == 192
    assert cv2.imread(str(out / 'contact_sheet.png')) is not None
    assert cv2.imread(str(out / 'energy_inliers.png')) is not None
    bag = read_bag(out / 'plane_bag')
    assert len(bag['messages']['/plane/mask']) == 4
