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


def test_contact_sheet_shows_every_label_in_full():
    from types import SimpleNamespace

    from domplane_ros.tools.demo import contact_sheet, frame_label
    import numpy as np

    reason = ('search found no verified plane: plane not verified: plane explains too little '
              'of the image (score 0.17 < verification.min_score 0.25)')
    left = np.full((120, 160), 100, np.uint8)

    def frame(index, ok):
        result = SimpleNamespace(ok=ok, reason='' if ok else reason, mask=np.zeros_like(left),
                                 left_points=np.zeros((0, 2)), n_inliers=5,
                                 estimate=SimpleNamespace(inliers=np.zeros(0, bool)))
        return SimpleNamespace(index=index, transfer_error_px=0.1 if ok else float('nan'),
                               replayed=SimpleNamespace(left=left, result=result))

    frames = [frame(0, False), frame(1, True)]
    assert frame_label(frames[0]).endswith(reason + ')')
    sheet = contact_sheet(frames, tiles=2, cols=2, tile_width=320)
    one_line = contact_sheet([frames[1], frames[1]], tiles=2, cols=2, tile_width=320)
    # The long label wraps onto more lines (the sheet grows) rather than being cut off.
    assert sheet.shape[1] == one_line.shape[1]
    assert sheet.shape[0] >= one_line.shape[0] + 2 * 14
