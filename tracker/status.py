"""A frame's status, as ``poses.npz`` stores it: how far its tracked pose can be trusted."""

TRACKED, UNCERTAIN, LOST, RESEEDED = 0, 1, 2, 3
NAMES = ("tracked", "uncertain", "lost", "re-seeded")
"""The status codes' names, indexed by code.  ``RESEEDED``: the tracked pose had strayed from the keypoint
detector's landmarks (or was lost), and the frame was tracked again from a pose fitted to them."""
