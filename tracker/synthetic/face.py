"""A face and hair painted on a rendered head, so that a person detector can tell its front from its back.

A point X on the head (metres, in the head component's frame: x to the body's left, y backwards, z up;
models/human.toml) is placed on the head's bounding ellipsoid (centre c, radii r) by u = (X - c) / r:

    azimuth   a = atan2(u_x, -u_y)      0 straight ahead, > 0 towards the body's left, +-pi at the back
    height    e = u_z / |u|             -1 under the chin ... +1 on the crown

Features are soft ellipses in (a, e) with a ramp at their rim, painted over the skin in this order:
ears (darker skin at a = +-1.5), eyes (white, with a dark iris), eyebrows, the nose's shadow on the
side away from the key light and its nostrils, the lips; then hair wherever e is above a hairline
that runs from the forehead (e = 0.55 in front) down the temples to the nape (e = -0.45 at the back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HAIR = np.array([0.07, 0.10, 0.16])
"""BGR reflectance of dark brown hair."""

_FEATURES = (
    # azimuth, height, half widths (azimuth, height), BGR colour (None: the skin darkened by the factor)
    (1.5, 0.0, 0.16, 0.25, None, 0.8),  # ears
    (-1.5, 0.0, 0.16, 0.25, None, 0.8),
    (0.38, 0.12, 0.19, 0.07, (0.92, 0.92, 0.92), 1.0),  # whites of the eyes
    (-0.38, 0.12, 0.19, 0.07, (0.92, 0.92, 0.92), 1.0),
    (0.38, 0.12, 0.08, 0.065, (0.12, 0.18, 0.22), 1.0),  # irises
    (-0.38, 0.12, 0.08, 0.065, (0.12, 0.18, 0.22), 1.0),
    (0.40, 0.28, 0.24, 0.035, tuple(HAIR), 1.0),  # eyebrows
    (-0.40, 0.28, 0.24, 0.035, tuple(HAIR), 1.0),
    (-0.1, -0.05, 0.06, 0.22, None, 0.78),  # the nose's shadow
    (0.08, -0.25, 0.05, 0.03, (0.15, 0.2, 0.3), 1.0),  # nostrils
    (-0.08, -0.25, 0.05, 0.03, (0.15, 0.2, 0.3), 1.0),
    (0.0, -0.47, 0.30, 0.06, (0.30, 0.30, 0.62), 1.0),  # lips
    (0.0, -0.47, 0.26, 0.012, (0.12, 0.12, 0.3), 1.0),  # the line between them
)


@dataclass(frozen=True)
class Face:
    """A face on component ``component``: the head's bounding ellipsoid ``centre`` and ``radii`` (3,) in its
    frame, ``skin`` and ``hair`` BGR (3,) in [0, 1]."""

    component: int
    centre: np.ndarray
    radii: np.ndarray
    skin: np.ndarray
    hair: np.ndarray


def head_coordinates(face: Face, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth a (M,) radians and height e (M,) in [-1, 1] of head points (M, 3) (see the module)."""
    u = (np.asarray(points, float) - face.centre) / face.radii
    return np.arctan2(u[:, 0], -u[:, 1]), u[:, 2] / np.maximum(np.linalg.norm(u, axis=1), 1e-12)


def hairline(azimuth: np.ndarray) -> np.ndarray:
    """The height (M,) above which the head is hair: 0.55 over the forehead (|a| < 1), 0.2 at the temples
    (|a| = 1.4), -0.45 at the nape (|a| >= 2.1), linear between."""
    return np.interp(np.abs(azimuth), [0.0, 1.0, 1.4, 2.1, np.pi], [0.55, 0.55, 0.2, -0.45, -0.45])


def paint_face(face: Face, points: np.ndarray) -> np.ndarray:
    """BGR colours (M, 3) in [0, 1] of head points (M, 3) in the head's frame: skin, features, hair."""
    azimuth, height = head_coordinates(face, points)
    colour = np.tile(face.skin, (len(azimuth), 1))
    for a0, e0, wa, we, paint, factor in _FEATURES:
        cover = _ellipse(azimuth - a0, height - e0, wa, we)
        target = face.skin * factor if paint is None else np.asarray(paint)
        colour += cover[:, None] * (target - colour)
    hair = np.clip((height - hairline(azimuth)) / 0.04, 0.0, 1.0)
    return colour + hair[:, None] * (face.hair - colour)


def _ellipse(da: np.ndarray, de: np.ndarray, wa: float, we: float) -> np.ndarray:
    """Coverage (M,) in [0, 1] of an ellipse of half widths ``wa``, ``we`` at offsets (da, de) from its
    centre: 1 inside, falling to 0 over the outer 15 % of its radius."""
    da = (da + np.pi) % (2.0 * np.pi) - np.pi
    rho = np.hypot(da / wa, de / we)
    return np.clip((1.0 - rho) / 0.15, 0.0, 1.0)
