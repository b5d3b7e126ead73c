"""End to end: scan (capture, decode, reconstruct), evaluate by C2M, turntable, CLI."""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import (
    C2M_MAE_M,
    PIPELINE_FORMAT_M,
    PIPELINE_TRUE_RIG_M,
    TURNTABLE_ICP_ANGLE_DEG,
    TURNTABLE_ICP_SHIFT_M,
    TURNTABLE_REFINE_SHIFT_MM,
)
from virtus.calib.io import load_rig_file
from virtus.cli import main
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import default_rig
from virtus.geometry.trajectories import turntable_poses
from virtus.io.ply import read_ply
from virtus.pipeline.evaluate import evaluate_scan
from virtus.pipeline.scan import reconstruct_capture, scan
from virtus.pipeline.turntable import turntable_scan
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.scene.builtin import freeform_scene
from virtus.scene.model import default_scene
from virtus.sensor.projector import Lookup, ProjectorModel

#: Blurred projector pixels (bilinear pattern lookup): with perfectly sharp DMD pixels
#: ("nearest") the phase keeps a pixel staircase that alone gives ~0.3 mm C2M MAE.
BLURRED = Scanner(projector=ProjectorModel(pixel=Lookup.bilinear))


@pytest.fixture(scope="module")
def freeform_scan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One view of the free-form object with the default rig, 4 spp, blurred projector."""
    out = tmp_path_factory.mktemp("freeform")
    scan(freeform_scene(out), out, scanner=BLURRED)
    return out


@pytest.fixture(scope="module")
def sphere_scan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sphere scene at 1 spp (cheap: only the files and the geometry matter here)."""
    out = tmp_path_factory.mktemp("sphere")
    scan(default_scene(), out, scanner=BLURRED.with_(render=RenderSettings(spp=1)))
    return out


@pytest.mark.slow
def test_single_view_c2m_of_the_free_form_object(freeform_scan: Path) -> None:
    cloud = read_ply(freeform_scan / "points.ply")
    assert cloud.units == "m" and cloud.frame == "camera" and cloud.normals is not None
    results = evaluate_scan(freeform_scan)
    assert len(results) == 1
    result = results[0]
    assert result.n_points > 20_000  # the object covers ~25k pixels at 1 m
    assert result.c2m.mae <= C2M_MAE_M
    assert result.c2m.icp is not None and result.c2m.icp.converged
    report = json.loads((freeform_scan / "evaluation.json").read_text())
    assert report["meshes"][0]["mae_mm"] == pytest.approx(result.c2m.mae * 1e3)


@pytest.mark.slow
def test_decoded_files_and_points_match_ground_truth(freeform_scan: Path) -> None:
    decoded = freeform_scan / "decoded"
    for name in ("phase_v", "phase_h", "proj_uv", "mask"):
        assert (decoded / f"{name}.npy").is_file()
    points = np.load(freeform_scan / "reconstruction" / "points.npy")
    truth = np.load(freeform_scan / "gt" / "points.npy")
    both = np.isfinite(points).all(-1) & np.isfinite(truth).all(-1)
    error = np.linalg.norm(points[both] - truth[both], axis=-1)
    assert np.median(error) < PIPELINE_TRUE_RIG_M


@pytest.mark.slow
def test_reconstruct_with_a_calibration_file(freeform_scan: Path, tmp_path: Path) -> None:
    data = default_rig().to_dict() | {"rms_px": {"stereo": 0.01}, "notes": "extra keys ignored"}
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps(data))
    assert load_rig_file(calibration) == default_rig()
    reference = np.load(freeform_scan / "reconstruction" / "points.npy")
    recon = reconstruct_capture(freeform_scan, calibration, tmp_path / "cal.ply")
    assert np.array_equal(np.isnan(recon.points), np.isnan(reference))
    assert np.nanmax(np.abs(recon.points - reference)) == 0.0
    assert len(read_ply(tmp_path / "cal.ply")) > 0
    small = default_rig().to_dict()
    small["camera"]["width"] = 480
    (tmp_path / "small.json").write_text(json.dumps(small))
    # The capture's camera size is given to the reader, which names the difference.
    with pytest.raises(VirtusError, match=r"camera_size given, \(960, 960\), got \(480, 960\)"):
        reconstruct_capture(freeform_scan, tmp_path / "small.json", tmp_path / "x.ply")
    assert not (tmp_path / "x.ply").exists()
    # The other calibration formats virtus calibrate writes: OpenCV YAML, the paper's txt.
    from virtus.calib.io import save_opencv_yaml, save_paper_txt

    for path in (save_opencv_yaml(default_rig(), tmp_path / "c.yaml"),
                 save_paper_txt(default_rig(), tmp_path / "paper_txt")):  # fmt: skip
        other = reconstruct_capture(freeform_scan, path, tmp_path / "other.ply")
        assert np.nanmax(np.abs(other.points - reference)) < PIPELINE_FORMAT_M
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(InputError, match="calibration"):
        load_rig_file(tmp_path / "bad.json")


@pytest.mark.slow
def test_turntable_merge_in_the_object_frame(tmp_path: Path) -> None:
    scene = freeform_scene(tmp_path)
    mesh_path = scene.objects[0].path
    result = turntable_scan(mesh_path, tmp_path / "tt", n_views=4, scanner=BLURRED)
    assert len(result.view_counts) == 4 and min(result.view_counts) > 20_000
    assert result.c2m.mae <= C2M_MAE_M
    # The known turntable poses already put the views in place: ICP corrects almost nothing.
    assert result.c2m.cloud2mesh.angle_deg < TURNTABLE_ICP_ANGLE_DEG
    assert np.linalg.norm(result.c2m.cloud2mesh.t) < TURNTABLE_ICP_SHIFT_M
    merged = read_ply(tmp_path / "tt" / "merged.ply")
    assert merged.frame == "object" and len(merged) == result.merged.shape[0]
    report = json.loads((tmp_path / "tt" / "turntable.json").read_text())
    assert report["c2m"]["mae_mm"] == pytest.approx(result.c2m.mae * 1e3)


def test_turntable_poses_turn_about_the_vertical_axis() -> None:
    poses = turntable_poses(4)
    assert [round(p.angle_deg, 9) for p in poses] == [0.0, 90.0, 180.0, 90.0]
    for pose in poses:
        assert np.allclose(pose.t, (0.0, 0.0, 1.0))
        assert np.allclose(pose.apply_direction([[0.0, 1.0, 0.0]]), [[0.0, 1.0, 0.0]])
    with pytest.raises(InputError, match="n_views"):
        turntable_poses(0)


@pytest.mark.slow
def test_cli_decode_reconstruct_evaluate(freeform_scan: Path, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as done:
        main(["decode", str(freeform_scan)])
    assert done.value.code == 0
    with pytest.raises(SystemExit) as done:
        main(["reconstruct", str(freeform_scan), "--out", str(tmp_path / "p.ply"), "--use", "u"])
    assert done.value.code == 0
    with pytest.raises(SystemExit) as done:
        main(["evaluate", str(freeform_scan), "--ply", str(tmp_path / "p.ply")])
    assert done.value.code == 0
    assert "cloud-to-mesh" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "no mesh object"),
        (b"", "empty file"),
        (b"solid x\n", "not a PLY"),
        ("zero", "no points"),
    ],
    ids=["no-mesh", "empty-file", "not-ply", "no-points"],
)
def test_cli_evaluate_errors(
    freeform_scan, sphere_scan, tmp_path, capsys, content, message
) -> None:
    if content is None:
        argv = ["evaluate", str(sphere_scan)]
    else:
        path = tmp_path / "cloud.ply"
        if content == "zero":
            from virtus.io.ply import write_ply

            write_ply(path, np.zeros((0, 3)))
        else:
            path.write_bytes(content)
        argv = ["evaluate", str(freeform_scan), "--ply", str(path)]
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_cli_turntable_with_refinement(tmp_path: Path, capsys) -> None:
    out = tmp_path / "tt"
    argv = ["scan", "--scene", "freeform", "--out", str(out), "--turntable", "2", "--refine",
            "--spp", "1", "--lookup", "bilinear"]  # fmt: skip
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 0
    assert "C2M MAE" in capsys.readouterr().out
    report = json.loads((out / "turntable.json").read_text())
    assert report["n_views"] == 2 and report["refine"] is True
    # True rig and known poses: the per-view ICP refinement moves each view very little.
    for angle_deg, shift_mm in report["refinement_deg_mm"]:
        assert angle_deg < TURNTABLE_ICP_ANGLE_DEG and shift_mm < TURNTABLE_REFINE_SHIFT_MM
    assert (out / "view_0" / "capture.json").is_file() and (out / "merged.ply").is_file()


def test_scan_with_a_missing_calibration_fails_before_rendering(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such calibration file"):
        scan(default_scene(), tmp_path / "out", calibration=tmp_path / "missing.json")
    assert not (tmp_path / "out").exists()  # no capture left behind


# --- run ownership, resume, derived files tied to their inputs ---------------------------------


#: A cheap scanner for the ownership tests: a 160 x 160 camera, 1 spp.
def _small_scanner() -> Scanner:
    from tests.support import small_rig

    return Scanner(
        rig=small_rig(),
        projector=ProjectorModel(pixel=Lookup.bilinear),
        render=RenderSettings(spp=1),
    )


def _record(directory: Path) -> dict:
    return json.loads((directory / "run.json").read_text())


def test_scan_owns_its_directory_and_overwrite_drops_the_old_evaluation(tmp_path: Path) -> None:
    out = tmp_path / "scan"
    scanner = _small_scanner()
    scan("sphere", out, scanner=scanner)
    record = _record(out)
    assert record["command"] == "scan" and record["status"] == "complete"
    assert {"capture.json", "points.ply", "decoded/source.json", "evaluation.json"} <= set(
        record["files"]
    )
    with pytest.raises(VirtusError, match=r"already holds a `virtus scan` run .* --resume"):
        scan("sphere", out, scanner=scanner)
    with pytest.raises(VirtusError, match=r"other settings \(config.scanner.spp: 4 here"):
        scan("sphere", out, scanner=scanner.with_(render=scanner.render.with_(spp=4)))
    (out / "evaluation.json").write_text('{"cloud_sha256": "old"}')
    points = (out / "points.ply").read_bytes()
    scan("sphere", out, scanner=scanner, overwrite=True)
    assert not (out / "evaluation.json").exists()  # the previous run's, removed
    assert (out / "points.ply").read_bytes() == points  # same settings, same cloud
    resumed = scan("sphere", out, scanner=scanner, resume=True)
    assert _record(out)["log"][-2:] == ["resume", "reused ."]
    assert (out / "points.ply").read_bytes() == points and resumed.reconstruction.mask.any()


def test_stale_derived_files_are_recomputed_or_refused(freeform_scan: Path, tmp_path: Path):
    import shutil

    from virtus.io.runs import file_digest

    directory = tmp_path / "copy"
    shutil.copytree(freeform_scan, directory)
    evaluate_scan(directory, register=False)
    evaluation = json.loads((directory / "evaluation.json").read_text())
    assert evaluation["cloud_sha256"] == file_digest(directory / "points.ply")
    source = json.loads((directory / "reconstruction" / "source.json").read_text())
    assert source["ply_sha256"] == evaluation["cloud_sha256"] and source["rig_sha256"]
    # A new cloud removes the evaluation of the old one.
    reconstruct_capture(directory, use="u")
    assert not (directory / "evaluation.json").exists()
    # A cloud that is not the recorded reconstruction is refused, not measured.
    (directory / "points.ply").write_bytes((freeform_scan / "points.ply").read_bytes())
    with pytest.raises(VirtusError, match="is stale"):
        evaluate_scan(directory)
    assert not (directory / "evaluation.json").exists()


def test_turntable_resume_keeps_finished_views(tmp_path: Path) -> None:
    out = tmp_path / "tt"
    scanner = _small_scanner()
    first = turntable_scan(None, out, n_views=2, scanner=scanner)
    merged = (out / "merged.ply").read_bytes()
    kept = (out / "view_0" / "view.npz").stat()
    # As if killed after view 0: view 1's result and the merged files are missing.
    for name in ("view_1/view.npz", "merged.ply", "turntable.json"):
        (out / name).unlink()
    with pytest.raises(VirtusError, match="--resume"):
        turntable_scan(None, out, n_views=2, scanner=scanner)
    again = turntable_scan(None, out, n_views=2, scanner=scanner, resume=True)
    after = (out / "view_0" / "view.npz").stat()
    assert (after.st_ino, after.st_mtime_ns) == (kept.st_ino, kept.st_mtime_ns)
    log = _record(out)["log"]
    after_resume = log[log.index("resume") :]
    assert "reused view 0" in after_resume and "scanned view 1" in after_resume
    assert not any("view_0" in line for line in after_resume)  # view 0 not scanned again
    assert again.view_counts == first.view_counts
    assert (out / "merged.ply").read_bytes() == merged
    with pytest.raises(InputError, match="turntable views"):
        turntable_scan(None, tmp_path / "none", n_views=361, scanner=scanner)
    assert not (tmp_path / "none").exists()


def test_ablation_resume_keeps_finished_cells(tmp_path: Path) -> None:
    from virtus.pipeline.ablation import run_ablation

    out = tmp_path / "ab"
    options = {"materials": ["matte"], "ambients": ["dark"], "realism": ["ideal", "gamma"]}
    rows = run_ablation(out, _small_scanner(), **options)
    cells = sorted(p.name for p in (out / "cells").glob("*.json"))
    assert cells == ["matte-dark-gamma.json", "matte-dark-ideal.json"]
    kept = (out / "cells" / "matte-dark-ideal.json").read_bytes()
    (out / "cells" / "matte-dark-gamma.json").unlink()
    (out / "ablation.csv").unlink()
    again = run_ablation(out, _small_scanner(), **options, resume=True)
    assert json.dumps(again) == json.dumps(rows)
    assert (out / "cells" / "matte-dark-ideal.json").read_bytes() == kept
    log = _record(out)["log"]
    assert log[log.index("resume") + 1 :] == [
        "reused cells/matte-dark-ideal.json",
        "measured cells/matte-dark-gamma.json",
    ]
