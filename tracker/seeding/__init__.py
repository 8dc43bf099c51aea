"""Seeding the tracking method from the landmarks, above it: the first pose and the re-seeds of a pose gone astray
(docs/keypoints.md, "Automatic first pose").

pose_fit.py    the body model fitted to the landmarks: to their world points, then to their pixels in every view
first_pose.py  the first pose without an init file: fitted to the first frames' landmarks, snapped to the edges
recovery.py    never stay lost: a tracked pose that strays from the landmarks seeded again from them
"""
