"""The robot file: robot, base, mount and its checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.robot.config import load_robot_file

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "robots"


def _write(folder: Path, text: str) -> Path:
    path = folder / "robot.yaml"
    path.write_text(text)
    return path


def test_cam2world_is_base_times_fk_times_mount() -> None:
    setup = load_robot_file(EXAMPLES / "panda_wrist.yaml")
    q = setup.home_q
    link2base = setup.robot.tree.fk(q)["panda_hand"]
    expected = (
        Pose(np.eye(3), (0, 0, 0.4)).matrix @ link2base @ Pose(np.eye(3), (0, 0, 0.13)).matrix
    )
    np.testing.assert_allclose(setup.cam2world(q).matrix, expected, atol=1e-15)
    record = setup.capture_record(q)
    assert record["q"] == list(q) and record["link"] == "panda_hand"
    assert record["joint_names"][0] == "panda_joint1"


def test_a_urdf_robot_with_euler_poses(tmp_path: Path) -> None:
    pytest.importorskip("yourdfpy")
    path = _write(
        tmp_path,
        f"""
robot: {EXAMPLES / "panda.urdf"}
base2world: {{euler_deg: [0, 0, 90], t: [1, 0, 0]}}
mount: {{link: panda_link8, link2cam: {{euler_deg: [0, 0, -45], t: [0, 0, 0.05]}}}}
""",
    )
    setup = load_robot_file(path)
    assert setup.robot.source["urdf"].endswith("panda.urdf")
    q = np.array([0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(setup.cam2world(q).t[:2], setup.link2world(q).t[:2], atol=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "robot: panda\nmount: {link: tool0}",
            r"mount.link: expected a link of panda .* got 'tool0'",
        ),
        ("robot: ur5\nmount: {link: x}", r"robot: expected one of \('panda',\) or a .urdf path"),
        ("robot: panda", r"robot file mount: expected this required key"),
        ("robot: panda\nmount: {link: panda_hand}\nspeed: 1", r"speed"),
        (
            "robot: panda\nmount: {link: panda_hand}\nhome_q: [0, 0, 0, 1, 0, 0, 0]",
            r"home_q joint panda_joint4: expected a value within",
        ),
        (
            "robot: panda\nmount: {link: panda_hand, link2cam: {R: [[1, 0], [0, 1]], t: [0, 0]}}",
            r"link2cam.R",
        ),
        ("robot: missing.urdf\nmount: {link: x}", r"robot: expected an existing URDF file"),
    ],
)
def test_bad_robot_files_are_refused(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        load_robot_file(_write(tmp_path, text))
