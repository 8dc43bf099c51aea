"""The tracking method (docs/method-tracking.md): the body's outline in every view, the cues read along it and at
the landmarks, and the frame loop that fits the poses to them all in one solve.

settings.py        the tracker's settings by group, each field with its help, its unit and its flag
rig.py             a camera rig as flat arrays for the kernels
samples.py         the buffers an outline sampling fills
outline.py         visible outline samples and their Jacobian rows; sections 2-3
ownership.py       search limits: which predicted outline may claim an image edge
measure.py         edge search, IRLS weights, per-component information; section 3
workspace.py       the buffers one search of a frame fills, its stage timings, and what a viewer is shown of it
cue.py             the interface every cue stands behind: prepare, add C_i and eta_i, learn, restart, inspect
cues.py            the cues the tracker asks, in order
edge_cue.py        the edge cue, and the images as its search reads them
keypoint_cue.py    the keypoint cue: the detector's landmarks pulling on the model points they mark
landmark_noise.py  the keypoints' learnt noise: each landmark's zone, and how firmly the edges hold its limb
region_cue.py      the region cue: the outline's offset posterior along each line, from the colours either side
region_lines.py    the region cue's lines in numba kernels: scored, added, counted
colours.py         the colours the region cue learns per part and background, and the colour images it reads
person.py          the person's masks from the detector, on the region cue's colour grid
held.py            which parts the images hold in a frame, and which the prior and the joints alone carry
lead.py            the limb lead: a limb beyond its edges' reach moved to its landmarks and tracked again
motion_prior.py    the Kalman motion prior (``--dynamics kalman``) and the motion a tracker carries between frames
motion_model.py    the motion models behind one interface (none, constant velocity, Kalman); poses moved along a motion
solve.py           one solve of the whole body: prior, trunk hold, tree solve, step, coercion; sections 3-5
frame_loop.py      the frame loop (:class:`~tracker.tracking.frame_loop.Tracker`); section 6
foreground.py      the empty scene: median and cleared backgrounds, the difference image the edges are searched in
view_time.py       when a view was captured, from its edges against a track of the other views (``tracker sync``)

The landmarks it reads, their names on the body model and the legs the detector guesses are below it
(:mod:`tracker.landmarks`); the first pose and the re-seeds that start it again are above it (:mod:`tracker.seeding`).
The rendered-data generator (:mod:`tracker.synthetic`) exists to test this method and is never imported by it.
"""
