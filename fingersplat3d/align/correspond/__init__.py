"""Finding correspondences between views: the ridge texture, cylinder charts and their turn votes, guided
and feature matching, epipolar checks, and the predictor that carries a pixel through a 3D model.

Nothing here solves for cameras or surfaces (that is ``align.solve``, which imports from here, never the
other way round).
"""
