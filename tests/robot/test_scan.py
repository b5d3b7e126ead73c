"""The robot scan job on a tiny rig: plan, capture with the arm, merge by FK, ICP, C2M."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.support import small_rig
from virtus.capture.capture import Capture
from virtus.errors import InputError
from virtus.render import RenderSettings
from virtus.robot.config import load_robot_file
from virtus.robot.scan import RobotScanResult, robot_scan
from virtus.scanner import Scanner
from virtus.sensor.projector import Lookup, ProjectorModel

#: The tiny camera's pixels are ~3.5 mm apart on the object: coverage counts a surface
#: sample as measured with a point within 5 mm.
RADIUS_M = 0.005
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda_wrist.yaml"


def tiny_scanner() -> Scanner:
    """A 120 x 120 px camera, 1 spp: seconds per view on two cores."""
    return Scanner(
        rig=small_rig(1 / 8),
        projector=ProjectorModel(pixel=Lookup.bilinear),
        render=RenderSettings(spp=1),
    )


def scan_two_views(out: Path, **changes) -> RobotScanResult:
    """The ``scanned`` fixture's robot scan into ``out`` (two planned views of the example
    robot, joint noise 1e-4 rad, ICP on the views); ``changes`` replace its arguments."""
    kwargs = {"scanner": tiny_scanner(), "plan": 2, "candidates": 8, "joint_noise_rad": 1e-4,
              "icp": "views", "seed": 1, "coverage_radius_m": RADIUS_M}  # fmt: skip
    return robot_scan(load_robot_file(EXAMPLE), "freeform", out, **(kwargs | changes))


@pytest.fixture(scope="module")
def scanned(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("robot") / "scan"
    return out, scan_two_views(out)


def test_views_record_the_robot_and_merge_in_the_world(scanned) -> None:
    out, result = scanned
    setup = load_robot_file(EXAMPLE)
    trajectory = json.loads((out / "trajectory.json").read_text())
    assert len(trajectory["q"]) == len(result.views) == 2
    for k, q in enumerate(trajectory["q"]):
        capture = Capture.load(out / "views" / f"{k:03d}")
        record = capture.provenance["robot"]
        assert record["q"] == q and len(record["q_reported"]) == 7
        np.testing.assert_allclose(capture.cam2world.matrix, setup.cam2world(q).matrix, atol=1e-15)
        noise = np.array(record["q_reported"]) - np.array(q)
        assert 0 < np.abs(noise).max() < 6e-4  # 1e-4 rad draws
    r = result.record
    kin, icp = r["c2m_kinematics"][0], r["c2m_icp"][0]
    assert kin["n_points"] == icp["n_points"] > 500
    # the joint noise misplaces whole views by ~0.1 mm; ICP takes it out
    assert icp["mae_mm"] < kin["mae_mm"] and icp["mae_mm"] < 0.05
    # the measurable surface (seen and lit by the two views) is where the points are
    assert r["coverage_kinematics"]["share_of_measurable"] > 0.8
    assert r["plan"]["coverage_after_each_view"][-1] == pytest.approx(1.0)
    assert (out / "merged.ply").is_file() and (out / "merged_icp.ply").is_file()


def test_resume_keeps_the_views_and_other_settings_are_refused(scanned) -> None:
    from virtus.errors import RunConflict

    out, first = scanned
    stamp = (out / "views" / "000" / "capture.json").stat().st_mtime_ns
    again = scan_two_views(out, resume=True)
    assert (out / "views" / "000" / "capture.json").stat().st_mtime_ns == stamp
    np.testing.assert_array_equal(again.merged, first.merged)
    with pytest.raises(RunConflict):
        scan_two_views(out, joint_noise_rad=2e-4, resume=True)


def test_bad_arguments_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    setup = load_robot_file(EXAMPLE)
    out = tmp_path / "none"
    with pytest.raises(InputError, match="exactly one of them"):
        robot_scan(setup, "freeform", out, scanner=tiny_scanner())
    with pytest.raises(InputError, match="--joint-noise"):
        robot_scan(setup, "freeform", out, scanner=tiny_scanner(), plan=1, joint_noise_rad=1.0)
    bad = tmp_path / "t.json"
    bad.write_text(json.dumps({"q": [[0.0] * 6]}))
    with pytest.raises(InputError, match="7 joint values"):
        robot_scan(setup, "freeform", out, scanner=tiny_scanner(), trajectory=bad)
    assert not out.exists()


def test_a_view_misplaced_by_its_joints_is_brought_back_without_the_mesh(scanned) -> None:
    from virtus.pipeline.evaluate import evaluate_points
    from virtus.robot.scan import merge_views

    out, result = scanned
    setup = load_robot_file(EXAMPLE)
    q = np.array(json.loads((out / "trajectory.json").read_text())["q"])
    clouds = [view.reconstruction.cloud() for view in result.views]
    reported = q.copy()
    reported[1, 1] += 2e-3  # shoulder 2 mrad off: the second view ~1.5 mm from the truth
    first = merge_views(setup, reported, clouds, result.meshes, anchor="first", seed=2)
    kin, icp = first.record["c2m_kinematics"][0], first.record["c2m_icp"][0]
    # the registration used no mesh (the truth only measures the result); the first view
    # is where kinematics put it, the second is brought onto it
    assert kin["mae_mm"] > 0.3 and icp["mae_mm"] < 0.05
    again = merge_views(setup, reported, clouds, result.meshes, anchor="first", seed=2)
    np.testing.assert_array_equal(again.merged_icp, first.merged_icp)
    # anchored on the kinematic average, the error of one view of two is shared by both:
    # the cloud as a whole is off, but its views lie on each other (one rigid fit to the
    # mesh takes the rest out)
    shared = merge_views(setup, reported, clouds, result.meshes, seed=2)
    assert shared.record["c2m_icp"][0]["mae_mm"] > 0.1
    fitted = evaluate_points(shared.merged_icp, result.meshes, register=True)[0].to_dict()
    assert fitted["mae_mm"] < 0.05
