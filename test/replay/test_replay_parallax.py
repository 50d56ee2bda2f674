"""plane_replay --parallax: the node's residual parallax image of every pair, in the output bag."""

from __future__ import annotations

from bag_helpers import expected_results, mask_array, read_bag, write_bag
from domplane_ros.core.mask import NOT_MEASURED, OBSTACLE, PLANE
from domplane_ros.replay.cli import main
from domplane_ros.stream.frame import parallax_image
import numpy as np


def test_parallax_images_are_the_nodes_for_every_pair(tmp_path, frames, capsys):
    stamps = write_bag(tmp_path / 'in', frames, 'sqlite3')
    expected = expected_results(frames, stamps)
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--parallax', '--no-progress'])
    out = capsys.readouterr().out
    assert rc == 0
    assert f'/plane/parallax {len(stamps)}' in out
    bag = read_bag(tmp_path / 'out')
    assert bag['types']['/plane/parallax'] == 'sensor_msgs/msg/Image'
    assert '/plane/debug_image' not in bag['types']
    parallax = bag['messages']['/plane/parallax']
    masks = bag['messages']['/plane/mask']
    # One per processed pair, at the mask's bag time and with its header (the left image's).
    assert [t for t, _ in parallax] == [t for t, _ in masks] == stamps
    for (_, msg), (_, mask_msg), result in zip(parallax, masks, expected):
        assert msg.header == mask_msg.header
        assert (msg.encoding, msg.is_bigendian, msg.step) == ('32FC1', 0, 4 * msg.width)
        values = np.frombuffer(np.asarray(msg.data, np.uint8).tobytes(), '<f4').reshape(
            msg.height, msg.width)
        assert np.array_equal(values, parallax_image(result))
        assert np.all(np.isfinite(values))
        assert np.all((values >= 0.0) | (values == NOT_MEASURED))
        mask = mask_array(mask_msg)
        if not result.ok:
            assert np.all(values == NOT_MEASURED)
            continue
        # The mask was decided on it: measured plane pixels show less parallax than the
        # threshold (1 px) in the median (those the clean-up added carry the coarse flow's
        # value), obstacle pixels more.
        plane = (mask == PLANE) & (values >= 0.0)
        obstacle = (mask == OBSTACLE) & (values >= 0.0)
        assert np.median(values[plane]) < 1.0 < np.median(values[obstacle])
    assert sum(result.ok for result in expected) >= 2  # 4 of the 8 pairs have a plane


def test_without_the_option_no_parallax_is_written(tmp_path, frames, capsys):
    stamps = write_bag(tmp_path / 'in', frames[:2], 'sqlite3')
    assert main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--no-progress']) == 0
    assert '/plane/parallax' not in capsys.readouterr().out
    bag = read_bag(tmp_path / 'out')
    assert '/plane/parallax' not in bag['types']
    assert len(bag['messages']['/plane/mask']) == len(stamps)
