"""Hand-eye from rendered board captures taken by the robot, through ``virtus handeye``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.support import cropped_rig
from virtus.calib import board_from_spec, board_texture
from virtus.cli import main
from virtus.geometry.transforms import Pose
from virtus.render import RenderSettings
from virtus.robot.capture import capture_at
from virtus.robot.config import load_robot_file
from virtus.robot.ik import Unreachable
from virtus.scanner import Scanner
from virtus.scene.model import PlaneObject, Scene, TexturedPlaneObject
from virtus.sensor.projector import Lookup, ProjectorModel

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda_wrist.yaml"
#: A 54 x 60 mm circle board: it fits the 320 px crop of the paper's camera at 0.9 m.
BOARD = "circles:4x7,spacing_mm=12,diameter_mm=6,border_mm=6"
#: The board on the floor in front of the robot (world z up), printed side up.
BOARD2WORLD = Pose.from_euler("xyz", [180.0, 0.0, 90.0], t=[0.5, 0.0, 0.001])


def _views(setup, count: int) -> list[np.ndarray]:  # noqa: ANN001
    """Reachable configurations looking at the board from 0.85-0.95 m, within 25 deg of
    straight down, turned by up to 25 deg about the optical axis."""
    rng = np.random.default_rng(5)
    centre, qs = BOARD2WORLD.t, []
    while len(qs) < count:
        polar, azimuth = np.radians(rng.uniform(0, 25)), rng.uniform(0, 2 * np.pi)
        d = np.array([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                      np.cos(polar)])  # fmt: skip
        view = Pose.look_at(centre + rng.uniform(0.85, 0.95) * d, centre, (1.0, 0.0, 0.0))
        try:
            qs.append(setup.solve_view(view @ Pose.from_euler("z", [rng.uniform(-25, 25)]),
                                       rng=len(qs), starts=16).q)  # fmt: skip
        except Unreachable:
            continue
    return qs


def test_handeye_from_rendered_board_captures(tmp_path: Path, capsys) -> None:
    setup = load_robot_file(EXAMPLE)
    board = board_from_spec(BOARD)
    plane = TexturedPlaneObject(size_m=board.plane_size_m, texture=board_texture(board),
                                pose=BOARD2WORLD)  # fmt: skip
    scene = Scene(objects=[plane], background=PlaneObject((3.0, 3.0), Pose.identity()))
    scanner = Scanner(rig=cropped_rig(320), projector=ProjectorModel(pixel=Lookup.bilinear),
                      render=RenderSettings(spp=1))  # fmt: skip
    qs = _views(setup, 8)
    for k, q in enumerate(qs):
        capture_at(scanner, scene, setup, q, tmp_path / f"{k:02d}", seed=k).save(
            tmp_path / f"{k:02d}", overwrite=True
        )
    # the robot poses as joint values (a trajectory file), turned into poses by --robot
    (tmp_path / "q.json").write_text(json.dumps({"q": [q.tolist() for q in qs]}))
    argv = ["handeye", *sum((["--captures", str(tmp_path / f"{k:02d}")] for k in range(8)), []),
            "--robot-poses", str(tmp_path / "q.json"), "--robot", str(EXAMPLE),
            "--board", BOARD, "--out", str(tmp_path / "he"), "--json"]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0, err
    record = json.loads(out)
    # measured 0.0008 deg / 0.011 mm; the bounds leave a factor ~10 for other platforms'
    # rounding in detection, and still fail on any frame or sign error (centimetres)
    assert record["truth"]["rotation_error_deg"] < 0.01
    assert record["truth"]["translation_error_mm"] < 0.1
    assert 0 < record["expected_translation_error_mm"] < 0.3
    assert record["residual_unit"] == "px" and record["residual_rms"] < 0.05
    assert (tmp_path / "he" / "handeye.json").is_file()
