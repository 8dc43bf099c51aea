"""The cue interface (tracker.tracking.cue): a cue plugs in by its line in tracker.tracking.cues.CUES alone, and the
tracker asks it as it asks the others: it prepares on each frame, adds its information in every iteration, says what
it read of each part in the last, learns after the frame, forgets on a restart and is shown in an inspection."""

import itertools
from pathlib import Path

import numpy as np

from tracker.io.posefile import load_pose_file
from tracker.io.recording import frames, open_recording
from tracker.model import load_model
from tracker.tracking import frame_loop
from tracker.tracking.cues import CUES
from tracker.tracking.settings import Settings

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"
PULL = np.array([0.05, 0.0, 0.0])  # metres: where the test cue wants the pelvis, from where it stands


class Beacon:
    """A cue that pulls the pelvis (component 0) PULL along the world's axes from its pose at the frame's start, with
    a weight far above the edges', and notes every call the tracker makes."""

    name = "beacon"
    stage = "measure"
    places = True

    def __init__(self, tracker):
        self.calls: list[str] = []
        self.target = None

    def restart(self) -> None:
        self.calls.append("restart")

    def warm_up(self, tracker) -> None:
        self.calls.append("warm_up")

    def prepare(self, tracker, frame):
        self.calls.append("prepare")
        self.target = tracker.poses[0, :3, 3] + PULL
        return None

    def add(self, tracker, work, iteration) -> None:
        self.calls.append(f"add {iteration.index}")
        rotation, position = tracker.poses[0, :3, :3], tracker.poses[0, :3, 3]
        weight = 1e9
        work.information[0, :3, :3] += weight * np.eye(3)
        work.eta[0, :3] += weight * rotation.T @ (self.target - position)  # body-frame translation

    def evidence(self, tracker, work, added):
        self.calls.append("evidence")
        return added

    def learn(self, tracker, status: int, *, kept: bool) -> None:
        self.calls.append("learn")

    def inspect(self, tracker, work):
        n = work.samples.count
        return np.zeros(n), np.ones(n)


def test_a_cue_listed_with_the_others_is_asked_in_every_step_and_moves_the_body(monkeypatch):
    monkeypatch.setattr(frame_loop, "CUES", (*CUES, Beacon))
    rec = open_recording(DEMO)
    model = load_model(rec.model_path)
    start = load_pose_file(rec.init_path, model)
    tracker = frame_loop.Tracker(model, rec.cameras, start, Settings().but(motion=dict(dynamics="none")))
    beacon = tracker.cue(Beacon)
    assert isinstance(beacon, Beacon) and beacon.calls == ["restart"]
    images = next(itertools.islice(frames(rec), 1))[1]
    tracker.step(images)
    iterations = Settings().solve.iterations
    assert beacon.calls[1:] == ["prepare", *(f"add {k}" for k in range(iterations)), "evidence", "learn"]
    np.testing.assert_allclose(tracker.poses[0, :3, 3], start[0, :3, 3] + PULL, atol=2e-3)
    assert set(tracker.inspect_cues()) == {"edges", "region", "beacon"}  # the keypoint cue reads no sample
    tracker.restart(start)
    assert beacon.calls[-1] == "restart"
