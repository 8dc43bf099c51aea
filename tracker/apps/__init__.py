"""The apps: what runs the tracking method on a recording or on cameras, above it and the tools beside it.

track.py      the library form of ``tracker track``: a recording tracked, poses.npz written (``tracker batch`` too)
live.py       live tracking from cameras (``tracker live``)
sync.py       ``tracker sync --refine``: each camera's offset refined by its edges against a track of the others
bench.py      stage timings, fps, decode floor, scaling (``tracker bench``)
loop.py       the frame loop that each of them runs: every frame tracked, checked, written to poses.npz, handed on

keypoint_stream.py, beside them: the detector over the recording they track, a worker process that detects every
step-th frame ahead of the tracker and hands each frame's landmarks over in order.
"""
