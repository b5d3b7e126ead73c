"""The VDI/VDE 2634-2 artefacts: sizes from the volume's diagonal, positions spanning it."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.design.artefacts import FEATURES, artefact_layout
from virtus.design.volume import volume_from_rig, volume_from_text
from virtus.errors import InputError
from virtus.geometry.devices import default_rig


def test_artefacts_follow_the_guideline_sizes_and_span_the_volume():
    volume = volume_from_rig(default_rig())
    sizes, layout = artefact_layout(volume, default_rig())
    d = volume.diagonal_m
    assert 0.1 * d <= sizes.sphere_diameter_m <= 0.2 * d
    assert sizes.bar_length_m >= 2 / 3 * d - 1e-12
    counts = {f: sum(p.feature == f for p in layout) for f in FEATURES}
    assert counts == {"sphere": 10, "ball_bar": 7, "plane": 6}
    lo, hi = np.asarray(volume.lower_m), np.asarray(volume.upper_m)
    r = sizes.sphere_diameter_m / 2
    for position in layout:
        for c in position.centres_m:  # every sphere wholly inside the volume
            assert (np.asarray(c) - r >= lo - 1e-9).all() and (np.asarray(c) + r <= hi + 1e-9).all()
        if position.feature == "ball_bar":
            a, b = np.asarray(position.centres_m)
            assert np.linalg.norm(b - a) == pytest.approx(sizes.bar_length_m)
    spheres = np.array([p.centres_m[0] for p in layout if p.feature == "sphere"])
    np.testing.assert_allclose(spheres.min(axis=0), lo + r)  # reaching the volume's corners
    np.testing.assert_allclose(spheres.max(axis=0)[:2], (hi - r)[:2])
    with pytest.raises(InputError, match="--positions"):
        artefact_layout(volume, positions=11)


def test_a_volume_too_flat_for_the_ball_bar_is_refused():
    flat = volume_from_text("-150,-5,950,150,5,1050")  # 300 x 10 x 100 mm
    with pytest.raises(InputError, match="--volume.*ball bar"):
        artefact_layout(flat)
