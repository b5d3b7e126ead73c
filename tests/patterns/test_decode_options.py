"""The decode options are checked before any pixel is: a saturation level outside the
frames' range is refused naming it, instead of an empty decode blamed on the modulation
(:func:`virtus.patterns.decode.decode_frames`)."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.patterns import default_sequence
from virtus.patterns.decode import check_saturation_level


def _frames(sequence) -> np.ndarray:
    width = 32
    images = [np.tile(sequence.profile(i)[:width] if sequence.profile(i).size > 1
                      else np.full(width, sequence.profile(i)[0]), (4, 1))
              for i in range(len(sequence))]  # fmt: skip
    return np.rint(np.asarray(images) * 200 + 20).astype(np.uint8)


@pytest.mark.parametrize("level", [0, -5, 0.0, 256, 300.0, float("nan"), float("inf"), True, "x"])
def test_a_saturation_level_outside_the_frames_range_is_refused(level: object) -> None:
    sequence = default_sequence(32, 32)
    with pytest.raises(InputError, match=r"^saturation_level: expected") as error:
        sequence.decode(_frames(sequence), saturation_level=level)
    assert "modulation" not in str(error.value)


def test_levels_inside_the_range_are_used() -> None:
    sequence = default_sequence(32, 32)
    frames = _frames(sequence)
    assert sequence.decode(frames, saturation_level=255).mask.any()
    assert not sequence.decode(frames, saturation_level=1).mask.any()  # all at or above 1 DN
    assert check_saturation_level(None, 255.0) is None
    assert check_saturation_level(np.float32(250), 255.0) == 250.0
    with pytest.raises(InputError, match=r"^--saturation-level: expected a level in \(0, 4095\]"):
        check_saturation_level(5000, 4095.0, "--saturation-level")
