"""The virtual VDI/VDE 2634-2 acceptance test against known answers (tiny renders: a 240 or
480 px camera, the first one or two positions of each feature, the true rig)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from virtus.design.acceptance import (
    _position_seed,
    acceptance_test,
    interior,
    parse_limits,
)
from virtus.design.artefacts import artefact_layout
from virtus.design.figures import (
    coordinate_sigma_px,
    expected_fit_bias,
    expected_form_range,
    measure_sphere,
    radial_sigma,
    sphere_normals,
    staircase_form_bound,
)
from virtus.design.volume import volume_from_rig
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.transforms import Pose
from virtus.reconstruct import reconstruct
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.scene.model import Scene, SphereObject
from virtus.sensor import Lookup, load_projector
from virtus.sensor.camera import Sensor

#: P_S and SD with the ideal sensor and the true rig (the issue's requirement).
IDEAL_SIZE_MM = 0.01
#: P_F of noise against its prediction (the issue's requirement: 20 %).
NOISE_FORM_REL = 0.2


def _rig(factor: float) -> Rig:
    """The paper's rig with its camera resampled (240 px for 1/4, 480 px for 1/2)."""
    rig = default_rig()
    return Rig(Camera(rig.camera.intrinsics.scaled(factor)), rig.projector, rig.proj2cam)


def _scanner(factor: float, lookup: str, sensor: Sensor | None = None) -> Scanner:
    projector = load_projector("ideal").with_(pixel=Lookup(lookup))
    return Scanner(rig=_rig(factor), projector=projector, sensor=sensor or Sensor(name="ideal"),
                   render=RenderSettings(spp=4))  # fmt: skip


@pytest.fixture(scope="module")
def dmd_run(tmp_path_factory):
    """Ideal sensor, sharp DMD pixels (nearest), 240 px, true rig, first position of each."""
    out = tmp_path_factory.mktemp("dmd")
    scanner = _scanner(0.25, "nearest")
    return scanner, acceptance_test(scanner, out, calibration="true", positions=1,
                                    limits="P_F=0.01,SD=100")  # fmt: skip


def test_limits_parse_and_refuse_unknown_names():
    assert parse_limits("SD=0.1, P_F=0.05") == {"P_F": 0.05, "SD": 0.1}
    assert parse_limits(None) == {}
    for bad in ("PF=0.05", "P_F=0.05,P_F=1", "P_F=-1", "P_F=abc", "P_F", "F=1e9"):
        with pytest.raises(InputError, match="--limits"):
            parse_limits(bad)


def test_ideal_sensor_true_rig_sizes_within_10_um(tmp_path):
    """P_S and SD within 0.01 mm: a 480 px camera (smaller pixels average less of the
    sphere's curvature) and projector pixels blurred over ~1 px (bilinear)."""
    result = acceptance_test(_scanner(0.5, "bilinear"), tmp_path, calibration="true", positions=2)
    for data in result.summary["positions"]:
        if data["feature"] == "sphere":
            assert abs(data["P_S_mm"]) <= IDEAL_SIZE_MM
        if data["feature"] == "ball_bar":
            assert abs(data["SD_mm"]) <= IDEAL_SIZE_MM
        if data["feature"] == "plane":  # no staircase: flat to a tenth of a millimetre
            assert data["F_mm"] <= 0.1
    assert result.summary["maxima"]["P_S"]["n"] == 2


def _first_sphere_fit(scanner):  # noqa: ANN001, ANN202
    """The one-position acceptance test's sphere, its decoded capture and its fit,
    recomputed as the job does (the same capture seed, decoding, interior mask and fit)."""
    _, layout = artefact_layout(volume_from_rig(scanner.rig), positions=1)
    sphere = layout[0]
    capture = scanner.capture(sphere.scene(), rng=_position_seed(0, sphere.name))
    decoded = capture.decode()
    points = reconstruct(scanner.rig, decoded.proj_uv, interior(decoded.mask)).points
    return sphere, decoded, measure_sphere(points, sphere.centres_m[0], sphere.radius_m)


def test_dmd_staircase_bounds_the_form_error(dmd_run):
    """With sharp DMD pixels P_F stays below the staircase's bound (half a projector pixel in
    u_p and v_p through the triangulation's Jacobian, figures.staircase_form_bound) and
    reaches a good part of it (the staircase, not something else, makes it)."""
    scanner, result = dmd_run
    data = result.summary["positions"][0]
    assert data["name"] == "sphere_01"
    sphere, _, fit = _first_sphere_fit(scanner)
    assert 1e3 * fit.form_m == data["P_F_mm"]  # the job's number, recomputed
    fit_error = np.linalg.norm(fit.centre_m - sphere.centres_m[0]) + abs(
        fit.diameter_m / 2 - sphere.radius_m
    )
    cam_px = fit.pixels[:, ::-1].astype(float)
    bound = staircase_form_bound(scanner.rig, cam_px, sphere.centres_m[0], sphere.radius_m,
                                 fit_error)  # fmt: skip
    assert 0.3 * bound <= fit.form_m <= bound
    assert result.summary["limits"]["P_F"]["passed"] is False  # mm of staircase > 0.01
    assert result.summary["limits"]["SD"]["passed"] is True
    assert result.passed is False


@pytest.mark.filterwarnings("ignore:decode.*flagged")  # a few % at this noise, expected
def test_noise_form_error_follows_the_sensor_model(tmp_path):
    """A sensor whose temporal noise (EMVA 1288: 6 e- read noise at 10 DN/e-, shot noise)
    dwarfs the staircase of blurred projector pixels: P_F within 20 % of the range of normal
    draws of each point's predicted radial sigma (figures.coordinate_sigma_px through the
    triangulation's Jacobian, figures.radial_sigma / expected_form_range)."""
    sensor = Sensor(bit_depth=12, auto_target=0.25, system_gain_dn_per_e=10.0,
                    dark_noise_e=6.0, black_level_dn=200.0, name="noisy")  # fmt: skip
    scanner = _scanner(0.25, "bilinear", sensor)
    result = acceptance_test(scanner, tmp_path, calibration="true", positions=1)
    measured = result.summary["positions"][0]["P_F_mm"] / 1e3
    sphere, decoded, fit = _first_sphere_fit(scanner)
    rows, cols = fit.pixels.T
    cam_px = fit.pixels[:, ::-1].astype(float)
    sigma_uv = coordinate_sigma_px(sensor, scanner.sequence, decoded, fit.pixels)
    _, normals, _ = sphere_normals(scanner.rig, cam_px, fit.centre_m, fit.diameter_m / 2)
    sigma = radial_sigma(scanner.rig, cam_px, decoded.proj_uv[rows, cols], normals, sigma_uv)
    predicted = expected_form_range(sigma)
    assert np.median(sigma_uv) > 0.2  # projector px: well above the bilinear staircase
    assert measured == pytest.approx(predicted, rel=NOISE_FORM_REL)


def test_dmd_size_error_is_the_sphere_fits_bias_from_the_staircase_not_an_offset():
    """Why P_S < 0 with sharp DMD pixels, the ideal sensor and the true rig (figures' module
    docstring): the decoded coordinates carry no offset (a half-pixel rounding slip would show
    here as |mean| ~ 0.5 px), only the staircase's spread (0.19 px RMS at 480 px), and the
    least-squares fit turns that spread into a smaller sphere as figures.expected_fit_bias
    predicts. The guideline's sphere at the volume's centre, 480 px camera, moved by 8
    sub-pixel steps (each draws the staircase anew); measured -0.089 +- 0.007 mm against
    -0.086 mm."""
    from virtus.design.artefacts import MATTE

    scanner = _scanner(0.5, "nearest")
    _, layout = artefact_layout(volume_from_rig(scanner.rig), positions=1)
    radius = layout[0].radius_m
    sizes, predicted = [], []
    for step in range(8):
        centre = np.asarray(layout[0].centres_m[0]) + step * np.array([0.37e-3, 0.23e-3, 1.1e-3])
        scene = Scene(objects=(SphereObject(radius_m=radius, center_m=tuple(centre),
                                            material=MATTE),))  # fmt: skip
        decoded = scanner.capture(scene, rng=1).decode()
        points = reconstruct(scanner.rig, decoded.proj_uv, interior(decoded.mask)).points
        fit = measure_sphere(points, centre, radius)
        cam_px = fit.pixels[:, ::-1].astype(float)
        _, _, true_uv = sphere_normals(scanner.rig, cam_px, centre, radius)
        error = decoded.proj_uv[fit.pixels[:, 0], fit.pixels[:, 1]] - true_uv
        error = error[np.isfinite(error).all(axis=1)]
        assert np.abs(error.mean(axis=0)).max() < 0.01  # projector px: no offset
        rms = np.sqrt((error**2).mean(axis=0))
        assert 0.1 < rms.min() and rms.max() < 0.3  # the staircase (uniform: 0.29 px)
        sizes.append(fit.diameter_m - 2 * radius)
        predicted.append(expected_fit_bias(scanner.rig, cam_px, centre, radius, rms, trials=8,
                                           seed=step)[0])  # fmt: skip
    measured = np.mean(sizes)
    standard_error = np.std(sizes, ddof=1) / np.sqrt(len(sizes))
    assert measured < -4 * standard_error  # a real bias, not chance
    assert measured == pytest.approx(np.mean(predicted), abs=3 * standard_error)


def test_planted_scale_error_shows_in_the_sphere_spacing(tmp_path):
    """A rig whose baseline is 1 % long scales every triangulated point by 1.01: SD is 1 % of
    the bar length."""
    scanner = _scanner(0.25, "bilinear")
    rig = scanner.rig
    wrong = Rig(rig.camera, rig.projector, Pose(rig.proj2cam.R, 1.01 * np.asarray(rig.proj2cam.t)))
    result = acceptance_test(scanner, tmp_path, calibration=wrong, positions=1)
    length = result.summary["artefacts"]["bar_length_mm"]
    sd = result.summary["positions"][1]["SD_mm"]
    assert sd == pytest.approx(0.01 * length, abs=0.03)  # 3.67 mm, within the 0.01-0.02 mm
    assert result.summary["rig"]["kind"] == "given"


def test_resume_skips_finished_positions_and_writes_the_same_bytes(dmd_run, tmp_path, monkeypatch):
    scanner, first = dmd_run
    files = {p.relative_to(first.directory): p.read_bytes()
             for p in first.directory.rglob("*") if p.is_file()}  # fmt: skip
    out = tmp_path / "again"
    out.mkdir()
    for name, data in files.items():  # the run, killed after its first two positions
        if name.name not in ("acceptance.json", "acceptance.csv", "plane_01.json"):
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            (out / name).write_bytes(data)
    import virtus.design.acceptance as job

    rendered = []
    original = job._run_position
    monkeypatch.setattr(job, "_run_position", lambda s, r, p, *a: rendered.append(p.name)
                        or original(s, r, p, *a))  # fmt: skip
    acceptance_test(scanner, out, calibration="true", positions=1, limits="P_F=0.01,SD=100",
                    resume=True)  # fmt: skip
    assert rendered == ["plane_01"]
    for name in ("acceptance.json", "acceptance.csv", "positions/plane_01.json"):
        assert (out / name).read_bytes() == files[Path(name)]
    summary = json.loads((out / "acceptance.json").read_text())
    assert summary["complete"] is False


def test_virtual_calibration_first_then_the_calibrated_rig_measures(tmp_path):
    """The default: the same scanner calibrated virtually (into OUT/calibration), its
    calibrated rig reconstructs; the calibration's small errors (measured: baseline ~0.05 mm
    at 240 px) keep SD and P_S well under a millimetre but not at the true rig's 0.01 mm."""
    scanner = _scanner(0.25, "bilinear")
    result = acceptance_test(scanner, tmp_path, positions=1)
    rig = result.summary["rig"]
    assert rig["kind"] == "virtual calibration"
    assert (tmp_path / "calibration" / "calibration.json").is_file()
    calibrated = Rig.from_dict(rig["rig"])
    assert calibrated.baseline_m != scanner.rig.baseline_m  # really the calibrated one
    assert (
        calibrated.to_dict()
        == Rig.load_json(tmp_path / "calibration" / "calibration.json").to_dict()
    )
    sd = result.summary["positions"][1]["SD_mm"]
    assert 1e-4 < abs(sd) < 0.5
    assert abs(result.summary["positions"][0]["P_S_mm"]) < 0.5


def test_a_position_renders_the_same_in_a_shortened_and_a_longer_run(dmd_run, tmp_path):
    """Capture seeds follow the position's name, not its place in the run: the first
    positions of a 2-position run are byte for byte those of the 1-position run."""
    scanner, first = dmd_run
    longer = acceptance_test(scanner, tmp_path, calibration="true", positions=2)
    for name in ("sphere_01", "ball_bar_01", "plane_01"):
        path = f"positions/{name}.json"
        assert (longer.directory / path).read_bytes() == (first.directory / path).read_bytes()
    assert len(list((tmp_path / "positions").glob("*.json"))) == 6
