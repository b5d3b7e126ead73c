"""Calibration files read completely or refused, and where each parameter came from.

Folders are built from a known rig with ``save_paper_txt`` and renamed the way labs name
them (``...Left``/``...Right``, ``1``/``2``, separators, case); ``.npz``, kamino410's
procam-calibration XML and mapping files are written here from the same rig. Each must give
the rig back with the right roles (the test rig's camera and projector differ in size, K and
distortion, so swapped roles fail), name every file it did not use, refuse two files for
one role, and say "none given" where a source has no distortion.
"""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.calib.test_io import RIG, SIZES, _assert_same_rig
from virtus.calib.io import (
    CalibrationFileWarning,
    load_calibration,
    load_calibration_report,
    save_opencv_yaml,
    save_paper_txt,
)
from virtus.calib.names import name_role, name_roles, side_read_as_camera
from virtus.calib.sources import NONE_GIVEN, uncalibrated_rig
from virtus.errors import InputError

#: save_paper_txt's files -> the stereo folder's names (Left = camera, Right = projector; the
#: Right device's rotation/translation: X_right = R X_left + T).
LEFT_RIGHT = {
    "CamIntrinsicMatrix.txt": "CamIntrinsicMatrixLeft.txt",
    "CamDistortion.txt": "CamDistortionCoefficientsLeft.txt",
    "ProjIntrinsicMatrix.txt": "CamIntrinsicMatrixRight.txt",
    "ProjDistortion.txt": "CamDistortionCoefficientsRight.txt",
    "ProjRotationMatrix.txt": "CamRotationMatrixRight.txt",
    "ProjTranslationVector.txt": "CamTranslationVectorRight.txt",
}
NUMBERED = {
    "CamIntrinsicMatrix.txt": "IntrinsicMatrix1.txt",
    "CamDistortion.txt": "Distortion1.txt",
    "ProjIntrinsicMatrix.txt": "IntrinsicMatrix2.txt",
    "ProjDistortion.txt": "Distortion2.txt",
    "ProjRotationMatrix.txt": "RotationMatrix2.txt",
    "ProjTranslationVector.txt": "TranslationVector2.txt",
}
SPELLED = {
    "CamIntrinsicMatrix.txt": "camera_intrinsics_left.TXT",
    "CamDistortion.txt": "Cam-Kc.txt",
    "ProjIntrinsicMatrix.txt": "PROJECTOR INTRINSIC MATRIX.txt",
    "ProjDistortion.txt": "proj_dist_coeffs_2.txt",
    "ProjRotationMatrix.txt": "Projector_Rotation.txt",
    "ProjTranslationVector.txt": "proj.translation.vector.txt",
}
FOLDERS = {"left-right": LEFT_RIGHT, "1-2": NUMBERED, "spellings": SPELLED}


def _folder(tmp_path: Path, names: dict[str, str] | None = None, drop: tuple = ()) -> Path:
    """RIG as the paper code's text files, renamed by ``names``, files in ``drop`` removed."""
    folder = save_paper_txt(RIG, tmp_path / "cal")
    for old, new in (names or {}).items():
        (folder / old).rename(folder / new)
    for name in drop:
        (folder / name).unlink()
    return folder


def _strict_load(path: Path, **kwargs):
    """load_calibration_report, failing on any warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_calibration_report(path, **kwargs)


@pytest.mark.parametrize("names", FOLDERS.values(), ids=FOLDERS.keys())
def test_folder_spellings_read_with_the_right_roles(tmp_path: Path, names: dict) -> None:
    folder = _folder(tmp_path, names)
    rig, sources = _strict_load(folder, **SIZES)
    _assert_same_rig(rig)
    inverse = {new: old for old, new in names.items()}
    assert inverse[sources.camera["K"]] == "CamIntrinsicMatrix.txt"
    assert inverse[sources.camera["dist"]] == "CamDistortion.txt"
    assert inverse[sources.projector["K"]] == "ProjIntrinsicMatrix.txt"
    assert inverse[sources.projector["dist"]] == "ProjDistortion.txt"
    assert sources.ignored == () and sources.format == "text folder"
    assert "X_proj = R X_cam + T" in sources.extrinsics
    assert sources.units.startswith("mm")


def test_the_stereo_folders_sides_decide_the_device() -> None:
    assert name_role("CamIntrinsicMatrixRight")[0] == "projector_matrix"
    assert name_role("CamRotationMatrixLeft")[0] == "cam_R"
    assert name_role("CamRotationMatrixRight")[0] == "R"
    assert name_role("cam_kc")[0] == name_role("CamKc")[0] == "camera_distortion"
    assert name_role("Kc")[0] == "camera_matrix"  # the table's own meaning (K of the camera)
    for name in ("ProjIntrinsicMatrixLeft", "R1", "P2", "IntrinsicMatrix", "rms", "Q"):
        assert name_role(name)[0] is None, name


#: The file names of the LightCrafter lab's calibration folder
#: (kimthyung/3D_Reconstruction_with_Fringe_pattern, 3D_reconstruction/
#: CalibrationDataDistortion/): its one camera is "Right", beside Proj... files. Names only
#: (facts); the values here are RIG's. save_paper_txt's file -> the lab's name.
LAB_NAMES = {
    "CamIntrinsicMatrix.txt": "CamIntrinsicMatrixRight.txt",
    "CamDistortion.txt": "CamDistortionCoefficientsRight.txt",
    "ProjIntrinsicMatrix.txt": "ProjIntrinsicMatrix.txt",
    "ProjDistortion.txt": "ProjDistortionCoefficients.txt",
    "ProjRotationMatrix.txt": "ProjRotationMatrix.txt",
    "ProjTranslationVector.txt": "ProjTranslationVector.txt",
}
#: The lab folder's other files: the camera's pose (identity, zero) and circle points.
LAB_EXTRA = {
    "CamRotationMatrixRight.txt": "1\t0\t0\n0\t1\t0\n0\t0\t1\n",
    "CamTranslationVectorRight.txt": "0\n0\n0\n",
    "cameraCirclePointsRight.txt": "512.5\t301.25\n530.0\t301.5\n",
    "projectorCirclePoints.txt": "400.5\t300.25\n420.0\t300.5\n",
}


def test_a_labs_right_camera_beside_proj_files_is_the_camera(tmp_path: Path) -> None:
    folder = _folder(tmp_path, LAB_NAMES)
    for name, text in LAB_EXTRA.items():
        (folder / name).write_text(text)
    with pytest.warns(CalibrationFileWarning) as caught:
        rig, sources = load_calibration_report(folder, **SIZES)
    _assert_same_rig(rig)
    # The camera's own distortion is read (it was once refused or dropped as zeros).
    assert np.array_equal(rig.camera.intrinsics.dist_array, RIG.camera.intrinsics.dist_array)
    rows = dict(sources.lines())
    assert rows["camera matrix"] == "CamIntrinsicMatrixRight.txt"
    assert rows["camera distortion"] == "CamDistortionCoefficientsRight.txt"
    assert rows["projector matrix"] == "ProjIntrinsicMatrix.txt"
    assert rows["projector distortion"] == "ProjDistortionCoefficients.txt"
    assert rows["camera image size"] == "given: camera_size"
    assert rows["extrinsics"].startswith(
        "ProjRotationMatrix.txt, ProjTranslationVector.txt, CamRotationMatrixRight.txt, "
        "CamTranslationVectorRight.txt"
    )
    assert rows["note"] == (
        "Right read as the camera (the projector's names start with Proj): "
        "CamIntrinsicMatrixRight.txt, CamDistortionCoefficientsRight.txt, "
        "CamRotationMatrixRight.txt, CamTranslationVectorRight.txt"
    )
    # The circle points are named, never used silently.
    ignored = {"cameraCirclePointsRight.txt", "projectorCirclePoints.txt"}
    assert set(sources.ignored) == ignored
    assert {str(w.message).split("ignored: ")[1].split(" ")[0] for w in caught} == ignored


def test_sides_read_with_their_sources_names() -> None:
    lab = name_roles(["CamIntrinsicMatrixRight", "CamRotationMatrixRight", "ProjRotationMatrix"])
    assert [role for role, _ in lab.values()] == ["camera_matrix", "cam_R", "R"]
    # Without a projector name the side decides, as in a stereo tool's folder.
    stereo = name_roles(["CamIntrinsicMatrixLeft", "CamIntrinsicMatrixRight"])
    assert [role for role, _ in stereo.values()] == ["camera_matrix", "projector_matrix"]
    # A projector-prefixed name that is no quantity does not change the reading.
    points = name_roles(["CamIntrinsicMatrix2", "projectorCirclePoints"])
    assert [role for role, _ in points.values()] == ["projector_matrix", None]
    assert side_read_as_camera("CamDistortionCoefficientsRight") == "Right"
    assert side_read_as_camera("cam_K_2") == "2"
    assert side_read_as_camera("CamIntrinsicMatrixLeft") == side_read_as_camera("K2") == ""


def test_an_unrecognised_distortion_file_is_named_never_dropped(tmp_path: Path) -> None:
    folder = _folder(tmp_path, {"CamDistortion.txt": "CamLensDistortionModel.txt"})
    (folder / "notes.md").write_text("bench of 2026-11\n")
    with pytest.warns(CalibrationFileWarning) as caught:
        rig, sources = load_calibration_report(folder, **SIZES)
    messages = [str(w.message) for w in caught]
    assert any("ignored: CamLensDistortionModel.txt" in m for m in messages), messages
    assert any("ignored (not .txt): notes.md" in m for m in messages), messages
    assert all("\n" not in m for m in messages)
    # The rig has no camera distortion, and the record says so (not silent zeros).
    assert not np.any(rig.camera.intrinsics.dist_array)
    assert sources.camera["dist"].startswith(NONE_GIVEN) and str(folder) in sources.camera["dist"]
    assert sources.projector["dist"] == "ProjDistortion.txt"
    assert set(sources.ignored) == {"CamLensDistortionModel.txt", "notes.md"}
    # load_calibration warns the same way.
    (folder / "notes.md").unlink()
    with pytest.warns(CalibrationFileWarning, match="CamLensDistortionModel.txt"):
        load_calibration(folder, **SIZES)


def test_two_files_for_one_role_are_refused_naming_both(tmp_path: Path) -> None:
    # A paper folder (Proj... names) plus a Right camera distortion: beside Proj names a
    # Cam...Right file is the camera's, so it clashes with CamDistortion.txt.
    folder = _folder(tmp_path)
    shutil.copy(folder / "ProjDistortion.txt", folder / "CamDistortionCoefficientsRight.txt")
    with pytest.raises(InputError, match=r"CamDistortion.txt.*CamDistortionCoefficientsRight"):
        load_calibration(folder, **SIZES)
    folder = _folder(tmp_path / "b")
    shutil.copy(folder / "CamIntrinsicMatrix.txt", folder / "CamIntrinsicMatrixLeft.txt")
    with pytest.raises(InputError, match=r"CamIntrinsicMatrix.txt.*CamIntrinsicMatrixLeft.txt"):
        load_calibration(folder, **SIZES)


def test_a_folder_without_distortion_says_none_given(tmp_path: Path) -> None:
    folder = _folder(tmp_path, drop=("CamDistortion.txt", "ProjDistortion.txt"))
    rig, sources = _strict_load(folder, **SIZES)
    assert not np.any(rig.camera.intrinsics.dist_array)
    assert sources.without_distortion() == ["camera", "projector"]
    rows = dict(sources.lines())
    assert rows["camera distortion"] == f"{NONE_GIVEN} (no distortion file in {folder})"
    assert rows["camera image size"] == "given: camera_size"
    assert sources.to_dict()["projector"]["dist"].startswith(NONE_GIVEN)


#: .npz name sets: camera K, camera dist, projector K, projector dist.
NPZ_NAMES = {
    "K1-D1": ("K1", "D1", "K2", "D2"),
    "cam_mtx": ("cam_mtx", "cam_dist", "proj_mtx", "proj_dist"),
    "mtx1": ("mtx1", "dist1", "mtx2", "dist2"),
}


@pytest.mark.parametrize("names", NPZ_NAMES.values(), ids=NPZ_NAMES.keys())
def test_npz_round_trips(tmp_path: Path, names: tuple[str, ...]) -> None:
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    arrays = dict(zip(names, (cam.K, cam.dist_array, proj.K, proj.dist_array), strict=True))
    path = tmp_path / "stereo.npz"
    np.savez(path, **arrays, R=RIG.cam2proj.R, T=RIG.cam2proj.t * 1000.0, units=np.array("mm"))
    rig, sources = _strict_load(path, **SIZES)
    _assert_same_rig(rig)
    assert sources.camera["dist"] == f"stereo.npz: {names[1]}" and sources.units.startswith("mm")
    # Without a units key the unit must be given.
    np.savez(path, **arrays, R=RIG.cam2proj.R, T=RIG.cam2proj.t, E=np.eye(3))
    with pytest.raises(InputError, match="states no units"):
        load_calibration(path, **SIZES)
    rig, sources = _strict_load(path, units="m", **SIZES)
    _assert_same_rig(rig)
    assert sources.ignored == ("E",)


def test_a_pickled_npz_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, K1=np.array([{"fx": 1}], dtype=object))
    with pytest.raises(InputError, match="bad.npz"):
        load_calibration(path, units="mm", **SIZES)


def test_procam_calibration_xml(tmp_path: Path) -> None:
    """kamino410/procam-calibration's calibration_result.xml: img_shape is the camera's
    numpy shape (height, width); rotation/translation map camera to projector."""
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    path = tmp_path / "calibration_result.xml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    nodes = {
        "img_shape": np.array([[cam.height], [cam.width]], np.int32),
        "rms": 0.21,
        "cam_int": cam.K,
        "cam_dist": cam.dist_array[None],
        "proj_int": proj.K,
        "proj_dist": proj.dist_array[None],
        "rotation": RIG.cam2proj.R,
        "translation": RIG.cam2proj.t[:, None] * 1000.0,
    }
    for key, value in nodes.items():
        storage.write(key, value)
    storage.release()
    rig, sources = _strict_load(path, units="mm", projector_size=SIZES["projector_size"])
    _assert_same_rig(rig)
    assert sources.camera["size"] == "calibration_result.xml: img_shape (height, width)"
    assert sources.ignored == ("rms",)


def test_unused_keys_that_look_like_parameters_are_warned(tmp_path: Path) -> None:
    path = tmp_path / "stereo.npz"
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    np.savez(path, K1=cam.K, K2=proj.K, D2=proj.dist_array, R=RIG.cam2proj.R,
             T=RIG.cam2proj.t, lens_distortion_camera=cam.dist_array)  # fmt: skip
    with pytest.warns(CalibrationFileWarning, match=r"not used: lens_distortion_camera"):
        _, sources = load_calibration_report(path, units="m", **SIZES)
    assert sources.camera["dist"] == f"{NONE_GIVEN} (no distortion node in {path})"


def test_virtus_own_files_load_without_warnings(tmp_path: Path) -> None:
    extras = {"rms_camera_px": 0.03, "rms_projector_px": 0.04, "rms_stereo_px": 0.05}
    path = save_opencv_yaml(RIG, tmp_path / "calibration.yaml", extras)
    rig, sources = _strict_load(path)
    _assert_same_rig(rig)
    assert set(sources.ignored) == set(extras) and sources.units == "m (stated: units)"
    assert "agreeing" not in sources.extrinsics and "X_cam = R X_proj + t" in sources.extrinsics
    rig, sources = _strict_load(RIG.save_json(tmp_path / "rig.json"))
    assert rig == RIG and sources.camera["dist"] == "rig.json: camera.dist"


MAPPING = """\
file: {file}
keys:
  camera_K: A
  camera_dist: {dist}
  projector_K: C
  projector_dist: D
  R: rot
  T: trans
units: mm
convention: {convention}
camera_size: [1280, 1024]
projector_size: [912, 1140]
"""


@pytest.mark.parametrize("target", ["npz", "yaml", "json"])
@pytest.mark.parametrize("convention", ["X_proj = R X_cam + T", "X_cam=R X_proj+T"])
def test_mapping_files_round_trip(tmp_path: Path, target: str, convention: str) -> None:
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    pose = RIG.cam2proj if convention.startswith("X_proj") else RIG.proj2cam
    arrays = {"A": cam.K, "B": cam.dist_array, "C": proj.K, "D": proj.dist_array,
              "rot": pose.R, "trans": pose.t * 1000.0, "rms": np.array(0.2)}  # fmt: skip
    data = tmp_path / "data" / f"calib.{target}"
    data.parent.mkdir()
    if target == "npz":
        np.savez(data, **arrays)
    elif target == "json":
        import json

        data.write_text(json.dumps({k: np.asarray(v).tolist() for k, v in arrays.items()}))
    else:
        storage = cv2.FileStorage(str(data), cv2.FILE_STORAGE_WRITE)
        for key, value in arrays.items():
            storage.write(key, value)
        storage.release()
    mapping = tmp_path / "rig.yaml"
    mapping.write_text(MAPPING.format(file=f"data/calib.{target}", dist="B", convention=convention))
    rig, sources = _strict_load(mapping)
    _assert_same_rig(rig, exact_r=convention.startswith("X_cam"))
    assert sources.camera["dist"] == f"calib.{target}: B"
    assert sources.camera["size"] == "rig.yaml: camera_size"
    assert sources.ignored == ("rms",) and sources.files == (str(mapping), str(data))
    # null: the mapping says the file has no camera distortion; the record says so.
    mapping.write_text(MAPPING.format(file=f"data/calib.{target}", dist="null",
                                      convention=convention))  # fmt: skip
    rig, sources = _strict_load(mapping)
    assert not np.any(rig.camera.intrinsics.dist_array)
    assert sources.camera["dist"] == f"{NONE_GIVEN} (keys.camera_dist: null in rig.yaml)"


BAD_MAPPINGS = {
    "no convention": (("convention: X_proj = R X_cam + T\n", ""), r"convention: expected"),
    "other convention": (("X_proj = R X_cam + T", "X_proj = R^T X_cam"), r"convention"),
    "dist left out": (("  camera_dist: B\n", ""), r"keys: expected the roles.*no camera_dist"),
    "unknown key": (("  camera_dist: B", "  camera_dist: Bee"), r"keys.camera_dist.*'Bee'"),
    "misspelt role": (("  camera_dist:", "  camera_distortion:"), r"did you mean 'camera_dist'"),
    "missing file": (("calib.npz", "nothing.npz"), r"nothing.npz"),
    "units": (("units: mm", "units: inch"), r"units: expected units"),
}


@pytest.mark.parametrize("edit, message", BAD_MAPPINGS.values(), ids=BAD_MAPPINGS.keys())
def test_bad_mapping_files_are_refused(tmp_path: Path, edit: tuple, message: str) -> None:
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    np.savez(tmp_path / "calib.npz", A=cam.K, B=cam.dist_array, C=proj.K, D=proj.dist_array,
             rot=RIG.cam2proj.R, trans=RIG.cam2proj.t)  # fmt: skip
    text = MAPPING.format(file="calib.npz", dist="B", convention="X_proj = R X_cam + T")
    assert edit[0] in text
    (tmp_path / "rig.yaml").write_text(text.replace(*edit))
    with pytest.raises((InputError, FileNotFoundError), match=message):
        load_calibration(tmp_path / "rig.yaml")


def test_the_placeholder_rig_cannot_pass_for_a_calibration(tmp_path: Path) -> None:
    rig, sources = uncalibrated_rig((64, 48), (912, 1140))
    assert (rig.camera.width, rig.camera.height) == (64, 48) and not sources.calibrated
    assert rig.baseline_m == 0.0  # nothing can be triangulated with it
    import json

    capture = {"format": "virtus.capture/2", "rig": rig.to_dict(),
               "calibration_source": sources.to_dict()}  # fmt: skip
    (tmp_path / "capture.json").write_text(json.dumps(capture))
    with pytest.raises(InputError, match="imported without one"):
        load_calibration(tmp_path / "capture.json")
