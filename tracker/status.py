"""A frame's status, as ``poses.npz`` stores it: how far its tracked pose can be trusted; and each part's, whether
the images hold it or only the prior and the joints carry it (``held``, :mod:`tracker.tracking.held`)."""

TRACKED, UNCERTAIN, LOST, RESEEDED = 0, 1, 2, 3
NAMES = ("tracked", "uncertain", "lost", "re-seeded")
"""The status codes' names, indexed by code.  ``RESEEDED``: the tracked pose had strayed from the keypoint
detector's landmarks (or was lost), and the frame was tracked again from a pose fitted to them."""

HELD, LOOSE, UNSEEN = 0, 1, 2
HELD_NAMES = ("held by the images", "loosely held", "unseen")
"""A part's codes in a frame, indexed by code.  ``HELD``: the images place it in every direction they can see;
``LOOSE``: they read something of it, too little to place it, and the prior and the joints carry it; ``UNSEEN``: no
cue reads anything of it (hidden from every view, no edge found, no landmark)."""
