"""Dominant ground plane homography from a stereo pair, without correspondences."""
