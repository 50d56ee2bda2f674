"""Seeded synthetic data with ground truth: rendered stereo scenes and point sets."""
