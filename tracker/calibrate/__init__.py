"""Camera rig calibration from board videos: ``tracker calibrate``.

board.py       the --board spec, the board's corners, detection (chessboard orientation, ChArUco)
sources.py     the cameras of a calibration folder, the board search over their frames
intrinsics.py  K and distortion per camera (Zhang / cv2.calibrateCamera)
extrinsics.py  board poses, robust pairwise poses, spanning tree, bundle adjustment
pipeline.py    the steps from a folder of board views to a rig, and the per-camera report
"""
