"""The head evaluation's own helpers: drop-out frames and the warm-start methods' configs."""

from __future__ import annotations

from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.tools.evaluate_head import dropout_frames, method_config
import pytest


def test_dropout_frames_start_every_n_frames_with_cycling_lengths():
    assert dropout_frames(10, 4, (1, 2)) == {2, 6, 7}


def test_method_configs_differ_in_the_warm_start_only():
    assert method_config('prediction') == PlaneNodeConfig()
    last = method_config('last')
    assert not last.tracking.enabled and last.pipeline == PlaneNodeConfig().pipeline
    cold = method_config('cold')
    assert not cold.tracking.enabled
    assert cold.pipeline == one_shot_search(PlaneNodeConfig()).pipeline
    with pytest.raises(ValueError, match='unknown method'):
        method_config('warm')
