"""Geometry: SE(3) and quadrics."""
