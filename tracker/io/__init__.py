"""Input and output: recording folders, frame readers, poses.npz, atomic file writes."""
