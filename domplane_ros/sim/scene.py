"""The renderer's names in one place, for callers written before the renderer was split.

New code imports from the module that does the job: :mod:`~domplane_ros.sim.model` (set-up,
boxes, frames), :mod:`~domplane_ros.sim.textures` (floor kinds), :mod:`~domplane_ros.sim.render`
(:func:`render_stereo`), :mod:`~domplane_ros.sim.generators` (random scenes and sequences) and
:mod:`~domplane_ros.sim.head` (active head sequences).
"""

from domplane_ros.sim.generators import (random_boxes, random_scene, random_setup,
                                         scene_sequence, SETUP_RANGES)
from domplane_ros.sim.head import head_sequence, HeadMotion, ring_of_boxes
from domplane_ros.sim.model import BACKGROUNDS, Box, CameraSetup, HeadPose, StereoFrame
from domplane_ros.sim.render import render_stereo
from domplane_ros.sim.textures import (ALL_FLOOR_KINDS, FLOOR_KINDS, PLAIN_FLOOR_KINDS,
                                       TEXTURE_VARIANTS)

__all__ = [
    'ALL_FLOOR_KINDS', 'BACKGROUNDS', 'Box', 'CameraSetup', 'FLOOR_KINDS', 'HeadMotion',
    'HeadPose', 'PLAIN_FLOOR_KINDS', 'SETUP_RANGES', 'StereoFrame', 'TEXTURE_VARIANTS',
    'head_sequence', 'random_boxes', 'random_scene', 'random_setup', 'render_stereo',
    'ring_of_boxes', 'scene_sequence',
]
