"""Solving for cameras and surfaces from correspondences: pairwise similarity (Procrustes, RANSAC), the
global problem (poses, focal, per-view depth fields) and its optimiser, the calibrated rig, pairwise
pointmaps turned into correspondences, and Open3D ICP.

Imports ``align.correspond`` for its data types; ``align.register`` drives both.
"""
