"""Board specs (:func:`virtus.calib.board.board_from_spec`): each length named as the spec
names it, finite and positive; flags and lengths written as such."""

from __future__ import annotations

import pytest

from virtus.calib.board import CheckerBoard, CircleBoard, board_from_spec
from virtus.errors import InputError

CIRCLES = "circles:4x11,spacing_mm={s},diameter_mm={d}"


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (CIRCLES.format(s=-40, d=20), r"^board spacing_mm: expected a length > 0 \(mm\), got '-40"),
        (CIRCLES.format(s="nan", d=20), r"^board spacing_mm: expected a length > 0"),
        (CIRCLES.format(s="inf", d=20), r"^board spacing_mm: expected a length > 0"),
        (CIRCLES.format(s=0, d=20), r"^board spacing_mm"),
        (CIRCLES.format(s=40, d=-1), r"^board diameter_mm: expected a length > 0"),
        (CIRCLES.format(s=40, d=30), r"^board diameter_mm: expected less than spacing_mm / sqrt"),
        (CIRCLES.format(s=40, d=20) + ",border_mm=-1", r"^board border_mm: expected a length >= 0"),
        (CIRCLES.format(s=40, d=20) + ",border_mm=nan", r"^board border_mm"),
        ("circles:4x11,spacing_mm,diameter_mm=20", r"^board spacing_mm: expected '=' and a length"),
        (CIRCLES.format(s=40, d=20) + ",white_on_black=0", r"^board white_on_black: expected"),
        ("checker:6x9,square_mm=-25", r"^board square_mm: expected a length > 0"),
        ("checker:6x9,square_mm=nan", r"^board square_mm"),
        ("checker:6x9,square_mm=x", r"^board square_mm: expected a length > 0 \(mm\), got 'x'"),
    ],
)  # fmt: skip
def test_bad_lengths_are_named_as_the_spec_names_them(spec: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as error:
        board_from_spec(spec)
    assert "center_distance" not in str(error.value) and "circle_diameter" not in str(error.value)


def test_good_specs_still_build() -> None:
    board = board_from_spec(CIRCLES.format(s=40, d=20) + ",border_mm=0,white_on_black")
    assert isinstance(board, CircleBoard) and board.center_distance_mm == 40.0
    assert board.border_mm == 0.0 and board.light_features
    checker = board_from_spec("checker:6x9,square_mm=25")
    assert isinstance(checker, CheckerBoard) and checker.square_mm == 25.0


def test_the_dataclasses_refuse_a_nan_border() -> None:
    with pytest.raises(InputError, match="^border_mm"):
        CircleBoard(border_mm=float("nan"))
    with pytest.raises(InputError, match="^border_mm"):
        CheckerBoard(border_mm=float("nan"))
