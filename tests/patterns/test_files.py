"""Sequence description files (:mod:`virtus.patterns.files`): the image list names a
different image for every frame."""

from __future__ import annotations

import json
import re

import pytest

from virtus.errors import InputError
from virtus.patterns import default_sequence, load_sequence_file


def _write(tmp_path, files: list[str]):
    data = default_sequence(912, 1140).to_dict()
    data["files"] = files
    path = tmp_path / "seq.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("first", "again", "at"),
    [("img0.png", "img0.png", 5), ("img0.png", "./img0.png", 51), ("a/b.png", "a/../a/b.png", 9)],
)
def test_one_image_for_two_frames_is_refused_naming_it(tmp_path, first, again, at) -> None:
    files = [f"img{i}.png" for i in range(52)]
    files[0], files[at] = first, again
    with pytest.raises(InputError, match=r"^files: expected a different image for every frame"):
        load_sequence_file(_write(tmp_path, files))
    with pytest.raises(InputError, match=re.escape(f"{again!r} for frames 0 and {at}")):
        load_sequence_file(_write(tmp_path, files))


def test_distinct_images_are_listed_in_order(tmp_path) -> None:
    files = [f"img{i}.png" for i in range(52)]
    sequence, listed = load_sequence_file(_write(tmp_path, files))
    assert listed == files and len(sequence) == 52
