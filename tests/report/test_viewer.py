"""The 3D view's packing: positions within a quantisation step, colours from the quantity's
colour map, grey for no value, seeded subsampling, an inline-safe payload."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from matplotlib import colormaps

from virtus.report.figures import QUANTITIES
from virtus.report.viewer import VIEWER_JS, pack_cloud, still_image


def _unpack(view) -> tuple[np.ndarray, np.ndarray]:
    q = np.frombuffer(base64.b64decode(view.positions_b64), dtype="<u2").reshape(-1, 3)
    points = q / 65535.0 * np.asarray(view.extent_m) + np.asarray(view.origin_m)
    index = np.frombuffer(base64.b64decode(view.colours_b64), dtype=np.uint8)
    return points, index


def test_positions_round_trip_within_one_step() -> None:
    rng = np.random.default_rng(3)
    points = rng.uniform((-0.1, -0.1, 0.9), (0.1, 0.1, 1.1), size=(5000, 3))
    view = pack_cloud(points, None, "depth")
    back, _ = _unpack(view)
    step = np.asarray(view.extent_m) / 65535.0
    assert np.all(np.abs(back - points) <= step / 2 + 1e-12)
    assert view.n_points == view.n_total == 5000


def test_colours_follow_the_quantitys_map_and_limits() -> None:
    points = np.column_stack([np.zeros(3), np.zeros(3), np.array([1.0, 1.1, 1.2])])
    view = pack_cloud(points, np.array([-2.0, 0.0, 2.0]), "signed_error", limits=(-2.0, 2.0))
    _, index = _unpack(view)
    assert index.tolist() == [0, 127, 254]
    expected = colormaps[QUANTITIES["signed_error"].cmap](0.0)[:3]
    assert view.palette[0] == [round(c * 255) for c in expected]
    assert "signed error (mm)" in view.label


def test_points_without_a_value_are_grey_and_kept() -> None:
    points = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [np.nan, 0.0, 1.0]])
    view = pack_cloud(points, np.array([0.5, np.nan, 0.1]), "signed_error")
    _, index = _unpack(view)
    assert view.n_points == 2  # the NaN point is dropped, the point without a value is not
    assert index[1] == 255 and view.palette[255][0] == view.palette[255][1]


def test_large_clouds_are_subsampled_the_same_way_each_time() -> None:
    points = np.random.default_rng(0).normal(size=(3000, 3)) + (0, 0, 2)
    a = pack_cloud(points, None, "depth", limit=1000)
    b = pack_cloud(points, None, "depth", limit=1000)
    assert a.n_points == 1000 and a.n_total == 3000
    assert a.positions_b64 == b.positions_b64


def test_payload_cannot_close_its_script_and_still_renders() -> None:
    view = pack_cloud(np.array([[0.0, 0.0, 1.0], [0.01, 0.02, 1.1]]), None, "depth")
    payload = view.payload()
    assert "</" not in payload
    assert json.loads(payload)["n"] == 2
    assert still_image(view, "two points")[:8] == b"\x89PNG\r\n\x1a\n"
    assert 'getContext("webgl"' in VIEWER_JS and "virtus-still" in VIEWER_JS


def test_unknown_quantity_is_refused() -> None:
    with pytest.raises(KeyError):
        pack_cloud(np.zeros((2, 3)) + 1, np.zeros(2), "temperature")
