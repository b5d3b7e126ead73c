"""The measuring volume: derived from the rig (both fields, the depth of field), or given."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.design.volume import (
    DEFAULT_DEPTH_FRACTION,
    FIELD_MARGIN,
    MAX_BLUR_PX,
    MeasuringVolume,
    check_volume,
    seen_by_both,
    volume_from_rig,
    volume_from_text,
    working_distance,
)
from virtus.errors import InputError
from virtus.geometry import ThinLens, default_rig
from virtus.render import RenderSettings

RIG = default_rig()


def _grown(volume: MeasuringVolume, factor: float) -> MeasuringVolume:
    """The volume with its lateral extent scaled by ``factor`` about its centre."""
    c, half = volume.centre_m, volume.size_m / 2
    half = half * np.array([factor, factor, 1.0])
    return MeasuringVolume(tuple(c - half), tuple(c + half))


def test_paper_rig_volume_is_centred_on_the_axes_crossing_and_as_large_as_the_fields_allow():
    distance, centre = working_distance(RIG)
    np.testing.assert_allclose(centre, [0.0, 0.0, 1.0], atol=tol.FLOAT64_EXACT)
    volume = volume_from_rig(RIG)
    np.testing.assert_allclose(volume.centre_m, [0.0, 0.0, 1.0], atol=1e-9)
    half_depth = DEFAULT_DEPTH_FRACTION * distance
    assert volume.lower_m[2] == pytest.approx(distance - half_depth)
    assert volume.upper_m[2] == pytest.approx(distance + half_depth)
    # The camera's field at the near depth limits it: 960 px / fx * 0.9 m, less the margin.
    cam = RIG.camera.intrinsics
    field = cam.width / cam.fx * volume.lower_m[2]
    assert volume.size_m[0] == pytest.approx(field * (1 - 2 * FIELD_MARGIN), rel=0.02)
    assert seen_by_both(RIG, volume.surface_points(), FIELD_MARGIN)
    assert not seen_by_both(RIG, _grown(volume, 1.001).surface_points(), FIELD_MARGIN)
    check_volume(volume, RIG)  # inside both fields


def test_lenses_bound_the_depth_by_their_blur():
    lens = ThinLens(aperture_m=0.02, focus_distance_m=1.0)
    volume = volume_from_rig(RIG, RenderSettings(camera_lens=lens))
    near, far = volume.lower_m[2], volume.upper_m[2]
    fx = RIG.camera.intrinsics.fx
    # at both ends the blur has just reached the limit (a 1 mm depth grid)
    for z in (near, far):
        assert lens.blur_diameter_px(z, fx) == pytest.approx(MAX_BLUR_PX, rel=0.05)
    assert near < 1.0 < far and far - near < 2 * DEFAULT_DEPTH_FRACTION
    # a wide aperture: a thinner volume
    wide = volume_from_rig(RIG, RenderSettings(camera_lens=ThinLens(0.04, 1.0)))
    assert wide.size_m[2] < volume.size_m[2]


def test_given_volume_outside_a_field_is_refused_naming_the_device():
    volume = volume_from_rig(RIG)
    with pytest.raises(InputError, match="--volume.*camera"):
        check_volume(_grown(volume, 1.2), RIG)
    beside = volume_from_text("300,-50,950,400,50,1050")  # right of the camera's field
    with pytest.raises(InputError, match="--volume"):
        check_volume(beside, RIG)


@pytest.mark.parametrize(
    "text", ["1,2,3", "a,b,c,d,e,f", "0,0,0,10,10,10", "0,0,-5,10,10,10", "0,0,5,0,10,10",
             "nan,0,900,10,10,1000"],
)  # fmt: skip
def test_bad_volume_text_is_refused(text):
    with pytest.raises(InputError, match="--volume"):
        volume_from_text(text)


def test_volume_text_in_millimetres_either_corner_order():
    volume = volume_from_text("100,50,1100,-100,-50,900")
    assert volume.lower_m == pytest.approx((-0.1, -0.05, 0.9))
    assert volume.upper_m == pytest.approx((0.1, 0.05, 1.1))
    assert volume.diagonal_m == pytest.approx(np.sqrt(0.2**2 + 0.1**2 + 0.2**2))
