"""A frame's status, as ``poses.npz`` stores it: how far its tracked pose can be trusted."""

TRACKED, UNCERTAIN, LOST = 0, 1, 2
NAMES = ("tracked", "uncertain", "lost")
"""The status codes' names, indexed by code."""
