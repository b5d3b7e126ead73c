"""What a lens may be: OpenCV's distortion vectors only, and a thin lens focused beyond its
focal length (:mod:`virtus.geometry.optics`)."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.geometry.devices import Rig, default_rig
from virtus.geometry.optics import MIN_F_NUMBER, OPENCV_DIST_LENGTHS, Intrinsics, ThinLens

K = [[100.0, 0.0, 31.5], [0.0, 100.0, 23.5], [0.0, 0.0, 1.0]]
RADIAL = [0.1, -0.05, 0.001, 0.002, 0.01, 0.003, -0.002, 0.001]


@pytest.mark.parametrize("length", OPENCV_DIST_LENGTHS)
def test_every_opencv_length_is_read(length: int) -> None:
    coeffs = (RADIAL + [0.0] * 6)[:length]
    lens = Intrinsics.from_opencv(K, coeffs, 64, 48)
    assert lens.dist == tuple(coeffs[:8])


@pytest.mark.parametrize("length", [1, 2, 3, 6, 7, 9, 10, 11, 13, 15])
def test_other_lengths_are_refused_not_padded(length: int) -> None:
    with pytest.raises(InputError, match=rf"^dist: expected 0, 4, 5, 8, 12 or 14 .*{length}"):
        Intrinsics.from_opencv(K, [0.0] * length, 64, 48)


def test_thin_prism_and_tilt_terms_are_refused_in_one_line() -> None:
    with pytest.raises(InputError, match=r"^dist: expected at most 8") as error:
        Intrinsics.from_opencv(K, [0.0] * 12 + [0.1, 0.0], 64, 48)
    assert "\n" not in str(error.value) and "[0.0, 0.0, 0.0, 0.0, 0.1, 0.0]" in str(error.value)


@pytest.mark.parametrize("device", ["camera", "projector"])
def test_the_rig_names_the_device_whose_dist_is_wrong(device: str) -> None:
    data = default_rig().to_dict()
    data[device]["dist"] = [0.1] * 7
    with pytest.raises(InputError, match=rf"^{device}\.dist: expected 0, 4, 5, 8, 12 or 14"):
        Rig.from_dict(data)
    data[device]["dist"] = [0.1, 0.0, 0.0, 0.0]
    assert Rig.from_dict(data) is not None


def test_a_lens_focuses_only_beyond_its_focal_length() -> None:
    # no lens is faster than f/0.5: an aperture A has a focal length of at least A / 2
    aperture = 0.01
    shortest = MIN_F_NUMBER * aperture
    assert ThinLens(aperture, shortest * 1.02).focus_distance_m == pytest.approx(0.0051)
    for focus in (shortest, 0.001):
        with pytest.raises(InputError, match=r"^focus_distance_m: expected a focus distance"):
            ThinLens(aperture, focus)
    with pytest.raises(InputError, match=r"^focal_length_m: expected at least 0\.005 m"):
        ThinLens(aperture, 1.0, focal_length_m=0.004)
    assert ThinLens.from_f_number(1.4, 0.05, 1.0).aperture_m == pytest.approx(0.05 / 1.4)
    with pytest.raises(InputError, match="focal_length_m"):
        ThinLens.from_f_number(0.4, 0.05, 1.0)  # f/0.4: faster than any lens
    np.testing.assert_allclose(ThinLens(0.01, 1.0).blur_diameter_px(1.0, 1000.0), 0.0)
