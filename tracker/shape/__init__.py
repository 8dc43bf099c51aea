"""The body model fitted to the person: its joints and its parts' sizes from a recording (docs/fit-model.md).

:mod:`tracker.shape.layout` lays out the unknowns (every joint's place, every part's stretch, one common scale)
and their priors; :mod:`tracker.shape.from_landmarks` fits them to the keypoint detector's triangulated landmarks,
:mod:`tracker.shape.edges` to the image edges along the model's outlines, and :mod:`tracker.shape.model_fit` runs both
on a recording, alternating with the poses.
"""
