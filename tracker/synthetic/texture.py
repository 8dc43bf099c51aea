"""Clothing textures for rendered bodies: solid patterns painted in each component's own frame.

A texture gives every point X on the body (metres, in its component's frame) a mix p in [0, 1]
between the component's albedo a and a contrasting colour b, colour = (1 - p) a + p b. As p is a
function of the component-frame point, the pattern moves with the body. Kinds:

    stripes  p = s(sin(2 pi (d . X) / period + phase))     bands across a direction d near the z axis
    print    p = 1 inside one ball per cell of a 3-D grid   spots of random place and size
    noise    p = s(value noise, two octaves)                mottled, like camouflage

with s a steep clipped ramp. Directions, periods, phases, spot sizes, lattice values and the
contrasting colours are drawn from the seed, the same for a left and a right component (``_l``,
``_r``), so a texture is deterministic and a shirt's sleeves match.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("stripes", "print", "noise")
"""The patterns; ``mixed`` (in :data:`CHOICES`) draws one per component pair."""

CHOICES = ("none", *KINDS, "mixed")
"""The values of ``tracker synth --texture``."""


@dataclass(frozen=True)
class Texture:
    """Per component (N): ``kind`` index into :data:`KINDS`, ``albedo`` and ``contrast`` BGR (N, 3) in [0, 1],
    stripe ``direction`` (N, 3) unit and ``period`` (N,) metres, ``phase`` (N,) radians, ``cell`` (N,) metres
    (print spots and noise lattice), ``salt`` (N,) uint64 seeding the lattice hash."""

    kind: np.ndarray
    albedo: np.ndarray
    contrast: np.ndarray
    direction: np.ndarray
    period: np.ndarray
    phase: np.ndarray
    cell: np.ndarray
    salt: np.ndarray


def make_texture(kind: str, names: tuple[str, ...], albedo: np.ndarray, *, seed: int) -> Texture:
    """A texture of ``kind`` (one of :data:`KINDS` or ``mixed``) for components ``names`` with albedos (N, 3)."""
    if kind not in (*KINDS, "mixed"):
        raise ValueError(f"texture {kind!r} is not one of {', '.join(CHOICES[1:])}")
    rng = np.random.default_rng([seed, 7])
    pairs = sorted({_pair(name) for name in names})
    drawn = {}
    for pair in pairs:
        tilt = rng.uniform(-0.4, 0.4, 2)
        drawn[pair] = {
            "kind": KINDS.index(kind) if kind != "mixed" else int(rng.integers(len(KINDS))),
            "direction": np.array([tilt[0], tilt[1], 1.0]) / np.hypot(1.0, np.hypot(*tilt)),
            "period": rng.uniform(0.05, 0.1),
            "phase": rng.uniform(0.0, 2.0 * np.pi),
            "cell": rng.uniform(0.05, 0.09),
            "shift": rng.uniform(-0.15, 0.15, 3),
            "salt": int(rng.integers(1, 2**62)),
        }
    rows = [drawn[_pair(name)] for name in names]
    albedo = np.asarray(albedo, dtype=np.float64)
    return Texture(
        kind=np.array([row["kind"] for row in rows], dtype=np.int64),
        albedo=albedo,
        contrast=np.clip(1.0 - albedo + np.array([row["shift"] for row in rows]), 0.05, 0.95),
        direction=np.array([row["direction"] for row in rows]),
        period=np.array([row["period"] for row in rows]),
        phase=np.array([row["phase"] for row in rows]),
        cell=np.array([row["cell"] for row in rows]),
        salt=np.array([row["salt"] for row in rows], dtype=np.uint64),
    )


def _pair(name: str) -> str:
    """A component's name without its side: ``thigh_l`` and ``thigh_r`` share their pattern."""
    return name[:-2] if name.endswith(("_l", "_r")) else name


def paint(texture: Texture, component: np.ndarray, points: np.ndarray) -> np.ndarray:
    """BGR colours (M, 3) in [0, 1] of surface points (M, 3) given in the frames of their components (M,)."""
    mix = np.zeros(len(points))
    kinds = texture.kind[component]
    for k, name in enumerate(KINDS):
        sel = kinds == k
        if not sel.any():
            continue
        c, x = component[sel], points[sel]
        if name == "stripes":
            along = np.einsum("ma,ma->m", x, texture.direction[c]) / texture.period[c]
            mix[sel] = np.clip(0.5 + 2.0 * np.sin(2.0 * np.pi * along + texture.phase[c]), 0.0, 1.0)
        elif name == "print":
            mix[sel] = _spots(x / texture.cell[c, None], texture.salt[c])
        else:
            fine = value_noise(2.5 * x / texture.cell[c, None], texture.salt[c] ^ np.uint64(0x5BD1E995))
            value = (value_noise(x / texture.cell[c, None], texture.salt[c]) + 0.5 * fine) / 1.5
            mix[sel] = np.clip(0.5 + 3.0 * (value - 0.5), 0.0, 1.0)
    mix = mix[:, None]
    return (1.0 - mix) * texture.albedo[component] + mix * texture.contrast[component]


def lattice_hash(cells: np.ndarray, salt: np.ndarray, lane: int = 0) -> np.ndarray:
    """Uniform numbers in [0, 1) (M,) from integer lattice cells (M, 3) and per-point salts (M,): a
    multiply-xorshift mix of the 64-bit words (SplitMix64's finaliser)."""
    words = cells.astype(np.int64).view(np.uint64)
    h = salt ^ np.uint64(lane * 0x9E3779B97F4A7C15 % 2**64)
    for a, prime in zip(words.T, (0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9, 0x27D4EB2F165667C5)):
        h = h ^ (a * np.uint64(prime))
        h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        h = h ^ (h >> np.uint64(31))
    return (h >> np.uint64(11)).astype(np.float64) * 2.0**-53


def _spots(x: np.ndarray, salt: np.ndarray) -> np.ndarray:
    """Coverage (M,) of one ball per unit cell of the lattice at the points x (M, 3) in cell units: radius
    0.18..0.35, its centre placed so that the ball stays inside its cell; a ramp 0.05 cells wide at the rim."""
    cells = np.floor(x)
    radius = 0.18 + 0.17 * lattice_hash(cells, salt, 0)
    centre = np.stack([radius + (1.0 - 2.0 * radius) * lattice_hash(cells, salt, lane) for lane in (1, 2, 3)], axis=1)
    distance = np.linalg.norm(x - cells - centre, axis=1)
    return np.clip(0.5 + (radius - distance) / 0.05, 0.0, 1.0)


def value_noise(x: np.ndarray, salt: np.ndarray) -> np.ndarray:
    """Smooth noise in [0, 1] (M,) at points x (M, 3) in lattice units: random values at the lattice
    corners, blended with the weights 3 u^2 - 2 u^3 of the point's place u in its cell."""
    base = np.floor(x)
    u = x - base
    w = u * u * (3.0 - 2.0 * u)
    out = np.zeros(len(x))
    for corner in np.ndindex(2, 2, 2):
        offset = np.array(corner, dtype=np.float64)
        weight = np.prod(np.where(offset == 1.0, w, 1.0 - w), axis=1)
        out += weight * lattice_hash(base + offset, salt)
    return out
