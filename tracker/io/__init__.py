"""Input and output: recording folders, frame readers, pose files, poses.npz, live capture, marker files and exports."""
