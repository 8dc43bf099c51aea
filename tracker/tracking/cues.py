"""The cues the tracker asks in every iteration, in this order (:class:`tracker.tracking.cue.Cue`); each is built
from the tracker it serves (``kind(tracker)``), which has its model, rig, settings and first poses."""

from tracker.tracking.edge_cue import EdgeCue
from tracker.tracking.keypoint_cue import KeypointCue
from tracker.tracking.region_cue import RegionCue

CUES = (EdgeCue, KeypointCue, RegionCue)
