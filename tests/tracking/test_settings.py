"""The settings by group (tracker.tracking.settings): scaled by their pixel metadata, changed by group."""

import dataclasses

import pytest

from tracker.tracking.settings import Settings, scaled_to


def test_pixel_settings_grow_with_the_image_and_stay_for_small_ones():
    base = Settings()
    assert scaled_to(base, 480) == base and scaled_to(base, 240) == base
    hd = scaled_to(base, 1080)
    assert hd.outline.spacing == pytest.approx(9.0) and hd.outline.search_range == 45
    assert hd.outline.final_search_range == 14
    assert hd.edges.blur_sigma == pytest.approx(2.25) and hd.edges.threshold == pytest.approx(6.0 / 2.25)
    assert hd.region.margin == 4  # the parts move as many more pixels between iterations
    assert hd.region.inside == 9 and hd.region.outside == 22 and hd.images.reference_size == 1080
    assert hd.solve.robust_c == base.solve.robust_c  # in pixels, but fixed
    assert scaled_to(hd, 1080) == hd  # already scaled: unchanged


def test_every_field_that_grows_or_shrinks_is_scaled_and_no_other():
    """Whatever field says it is in pixels that grow (or shrink) is scaled by 2.25 from 480 to 1080 pixels (an
    integer rounded, at its least), and every other field keeps its value."""
    base = Settings()
    hd = scaled_to(base, 1080)
    for group in dataclasses.fields(base):
        before, after = getattr(base, group.name), getattr(hd, group.name)
        for spec in dataclasses.fields(before):
            old, new, pixels = getattr(before, spec.name), getattr(after, spec.name), spec.metadata["pixels"]
            if pixels == "grows":
                expected = max(spec.metadata["least"], round(old * 2.25)) if isinstance(old, int) else old * 2.25
            elif pixels == "shrinks":
                expected = old / 2.25
            else:
                expected = 1080 if spec.name == "reference_size" else old
            assert new == pytest.approx(expected), (group.name, spec.name)
            assert type(new) is type(old), (group.name, spec.name)


def test_every_field_has_its_help_and_the_settings_change_by_group():
    for group in dataclasses.fields(Settings()):
        for spec in dataclasses.fields(getattr(Settings(), group.name)):
            assert spec.metadata["help"], (group.name, spec.name)
    changed = Settings().but(motion=dict(dynamics="none"), solve=dict(iterations=10))
    assert changed.motion.dynamics == "none" and changed.solve.iterations == 10
    assert changed.motion.damping == Settings().motion.damping and changed.outline == Settings().outline
    with pytest.raises(TypeError):
        Settings().but(motion=dict(iterations=10))  # a field of another group


def test_a_pixel_kind_other_than_grows_shrinks_or_fixed_is_refused():
    from tracker.tracking.settings import setting

    with pytest.raises(ValueError, match="grows, shrinks or fixed"):
        setting(1.0, "a length", pixels="big")
