"""FPP coverage (camera sees AND projector lights), greedy planning, trajectory files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from virtus.errors import InputError
from virtus.geometry.devices import default_rig
from virtus.geometry.transforms import Pose
from virtus.robot.config import load_robot_file
from virtus.robot.planning import (
    CoverageSettings,
    candidate_views,
    load_trajectory,
    plan_views,
    save_trajectory,
    view_coverage,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda_wrist.yaml"


def _grid(z: float, half: float = 0.05, n: int = 11) -> tuple[np.ndarray, np.ndarray]:
    xs = np.linspace(-half, half, n)
    points = np.array([[x, y, z] for x in xs for y in xs])
    return points, np.tile([0.0, 0.0, -1.0], (len(points), 1))  # facing the camera


def test_a_plane_facing_the_rig_is_covered_and_each_condition_removes_it() -> None:
    rig = default_rig()
    cam2world = Pose.identity()
    points, normals = _grid(1.0)
    assert view_coverage(rig, cam2world, points, normals, None).all()
    # out of the depth of field
    far, _ = _grid(1.5)
    assert not view_coverage(rig, cam2world, far, normals, None).any()
    # grazing: normals turned 80 deg away from both devices
    grazing = np.tile([np.sin(np.radians(80)), 0.0, -np.cos(np.radians(80))], (len(points), 1))
    assert not view_coverage(rig, cam2world, points, grazing, None).any()
    assert view_coverage(
        rig, cam2world, points, grazing, None, CoverageSettings(max_incidence_deg=85.0)
    ).any()
    # a small plate in front of the projector only: the camera sees the points, the
    # projector does not light them
    proj = rig.proj2cam.t
    plate = trimesh.creation.box(extents=(0.05, 0.05, 0.002))
    plate.apply_translation(proj + (0.0, 0.0, 0.3))
    lit = view_coverage(rig, cam2world, points, normals, plate)
    assert 0 < lit.sum() < len(points)
    # the same plate in front of the camera hides them from the camera
    plate.apply_translation(-proj)
    seen = view_coverage(rig, cam2world, points, normals, plate)
    assert seen.sum() < len(points) and not np.array_equal(seen, lit)


def test_candidate_views_look_at_the_centre_from_the_distance() -> None:
    views = candidate_views((0.5, 0.0, 0.1), 1.0, 20, max_polar_deg=60.0)
    for view in views:
        to_centre = np.array([0.5, 0.0, 0.1]) - view.t
        assert np.linalg.norm(to_centre) == pytest.approx(1.0)
        np.testing.assert_allclose(view.R[:, 2], to_centre, atol=1e-12)  # +z at the centre
        assert to_centre[2] / 1.0 <= -np.cos(np.radians(60.0)) + 1e-9  # looking down


def test_plan_is_greedy_deterministic_and_reachable(tmp_path: Path) -> None:
    setup = load_robot_file(EXAMPLE)
    target = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    target.apply_translation((0.5, 0.0, 0.1))
    kwargs = {"candidates": 8, "samples": 500, "floor_z_m": 0.0, "rng": 1}
    plan = plan_views(setup, default_rig(), target, 4, **kwargs)
    again = plan_views(setup, default_rig(), target, 4, **kwargs)
    np.testing.assert_array_equal(plan.q, again.q)
    assert 0 < len(plan.q) <= 4 and plan.reachable <= plan.candidates
    assert np.all(np.diff(plan.coverage) > 0) and plan.coverage[-1] <= 1.0
    for q, view in zip(plan.q, plan.cam2world, strict=True):
        assert not setup.robot.in_collision(q)
        assert np.abs(setup.cam2world(q).matrix - view.matrix).max() < 1e-6
    path = save_trajectory(tmp_path / "t.json", setup, plan.q)
    np.testing.assert_array_equal(load_trajectory(path, setup), plan.q)


def test_bad_trajectories_are_refused(tmp_path: Path) -> None:
    setup = load_robot_file(EXAMPLE)
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"q": [[0.0] * 6]}))
    with pytest.raises(InputError, match=r"trajectory q\[0\]: expected 7 joint values, got 6"):
        load_trajectory(path, setup)
    path.write_text(json.dumps({"q": [[0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0]]}))
    with pytest.raises(InputError, match="panda_joint4: expected a value within"):
        load_trajectory(path, setup)
    path.write_text(json.dumps({"q": [[0.0] * 7], "joint_names": ["a"] * 7}))
    with pytest.raises(InputError, match="joint_names"):
        load_trajectory(path, setup)


def test_occluders_block_segments_through_a_surface_only() -> None:
    # the rays go through Mitsuba: neither rtree nor embreex is needed (a GPU host had
    # neither, and trimesh's rtree casting took 88 s to plan 48 candidates on 2 cores)
    import trimesh

    from virtus.robot.planning import Occluders

    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))  # |x|, |y|, |z| < 0.05 m
    occluders = Occluders([box])
    origins = np.array([[-0.2, 0.0, 0.0], [-0.2, 0.0, 0.0], [-0.2, 0.2, 0.0], [0.0, 0.0, 0.06]])
    directions = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [0, 0, 1.0]])
    lengths = np.array([0.4, 0.14, 0.4, 1.0])  # through; stops 1 cm short; beside; away
    np.testing.assert_array_equal(
        occluders.blocked(origins, directions, lengths), [True, False, False, False]
    )
