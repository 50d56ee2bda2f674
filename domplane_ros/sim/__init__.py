"""Seeded synthetic data with ground truth: rendered stereo scenes and point sets.

``model`` (the stereo head, boxes, frames) -> ``textures`` -> ``render`` (the ray caster) ->
``generators`` (random scenes, walking sequences) and ``head`` (active head sequences);
``truth`` scores a homography against a rendered frame; ``synthetic`` draws point and line
sets for the core.
"""
