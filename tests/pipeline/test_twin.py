"""Digital twins: Isaac Sim parameters of a calibrated rig, ``virtus twin``, and the twin's
validation against the captures of the rig it copies."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests import tolerances as tol
from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.calib.board import board_from_spec
from virtus.calib.poses import pose_set
from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.pipeline.calibrate import calibrate_captures
from virtus.pipeline.twin import validate_twin, write_twin
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.twin.parameters import twin_parameters


def _run_cli(args: list[str]) -> int:
    from virtus.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(args)
    return int(exit_info.value.code)


def test_paper_rig_twin_has_the_papers_isaac_values():
    params = twin_parameters(default_rig(), meters_per_unit=0.01)  # Isaac's cm stage: mm
    usd = params["camera"]["usd"]
    assert usd["focalLength"] == pytest.approx(50.0)
    assert usd["horizontalAperture"] == pytest.approx(20.9995)
    assert usd["horizontalApertureOffset"] == pytest.approx(0.0, abs=1e-12)
    rect = params["projector"]["rect_light"]
    assert (rect["width"], rect["height"]) == pytest.approx((50.0, 62.5))  # cm at 1 m
    pose = params["projector"]["pose"]
    np.testing.assert_allclose(pose["position"], [0.0, 12.5, -10.0], atol=1e-12)
    assert params["metersPerUnit"] == 0.01 and params["upAxis"] == "Z"
    metres = twin_parameters(default_rig(), meters_per_unit=1.0)["camera"]["usd"]
    assert metres["focalLength"] == pytest.approx(0.5)  # tenths of a metre


def test_twin_command_writes_the_files(tmp_path, capsys):
    rig = scaled_rig(0.25)
    rig.save_json(tmp_path / "calib.json")
    assert _run_cli(["twin", str(tmp_path / "calib.json"), "--out", str(tmp_path / "t")]) == 0
    assert Rig.load_json(tmp_path / "t" / "rig.json") == rig
    isaac = json.loads((tmp_path / "t" / "isaac.json").read_text())
    assert isaac["metersPerUnit"] == 1.0 and "lens_distortion" in isaac["camera"]
    from virtus.twin.usd import read_usd

    back = read_usd(tmp_path / "t" / "twin.usda").rig
    assert back.camera == rig.camera and back.projector == rig.projector
    np.testing.assert_allclose(back.proj2cam.matrix, rig.proj2cam.matrix, atol=tol.FLOAT64_EXACT)


_GOOD = default_rig().to_dict()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ({"units": "m", "camera": _GOOD["camera"], "projector": _GOOD["projector"]}, "missing"),
        ({**_GOOD, "camera": {**_GOOD["camera"], "K": [[1, 0, 4], [0, 1, 4]]}}, "K"),
        (
            {**_GOOD, "proj2cam": {"R": [[1, 0, 0], [0, 2, 0], [0, 0, 1]], "t": [0, 0, 0]}},
            "rotation",
        ),
    ],
)
def test_bad_calibration_files_are_one_line_errors(tmp_path, capsys, content, message):
    (tmp_path / "calib.json").write_text(json.dumps(content))
    assert _run_cli(["twin", str(tmp_path / "calib.json"), "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("virtus: error:") and message in err


def _distorted_rig() -> Rig:
    """The quarter rig with off-centre principal points and distortion on both devices."""
    rig = scaled_rig(0.25)
    c, p = rig.camera.intrinsics, rig.projector.intrinsics
    camera = Intrinsics(c.fx, c.fy * 1.002, c.cx + 6.3, c.cy - 4.1, c.width, c.height,
                        (-0.08, 0.03, 2e-4, -3e-4, 0.0))  # fmt: skip
    projector = Intrinsics(p.fx, p.fy, p.cx - 5.2, p.cy + 7.7, p.width, p.height,
                           (0.04, -0.01, 0.0, 0.0, 0.0))  # fmt: skip
    return Rig(Camera(camera), Projector(projector), rig.proj2cam)


@pytest.mark.slow
def test_twin_validation_round_trip(tmp_path, capsys):
    """Captures of a rig with off-centre principal points and distortion on both devices;
    its twin goes through the twin files (USD stage) and re-renders every pose: virtual to
    virtual, the validation must find no difference. A twin calibrated from the captures is
    validated too (its numbers are the calibration's errors)."""
    rig, board = _distorted_rig(), board_from_spec("4x7")
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    poses = pose_set("random:4", rig, board, np.random.default_rng(2))
    for index, pose in enumerate(poses):
        capture = scanner.capture(board_scene(board, pose, texture), rng=100 + index)
        capture.save(tmp_path / "captures" / pose.name)
    calibrated = calibrate_captures([tmp_path / "captures"], board=board, out_dir=tmp_path / "c")
    # the true rig's twin, read back from its USD stage, with the true board poses
    write_twin(tmp_path / "c" / "calibration.json", tmp_path / "twin")  # files of a real run
    true_json = json.loads((tmp_path / "c" / "calibration.json").read_text())
    write_twin_dir = tmp_path / "true_twin"
    rig.save_json(tmp_path / "true_rig.json")
    write_twin(tmp_path / "true_rig.json", write_twin_dir)
    from virtus.twin.usd import read_usd

    twin_rig = read_usd(write_twin_dir / "twin.usda").rig
    true_json.update(twin_rig.to_dict())
    for item, pose in zip(true_json["per_pose"], poses, strict=True):
        item["board2cam"] = pose.board2cam.to_dict()
    (tmp_path / "true_calibration.json").write_text(json.dumps(true_json))
    result = validate_twin(tmp_path / "true_calibration.json", [tmp_path / "captures"])
    assert len(result.per_pose) == 4 and not result.dropped
    assert result.overall["cloud_mae_mm"] <= tol.TWIN_ROUND_TRIP_MAE_MM
    assert result.overall["proj_uv_rms_px"] <= tol.TWIN_ROUND_TRIP_PROJ_PX
    assert result.overall["centre_diff_max_px"] <= tol.TWIN_ROUND_TRIP_PROJ_PX
    # the calibrated twin, through the command line: a table printed and written
    code = _run_cli(
        [
            "twin",
            str(tmp_path / "c" / "calibration.json"),
            "--out",
            str(tmp_path / "v"),
            "--validate",
            str(tmp_path / "captures"),
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "overall" in printed and "0.436" in printed
    table = json.loads((tmp_path / "v" / "validation.json").read_text())
    assert [row["name"] for row in table["per_pose"]] == [p.name for p in poses]
    assert table["overall"]["cloud_mae_mm"] <= tol.TWIN_CALIBRATED_MAE_MM
    assert calibrated.rig.camera.intrinsics.has_distortion


def _plane_captures(folder) -> None:
    """The photometric tests' three plane poses, rendered with their true light."""
    from tests.twin.test_photometric import POSES, TRUE_PROJECTOR, TRUE_SENSOR, plane, scanner

    truth = scanner(TRUE_SENSOR, TRUE_PROJECTOR)
    for index, pose in enumerate(POSES):
        truth.capture(plane(*pose), rng=30 + index).save(folder / f"plane_{index}")


def test_twin_fit_command_writes_models_the_scanner_reads(tmp_path, capsys):
    """``virtus twin CALIB --fit CAPTURE...``: DIR/sensor.yaml and DIR/projector.yaml are
    sensor and projector files (``--sensor FILE``, ``--projector FILE``) holding the light
    the captures were rendered with, DIR/photometric.json the ambient level and the report."""
    from tests.twin.test_photometric import AMBIENT, RIG, TRUE_PROJECTOR, TRUE_SENSOR
    from virtus.sensor.camera import load_sensor
    from virtus.sensor.projector import load_projector

    _plane_captures(tmp_path / "planes")
    RIG.save_json(tmp_path / "calib.json")
    (tmp_path / "camera.yaml").write_text("bit_depth: 10\nblack_level_dn: 8.0\n")
    (tmp_path / "lamp.yaml").write_text("contrast_ratio: 500.0\n")
    planes = [str(tmp_path / "planes" / f"plane_{i}") for i in range(3)]
    args = ["twin", str(tmp_path / "calib.json"), "--out", str(tmp_path / "t"), "--fit"]
    args += [*planes, "--albedo", "0.7", "--sensor", str(tmp_path / "camera.yaml")]
    assert _run_cli([*args, "--projector", str(tmp_path / "lamp.yaml")]) == 0
    assert "sensor.yaml" in capsys.readouterr().out
    sensor = load_sensor(tmp_path / "t" / "sensor.yaml")
    projector = load_projector(tmp_path / "t" / "projector.yaml")
    report = json.loads((tmp_path / "t" / "photometric.json").read_text())
    rel = tol.PHOTOMETRIC_FIT_REL
    assert sensor.name == "fitted" and sensor.vignetting == "cos" and sensor.bit_depth == 10
    exponent = TRUE_SENSOR.vignetting_exponent
    assert sensor.vignetting_exponent == pytest.approx(exponent, rel=rel)
    assert sensor.system_gain_dn_per_e == pytest.approx(TRUE_SENSOR.system_gain_dn_per_e, rel=rel)
    assert sensor.exposure == pytest.approx(TRUE_SENSOR.exposure, rel=rel)
    assert projector.gamma == pytest.approx(TRUE_PROJECTOR.gamma, rel=rel)
    assert projector.psf_sigma_px == pytest.approx(TRUE_PROJECTOR.psf_sigma_px, rel=rel)
    assert projector.falloff == "cos" and projector.contrast_ratio == 500.0
    exponent = TRUE_PROJECTOR.falloff_exponent
    assert projector.falloff_exponent == pytest.approx(exponent, rel=rel)
    assert report["ambient"] == pytest.approx(AMBIENT, rel=rel)
    assert len(report["captures"]) == 3 and report["shading"]["separable"]
    # captures after both options are ambiguous: one line
    both = ["twin", str(tmp_path / "calib.json"), "--out", str(tmp_path / "u")]
    both += ["--fit", planes[0], "--validate", planes[1], planes[2]]
    assert _run_cli(both) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "only one of --fit and --validate" in err


@pytest.mark.slow
def test_fitted_twin_validation_matches_the_frames(tmp_path):
    """Board captures rendered with the true light (gamma, blur, fall-off, vignetting,
    ambient, noise) against their twin: with the light fitted from plane captures the
    normalised frames differ by the noise alone and the point noise agrees; the geometric
    twin (ideal projector) is far off."""
    from tests.twin import test_photometric as light
    from virtus.scene.model import Scene

    _plane_captures(tmp_path / "planes")
    board = board_from_spec("4x7")
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    truth = light.scanner(light.TRUE_SENSOR, light.TRUE_PROJECTOR)
    rig = light.RIG
    for index, pose in enumerate(pose_set("random:3", rig, board, np.random.default_rng(5))):
        scene = Scene(objects=board_scene(board, pose, texture).objects, ambient=light.AMBIENT)
        truth.capture(scene, rng=40 + index).save(tmp_path / "boards" / pose.name)
    twin = tmp_path / "twin"
    write_twin(
        rig.save_json(tmp_path / "rig.json"), twin, fit=[tmp_path / "planes"], albedo=0.7,
        sensor=light.PRIOR_SENSOR, projector=light.PRIOR_PROJECTOR,
    )  # fmt: skip
    geometric = validate_twin(rig, [tmp_path / "boards"], board="4x7").overall
    fitted = validate_twin(rig, [tmp_path / "boards"], board="4x7", twin=twin).overall
    assert fitted["fringe_rms"] <= tol.TWIN_FITTED_FRAME_RMS < geometric["fringe_rms"]
    assert fitted["white_rms"] <= tol.TWIN_FITTED_FRAME_RMS
    assert fitted["black_rms"] < 0.25 * geometric["black_rms"]
    assert fitted["point_noise_ratio"] == pytest.approx(1.0, abs=tol.PHOTOMETRIC_POINT_NOISE_REL)
    assert geometric["point_noise_ratio"] < 0.5  # an ideal projector's staircase
    assert fitted["cloud_mae_mm"] < geometric["cloud_mae_mm"]
