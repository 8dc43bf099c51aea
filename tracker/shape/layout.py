"""The unknowns of a body's shape, laid out in one vector (docs/fit-model.md, "The unknowns").

    x = [at of every joint set (3 each), stretch factors of every component set (3 each), common scale s]

A joint set is one joint's place ``at_i`` in its parent's frame (every component but the root); a component
set holds the factors ``a_c`` that stretch its quadrics (:func:`tracker.proportions.reshaped`).  With the sides
tied, ``<part>_r`` shares ``<part>_l``'s sets, its joint mirrored across the body's midplane (x negated: the
model's x runs to the body's left).  The prior keeps the shape human and fixes what nothing measures:

    prior_joint (at_i - s at0_i) = 0,    prior_factor (a_c - s 1) = 0

(``at0`` the given model's joints): the body as given, scaled by one common s, unless the data say otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.model import Model
from tracker.proportions import reshaped


def partners(names: tuple[str, ...]) -> np.ndarray:
    """For each component (N,), the component whose sets it uses when the sides are tied: ``<part>_r`` uses
    ``<part>_l``'s, every other component its own."""
    out = np.arange(len(names))
    for index, name in enumerate(names):
        if name.endswith("_r") and f"{name[:-2]}_l" in names:
            out[index] = names.index(f"{name[:-2]}_l")
    return out


@dataclass(frozen=True)
class Layout:
    """Where each component's joint (``joint`` (N,) first column, -1 for the root, with ``sign`` (N, 3) +-1
    mirroring a tied right part) and factors (``factor`` (N,) first column) sit in x, its ``width`` (the common
    scale last), and the given model's joints ``at0`` (N, 3)."""

    names: tuple[str, ...]
    parent: np.ndarray
    joint: np.ndarray
    sign: np.ndarray
    factor: np.ndarray
    at0: np.ndarray
    width: int

    @staticmethod
    def of(model: Model, *, tie_sides: bool = True) -> Layout:
        owner = partners(model.names) if tie_sides else np.arange(model.size)
        joint_sets = [i for i in range(model.size) if owner[i] == i and model.parent[i] >= 0]
        factor_sets = [i for i in range(model.size) if owner[i] == i]
        joint = np.array([3 * joint_sets.index(owner[i]) if model.parent[i] >= 0 else -1 for i in range(model.size)])
        factor = np.array([3 * (len(joint_sets) + factor_sets.index(owner[i])) for i in range(model.size)])
        sign = np.ones((model.size, 3))
        sign[owner != np.arange(model.size), 0] = -1.0
        width = 3 * (len(joint_sets) + len(factor_sets)) + 1
        return Layout(model.names, model.parent.copy(), joint, sign, factor, model.rest[:, :3, 3].copy(), width)

    def joint_map(self, i: int) -> np.ndarray:
        """The (3, width) map from x to joint i's ``at``."""
        out = np.zeros((3, self.width))
        out[:, self.joint[i] : self.joint[i] + 3] = np.diag(self.sign[i])
        return out

    def start(self) -> np.ndarray:
        """x of the given model: its joints, every factor 1, s = 1."""
        x = np.ones(self.width)
        for i in np.flatnonzero(self.joint >= 0):
            x[self.joint[i] : self.joint[i] + 3] = self.sign[i] * self.at0[i]
        return x

    def joints(self, x: np.ndarray) -> np.ndarray:
        """Every component's ``at`` (N, 3) under x (the root's zero)."""
        out = np.zeros((len(self.names), 3))
        for i in np.flatnonzero(self.joint >= 0):
            out[i] = self.sign[i] * x[self.joint[i] : self.joint[i] + 3]
        return out

    def factors(self, x: np.ndarray) -> np.ndarray:
        """Every component's stretch factors (N, 3) under x."""
        return np.stack([x[f : f + 3] for f in self.factor])

    def prior(
        self, joint_weight: float, factor_weight: float, *, span_weight: float = 0.0, held: np.ndarray | None = None
    ) -> np.ndarray:
        """The prior's rows (R, width) (module docstring), each set once; the joints ``held`` (N,) bool (those no
        measurement reaches: every component of their set held) are pulled to the given model scaled with
        ``span_weight`` instead of ``joint_weight``."""
        held = np.zeros(len(self.names), bool) if held is None else held
        rows, seen = [], set()
        for i in map(int, np.flatnonzero(self.joint >= 0)):
            if self.joint[i] not in seen:
                seen.add(self.joint[i])
                weight = span_weight if held[self.joint == self.joint[i]].all() else joint_weight
                block = weight * self.joint_map(i)
                block[:, -1] = -weight * self.at0[i]
                rows.append(block)
                span = span_weight * self.joint_map(i)
                f = self.factor[self.parent[i]]
                span[:, f : f + 3] -= span_weight * np.diag(self.at0[i])
                rows.append(span)
        for f in np.unique(self.factor):
            block = np.zeros((3, self.width))
            block[:, f : f + 3] = factor_weight * np.eye(3)
            block[:, -1] = -factor_weight
            rows.append(block)
        return np.vstack(rows)

    def document(self, x: np.ndarray, base: dict, *, name: str | None = None) -> dict:
        """The model TOML document ``base`` (parsed, the model this layout was made of) reshaped to x."""
        joints, factors = self.joints(x), self.factors(x)
        return reshaped(
            base,
            {n: joints[i] for i, n in enumerate(self.names) if self.joint[i] >= 0},
            {n: factors[i] for i, n in enumerate(self.names)},
            name=name,
        )
