"""The library behind ``python -m domplane_ros.tools.evaluate`` and the other evaluations.

``references`` (data folders, KITTI disparity plane, chessboards, transfer error) ->
``methods`` (the product's pipeline and the ORB + MAGSAC baseline) -> ``datasets`` (priors,
targets, both methods run and scored per pair) -> ``tables`` and ``plots``.
"""
