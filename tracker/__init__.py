"""tracker: real-time model-based tracking of articulated bodies from calibrated cameras.

Frames.  Every stored rigid transform is a 4x4 array ``[[R, t], [0, 1]]`` (``numpy.ndarray``,
float64) named ``a_from_b``: it maps coordinates in frame b to frame a, so products read right to
left, ``camera_from_component = camera_from_world @ world_from_component``.  The frames are the
world (right-handed, z up, metres), each camera (x right, y down, z forward, OpenCV's) and each
component of the body (its origin is its joint with its parent).  A body's poses, ``poses``
(N, 4, 4), are world_from_component; a camera's extrinsics are ``Camera.camera_from_world``.  A
small motion is a body twist ``(v, w)`` (6,), translation first, applied on the right:
``E <- E exp(alpha)`` (docs/method-tracking.md, section 1).  Inside a formula the method's own
symbols stand (``E_i`` world_from_component, ``P_k`` camera_from_world).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tracker")
except PackageNotFoundError:  # run from a source tree that was never installed (pip install -e .)
    __version__ = "unknown (not installed)"
