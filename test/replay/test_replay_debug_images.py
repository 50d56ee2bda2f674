"""plane_replay --debug-images: the node's debug overlay of every pair, in the output bag."""

from __future__ import annotations

from bag_helpers import (expected_results, mask_array, PERIOD_NS, read_bag, STAMP0_NS,
                         write_bag)
from domplane_ros.core.mask import OBSTACLE, PLANE, UNKNOWN
from domplane_ros.replay.cli import main
from domplane_ros.stream.frame import debug_overlay
import numpy as np


def test_debug_images_are_the_overlay_of_every_pair(tmp_path, frames, capsys):
    stamps = write_bag(tmp_path / 'in', frames, 'mcap')
    expected = expected_results(frames, stamps)
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--debug-images',
               '--no-progress'])
    out = capsys.readouterr().out
    assert rc == 0
    assert f'/plane/debug_image {len(stamps)}' in out
    bag = read_bag(tmp_path / 'out')
    assert bag['storage'] == 'mcap'    # Foxglove opens MCAP as it is
    assert bag['types']['/plane/debug_image'] == 'sensor_msgs/msg/Image'
    debug = bag['messages']['/plane/debug_image']
    masks = bag['messages']['/plane/mask']
    # One per processed pair, at the mask's bag time and with its header (the left image's).
    assert [t for t, _ in debug] == [t for t, _ in masks] == stamps
    for (_, msg), (_, mask_msg), result, stamp in zip(debug, masks, expected, stamps):
        assert msg.header == mask_msg.header
        assert (msg.encoding, msg.step) == ('rgb8', 3 * msg.width)
        rgb = np.asarray(msg.data, np.uint8).reshape(msg.height, msg.width, 3)
        left = frames[(stamp - STAMP0_NS) // PERIOD_NS].left
        assert np.array_equal(rgb, debug_overlay(left, result))
        mask = mask_array(mask_msg)
        r, g, b = (rgb[..., k].astype(int) for k in range(3))
        grey = (r == g) & (g == b)
        # The tint says what the mask says: plane green, obstacle red, undecided untinted
        # (except under the drawn marks).
        if np.any(mask == PLANE):
            assert np.mean(g[mask == PLANE] > r[mask == PLANE]) > 0.9
        if np.any(mask == OBSTACLE):
            assert np.mean(r[mask == OBSTACLE] > g[mask == OBSTACLE]) > 0.9
        if np.any(mask == UNKNOWN):
            assert np.mean(grey[mask == UNKNOWN]) > 0.9
    assert any(result.ok for result in expected)
