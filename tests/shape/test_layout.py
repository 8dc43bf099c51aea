"""The shape's unknowns (tracker.shape.layout): the given model at the start, tied sides, the prior."""

from __future__ import annotations

import numpy as np
from conftest import HUMAN

from tracker.model import model_from_dict
from tracker.proportions import sizes
from tracker.shape.layout import Layout, partners
from tracker.tomlfile import read_toml


def test_the_start_is_the_given_model_and_tied_sides_mirror():
    document = read_toml(HUMAN, "model", "")
    model = model_from_dict(document)
    tied, apart = Layout.of(model), Layout.of(model, tie_sides=False)
    assert apart.width == 3 * (14 + 15) + 1 and tied.width == 3 * (8 + 9) + 1
    for layout in (tied, apart):
        x = layout.start()
        assert [s.metres for s in sizes(layout.document(x, document))] == [s.metres for s in sizes(document)]
        np.testing.assert_allclose(layout.joints(x), model.rest[:, :3, 3])
    assert [model.names[i] for i in partners(model.names)][model.index("thigh_r")] == "thigh_l"
    x = tied.start()
    x[tied.joint[model.index("upperarm_l")] : tied.joint[model.index("upperarm_l")] + 3] = [0.25, 0.01, 0.4]
    joints = tied.joints(x)
    np.testing.assert_allclose(joints[model.index("upperarm_l")], [0.25, 0.01, 0.4])
    np.testing.assert_allclose(joints[model.index("upperarm_r")], [-0.25, 0.01, 0.4])


def test_the_prior_holds_the_given_model_scaled_and_each_joint_on_its_parents_stretch():
    model = model_from_dict(read_toml(HUMAN, "model", ""))
    layout = Layout.of(model)
    prior = layout.prior(2.0, 3.0, span_weight=5.0)
    x = layout.start()
    assert np.abs(prior @ x).max() < 1e-12
    scaled = x * 1.1  # every joint and factor, and the common scale: the model scaled whole
    assert np.abs(prior @ scaled).max() < 1e-12
    off = x.copy()
    i = model.index("forearm_l")
    off[layout.joint[i] + 2] += 0.01  # the elbow 1 cm lower: off the scale and off the upper arm's stretch
    residual = prior @ off
    np.testing.assert_allclose(np.sort(np.abs(residual[residual != 0])), [0.02, 0.05])
    stretched = x.copy()
    f = layout.factor[model.index("upperarm_l")]
    stretched[f + 2] = 1.1  # the upper arm 10 % longer, its elbow with it: only the scale prior objects
    stretched[layout.joint[i] : layout.joint[i] + 3] = 1.1 * model.rest[i, :3, 3] * [1, 1, 1]
    residual = prior @ stretched
    np.testing.assert_allclose(np.abs(residual[residual != 0]), [2.0 * 0.1 * 0.29, 3.0 * 0.1], atol=1e-12)


def test_a_held_joint_is_pulled_to_the_given_model_as_firmly_as_the_span():
    model = model_from_dict(read_toml(HUMAN, "model", ""))
    layout = Layout.of(model)
    x = layout.start()
    i = model.index("forearm_l")
    x[layout.joint[i] + 2] += 0.01
    held = np.zeros(model.size, bool)
    held[[i, model.index("forearm_r")]] = True  # both sides of the tied set
    residual = layout.prior(2.0, 3.0, span_weight=5.0, held=held) @ x
    np.testing.assert_allclose(np.sort(np.abs(residual[residual != 0])), [0.05, 0.05])
    held[model.index("forearm_r")] = False  # one side seen: the set is measured
    residual = layout.prior(2.0, 3.0, span_weight=5.0, held=held) @ x
    np.testing.assert_allclose(np.sort(np.abs(residual[residual != 0])), [0.02, 0.05])
