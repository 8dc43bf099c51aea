"""Camera rig calibration from board videos: ``tracker calibrate``.

board.py       the --board spec, the board's corners, detection (chessboard orientation, ChArUco)
sources.py     the cameras of a calibration folder, the board search over their frames
intrinsics.py  K and distortion per camera (Zhang / cv2.calibrateCamera)
extrinsics.py  board poses, robust pairwise poses, spanning tree, bundle adjustment
command.py     add_arguments(parser) and run(args) for the command line
"""
