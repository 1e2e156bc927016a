"""Geometry of the plane shared by every stage: neighbour search, vector lengths."""
