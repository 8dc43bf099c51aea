"""The tracking method (docs/method-tracking.md): the body's outline in every view, the edges searched
along it, and the frame loop that fits the poses to them.

outline.py         visible outline samples and their Jacobian rows; sections 2-3
ownership.py       search limits: which predicted outline may claim an image edge
measure.py         edge search, IRLS weights, per-component information; section 3
region_cue.py      the region cue: colours learnt along the outline, the outline's offset posterior per line
keypoint_cue.py    the 2-D keypoints' landmarks fused with the edges in the solve
landmark_noise.py  the keypoints' learnt noise: each landmark's zone, and how firmly the edges hold its limb
motion_prior.py    the Kalman motion prior (``--dynamics kalman``) and the motion a tracker carries between frames
track.py           the frame loop (:class:`~tracker.tracking.track.Tracker`) and its settings; section 6
foreground.py      the empty scene: median and cleared backgrounds, the difference image the edges are searched in
view_time.py       when a view was captured, from its edges against a track of the other views (``tracker sync``)

The rendered-data generator (:mod:`tracker.synthetic`) exists to test this method and is never imported by it.
"""
