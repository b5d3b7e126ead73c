"""``virtus handeye``: robot poses that do not match the captures, degenerate or unreadable
input -> one line, exit 2, nothing written."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from virtus.cli import main


def _poses(path, count: int):  # noqa: ANN001, ANN202
    poses = [{"R": np.eye(3).tolist(), "t": [0.1 * k, 0.0, 0.5]} for k in range(count)]
    path.write_text(json.dumps({"hand2base": poses}))
    return path


@pytest.mark.parametrize(
    ("poses", "flags", "message"),
    [
        (3, [], r"--robot-poses: expected 2 poses \(one per capture\), got '3 poses'"),
        (2, ["--mode", "sideways"], r"--mode: expected one of \('eye_in_hand', 'eye_to_hand'\)"),
        (None, [], r"robot poses: expected a \"hand2base\" list or a trajectory"),
        (2, [], r"hand-eye needs at least 3 robot poses \(two motions\); got 2"),
    ],
)
def test_bad_input_is_one_line_exit_2(poses, flags, message, tiny, tmp_path, capsys) -> None:
    import re

    captures = tmp_path / "captures"
    for k in range(2):
        shutil.copytree(tiny / "cap", captures / f"{k:02d}")
    pose_file = tmp_path / "poses.json"
    if poses is None:
        pose_file.write_text(json.dumps({"poses": []}))
    else:
        _poses(pose_file, poses)
    out = tmp_path / "he"
    argv = [
        "handeye",
        "--captures",
        str(captures),
        "--robot-poses",
        str(pose_file),
        "--board",
        "4x7",
        "--out",
        str(out),
        *flags,
    ]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    stdout, err = capsys.readouterr()
    assert exit_info.value.code == 2 and stdout == ""
    assert len(err.strip().splitlines()) == 1 and re.search(message, err), err
    assert not out.exists()
