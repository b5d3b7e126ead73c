"""Captures from the robot: the stored pose is the rendered pose, the arm is in the scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.support import small_rig
from virtus.capture.capture import Capture
from virtus.geometry.transforms import Pose
from virtus.render import RenderSettings
from virtus.robot.capture import capture_at, q_of, robot_record, scene_with_robot
from virtus.robot.config import load_robot_file
from virtus.scanner import Scanner
from virtus.scene.model import PlaneObject, Scene, SphereObject
from virtus.sensor.projector import Lookup, ProjectorModel

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda_wrist.yaml"


@pytest.fixture(scope="module")
def scanner() -> Scanner:
    return Scanner(
        rig=small_rig(1 / 8),
        projector=ProjectorModel(pixel=Lookup.bilinear),
        render=RenderSettings(spp=1),
    )


def test_stored_cam2world_renders_the_same_capture_bit_for_bit(scanner, tmp_path) -> None:
    setup = load_robot_file(EXAMPLE)
    q = setup.home_q
    cam2world = setup.cam2world(q)
    target = cam2world.apply([[0.0, 0.0, 1.0]])[0]  # the sphere at the working distance
    scene = Scene(
        objects=[SphereObject(0.08, tuple(target))],
        background=PlaneObject((3.0, 3.0), Pose.identity()),
    )  # the floor
    captured = capture_at(scanner, scene, setup, q, tmp_path / "a", seed=3)
    captured.save(tmp_path / "a", overwrite=True)
    loaded = Capture.load(tmp_path / "a")
    record = robot_record(loaded)
    np.testing.assert_array_equal(q_of(loaded), q)
    # FK(q) x mount composed here, independently of RobotSetup.cam2world
    link2base = setup.robot.tree.fk(q)["panda_hand"]
    expected = setup.base2world.matrix @ link2base @ setup.cam2link.matrix
    np.testing.assert_array_equal(
        loaded.cam2world.matrix, Pose.from_dict(record["cam2world"]).matrix
    )
    np.testing.assert_allclose(loaded.cam2world.matrix, expected, atol=1e-15)
    np.testing.assert_allclose(
        Pose.from_dict(record["link2world"]).matrix, setup.base2world.matrix @ link2base, atol=1e-15
    )
    again = scanner.capture(
        scene_with_robot(scene, setup, q, tmp_path / "b"), cam2world=loaded.cam2world, rng=3
    )
    np.testing.assert_array_equal(again.frames, loaded.frames)
    assert np.isfinite(loaded.ground_truth.depth).mean() > 0.9


def test_the_arm_occludes_the_scene(scanner, tmp_path) -> None:
    setup = load_robot_file(EXAMPLE)
    q = setup.home_q
    hand = setup.link2world(q).t
    # a camera 1.2 m beside the robot looking at its hand, a wall behind the robot
    eye = hand + np.array([0.0, -1.2, 0.0])
    look = Pose.look_at(eye, hand, image_down=(0.0, 0.0, -1.0))
    wall = PlaneObject((4.0, 4.0), Pose.look_at(hand + [0.0, 1.0, 0.0], hand, (0, 0, -1)))
    empty = Scene(background=wall)
    bare = scanner.capture(empty, cam2world=look, rng=0).ground_truth.depth
    with_arm = scanner.capture(
        scene_with_robot(empty, setup, q, tmp_path), cam2world=look, rng=0
    ).ground_truth.depth
    nearer = with_arm < bare - 0.5  # the arm is ~1 m nearer than the wall
    assert 0.02 < nearer.mean() < 0.5
    centre = with_arm[with_arm.shape[0] // 2, with_arm.shape[1] // 2]
    assert centre == pytest.approx(1.2, abs=0.1)  # the hand itself
