"""Report figures: PNG bytes that depend on the data alone, one colour map per quantity,
signed quantities on symmetric scales, missing data drawn grey."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from virtus.report import figures
from virtus.report.figures import QUANTITIES


def _rgb(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def test_same_data_same_bytes_and_no_metadata() -> None:
    ramp = np.linspace(0, 1, 400).reshape(20, 20)
    a = figures.image_map(ramp, "modulation", "ramp")
    b = figures.image_map(ramp.copy(), "modulation", "ramp")
    assert a == b and a[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"Software" not in a and b"matplotlib" not in a
    assert figures.image_map(ramp * 2, "modulation", "ramp") != a
    assert Image.open(io.BytesIO(a)).size == (512, 384)


def test_each_quantity_has_one_colour_map_and_a_unit() -> None:
    maps = [q.cmap for name, q in QUANTITIES.items() if name not in ("difference",)]
    assert len(maps) == len(set(maps)) + 1  # proj_u shares viridis with absolute phase only
    for quantity in QUANTITIES.values():
        assert "(" in quantity.label and quantity.label.endswith(")")  # a unit in brackets
    assert QUANTITIES["signed_error"].symmetric and not QUANTITIES["depth"].symmetric


def test_missing_data_is_grey_and_signed_limits_are_symmetric() -> None:
    values = np.full((40, 40), np.nan)
    values[:20] = 0.3
    values[20:, :20] = -0.1
    png = figures.image_map(values, "signed_error", "error")
    pixels = _rgb(png).reshape(-1, 3)
    grey = (pixels == (0xD9, 0xD9, 0xD9)).all(axis=1)
    assert grey.sum() > 1000  # the NaN quarter, drawn as "no data"
    low, high = figures._limits(values, QUANTITIES["signed_error"], None)
    assert low == -high and high == pytest.approx(0.3)


def test_histogram_and_bars_and_fields_draw() -> None:
    counts, edges = np.array([1, 5, 9, 5, 1]), np.linspace(-1, 1, 6)
    png = figures.histogram_chart(counts, edges, "radial error (mm)", "h",
                                  marks=((0.5, "threshold"),), note="radius 99.99 mm")  # fmt: skip
    assert _rgb(png).std() > 0
    assert figures.bar_chart(["a", "b"], {"x": [1, 2], "y": [2, 1]}, "px", "b")[:4] == b"\x89PNG"
    uv = np.array([[10.0, 10.0], [50.0, 40.0]])
    assert figures.vector_field([("camera", (64, 48), uv, uv * 0.01)], "r")[:4] == b"\x89PNG"
    assert figures.scatter_fields([("camera", (64, 48), [("p", uv)])], "c")[:4] == b"\x89PNG"
    frustum = np.array([[0, 0, 0], [-1, -1, 3], [1, -1, 3], [1, 1, 3], [-1, 1, 3]], float)
    board = np.array([[0, 0, 9], [1, 0, 9], [1, 1, 9], [0, 1, 9]], float)
    assert figures.poses_3d([("camera", frustum)], [("b", board)], "p")[:4] == b"\x89PNG"
