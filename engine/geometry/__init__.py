"""Geometry every stage shares: the camera model, similarity transforms and their fits, the
upright world frame (table at z = 0), and checks of point arrays."""
