"""Calibration files as labs write them: one reader (load_calibration) for every format.

Each round trip writes a known rig the way a lab's tool would (OpenCV FileStorage written
here with cv2, text files in both layouts) and requires the same rig back: K and
distortion to 1e-12, R exactly, t to 1e-12 m after the unit conversion. Each malformed
file must end as one InputError naming the file and the problem.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.tolerances import CALIB_IO_COMPOSED, CALIB_IO_K_REL, CALIB_IO_T_M
from virtus.calib.io import (
    CALIBRATION_NAMES,
    PAPER_TXT_FILES,
    load_calibration,
    load_paper_txt,
    save_opencv_yaml,
    save_paper_txt,
)
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.io.safeio import MAX_CONFIG_BYTES

#: (width, height) of the test rig's devices: neither square nor the paper's, so a swapped
#: or assumed size shows.
CAM_SIZE = (1280, 1024)
PROJ_SIZE = (912, 1140)
SIZES = {"camera_size": CAM_SIZE, "projector_size": PROJ_SIZE}


def _rig() -> Rig:
    """A rig with distortion, off-centre principal points, a toe-in and a 3D baseline."""
    cam = Intrinsics(2280.5, 2281.25, 641.3, 509.7, *CAM_SIZE, (-0.11, 0.05, 1e-4, -2e-4, 0.01))
    proj = Intrinsics(1820.0, 1825.5, 450.1, 570.2, *PROJ_SIZE, (0.01, -0.02, 3e-4, 1e-4, 0.0))
    proj2cam = Pose.from_euler("xyz", (5.7, -7.1, 0.4), t=(-0.125, 0.1, 0.013))
    return Rig(Camera(cam), Projector(proj), proj2cam)


RIG = _rig()


def _assert_same_rig(got: Rig, want: Rig = RIG, *, exact_r: bool = True) -> None:
    for a, b in (
        (got.camera.intrinsics, want.camera.intrinsics),
        (got.projector.intrinsics, want.projector.intrinsics),
    ):
        np.testing.assert_allclose(a.K, b.K, rtol=CALIB_IO_K_REL, atol=0)
        np.testing.assert_allclose(a.dist_array, b.dist_array, rtol=CALIB_IO_K_REL, atol=0)
        assert a.size == b.size
    if exact_r:
        assert np.array_equal(got.proj2cam.R, want.proj2cam.R)
    else:
        np.testing.assert_allclose(got.proj2cam.R, want.proj2cam.R, rtol=0, atol=CALIB_IO_COMPOSED)
    np.testing.assert_allclose(got.proj2cam.t, want.proj2cam.t, rtol=0, atol=CALIB_IO_T_M)


def _write_storage(path: Path, nodes: dict[str, object]) -> Path:
    """Write ``nodes`` with OpenCV's own FileStorage (YAML or XML by the suffix)."""
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in nodes.items():
        storage.write(key, value)
    storage.release()
    return path


#: Name sets of stereo calibration files: camera K, camera dist, projector K, projector dist.
STEREO_NAMES = {
    "K1-D1": ("K1", "D1", "K2", "D2"),
    "cameraMatrix1": ("cameraMatrix1", "distCoeffs1", "cameraMatrix2", "distCoeffs2"),
    "M1": ("M1", "D1", "M2", "D2"),
    "Kc-Kp": ("Kc", "Dc", "Kp", "Dp"),
    "scan3d-capture": ("cam_K", "cam_kc", "proj_K", "proj_kc"),
    "upper case": ("CAMERA_MATRIX", "CAMERA_DISTORTION", "PROJECTOR_MATRIX", "PROJECTOR_DIST"),
}


def _stereo_nodes(names: tuple[str, ...] = STEREO_NAMES["K1-D1"]) -> dict[str, object]:
    """A stereoCalibrate-style result of RIG, camera first: X_proj = R X_cam + T, T in mm."""
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    return {
        names[0]: cam.K,
        names[1]: cam.dist_array[None, :],
        names[2]: proj.K,
        names[3]: proj.dist_array[None, :],
        "R": RIG.cam2proj.R,
        "T": RIG.cam2proj.t[:, None] * 1000.0,
    }


# -- round trips ----------------------------------------------------------------------------


def test_json_round_trips(tmp_path: Path) -> None:
    path = RIG.save_json(tmp_path / "rig.json")
    assert load_calibration(path) == RIG
    calibration = RIG.to_dict() | {"rms_px": {"stereo": 0.05}, "per_pose": []}
    (tmp_path / "calibration.json").write_text(json.dumps(calibration))
    assert load_calibration(tmp_path / "calibration.json") == RIG
    capture = {"format": "virtus-capture/1", "units": "m", "rig": RIG.to_dict()}
    (tmp_path / "capture.json").write_text(json.dumps(capture))
    assert load_calibration(tmp_path / "capture.json") == RIG
    # The same schema with t in millimetres, stated by the file.
    in_mm = RIG.to_dict() | {"units": "mm"}
    in_mm["proj2cam"]["t"] = (RIG.proj2cam.t * 1000.0).tolist()
    (tmp_path / "mm.json").write_text(json.dumps(in_mm))
    _assert_same_rig(load_calibration(tmp_path / "mm.json"))


def test_virtus_yaml_round_trip(tmp_path: Path) -> None:
    path = save_opencv_yaml(RIG, tmp_path / "calibration.yaml", {"rms_stereo_px": 0.05})
    _assert_same_rig(load_calibration(path))
    _assert_same_rig(load_calibration(path, units="m"))


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
@pytest.mark.parametrize("units_from", ["file", "argument"])
def test_stereo_calibrate_file_round_trip(tmp_path: Path, suffix: str, units_from: str) -> None:
    nodes = _stereo_nodes()
    if units_from == "file":
        nodes["units"] = "mm"
    path = _write_storage(tmp_path / f"stereo{suffix}", nodes)
    units = "mm" if units_from == "argument" else None
    _assert_same_rig(load_calibration(path, units=units, **SIZES))


@pytest.mark.parametrize("names", STEREO_NAMES.values(), ids=STEREO_NAMES.keys())
def test_stereo_name_variants(tmp_path: Path, names: tuple[str, ...]) -> None:
    nodes = _stereo_nodes(names) | {"Units": "millimeters"}
    path = _write_storage(tmp_path / "stereo.yml", nodes)
    _assert_same_rig(load_calibration(path, **SIZES))


def test_image_sizes_from_the_file(tmp_path: Path) -> None:
    """OpenCV's calibration sample writes image_width/image_height; imageSize is (w, h)."""
    nodes = _stereo_nodes() | {"unit": "cm", "T": RIG.cam2proj.t[:, None] * 100.0}
    nodes |= {"image_width": CAM_SIZE[0], "image_height": CAM_SIZE[1]}
    nodes |= {"projector_size": np.array([PROJ_SIZE], np.int32)}
    _assert_same_rig(load_calibration(_write_storage(tmp_path / "a.yaml", nodes)))
    nodes = {key: value for key, value in nodes.items() if not key.startswith("image_")}
    nodes["imageSize"] = CAM_SIZE  # what cv::Size becomes
    _assert_same_rig(load_calibration(_write_storage(tmp_path / "b.xml", nodes)))
    # Sizes given and stated must agree; the file's are not overridden silently.
    _assert_same_rig(load_calibration(tmp_path / "b.xml", camera_size=CAM_SIZE))
    with pytest.raises(InputError, match=r"imageSize: expected the camera_size given"):
        load_calibration(tmp_path / "b.xml", camera_size=CAM_SIZE[::-1])


def test_plain_yaml_lists_are_read(tmp_path: Path) -> None:
    """Hand-written YAML: nested lists instead of opencv-matrix nodes, a flat T."""
    lines = ["%YAML:1.0", "units: mm"]
    for key, value in _stereo_nodes().items():
        lines.append(f"{key}: {json.dumps(np.asarray(value).squeeze().tolist())}")
    path = tmp_path / "hand.yaml"
    path.write_text("\n".join(lines) + "\n")
    _assert_same_rig(load_calibration(path, **SIZES))


def _write_txt(folder: Path, layout: str, names: dict[str, str], sep: str = "\t") -> Path:
    """The paper code's text files for RIG: matrices as rows, vectors in ``layout``."""
    folder.mkdir(parents=True, exist_ok=True)
    cam, proj = RIG.camera.intrinsics, RIG.projector.intrinsics
    values = {
        "camera_matrix": cam.K,
        "camera_distortion": cam.dist_array,
        "projector_matrix": proj.K,
        "projector_distortion": proj.dist_array,
        "R": RIG.cam2proj.R,
        "T": RIG.cam2proj.t * 1000.0,
    }
    for quantity, value in values.items():
        table = value if value.ndim == 2 else value[None, :] if layout == "row" else value[:, None]
        text = "\n".join(sep.join(repr(float(v)) for v in row) for row in table)
        (folder / names[quantity]).write_text(text + "\n")
    return folder


TXT_VARIANTS = {
    "paper": PAPER_TXT_FILES,
    "lab": PAPER_TXT_FILES
    | {
        "camera_distortion": "CamDistortionCoefficients.txt",
        "projector_distortion": "ProjDistortionCoefficients.txt",
    },
    "case": {
        "camera_matrix": "camintrinsicmatrix.TXT",
        "camera_distortion": "CAMDISTORTION.txt",
        "projector_matrix": "projIntrinsicMatrix.txt",
        "projector_distortion": "Proj_Distortion_Coefficients.txt",
        "R": "projrotationmatrix.txt",
        "T": "PROJTRANSLATIONVECTOR.txt",
    },
}


@pytest.mark.parametrize("layout", ["row", "column"])
@pytest.mark.parametrize("variant", TXT_VARIANTS, ids=TXT_VARIANTS.keys())
@pytest.mark.parametrize("sep", ["\t", " ", ", "], ids=["tab", "space", "comma"])
def test_txt_folder_layouts_and_names(tmp_path: Path, layout: str, variant: str, sep: str) -> None:
    folder = _write_txt(tmp_path / "cal", layout, TXT_VARIANTS[variant], sep)
    # mm by the paper code's definition: no units needed.
    _assert_same_rig(load_calibration(folder, **SIZES))
    # A file inside the folder stands for the folder.
    inside = next(folder.iterdir())
    _assert_same_rig(load_calibration(inside, **SIZES))


def test_txt_folder_units_argument_overrides_mm(tmp_path: Path) -> None:
    folder = _write_txt(tmp_path / "cal", "column", PAPER_TXT_FILES)
    (folder / "ProjTranslationVector.txt").write_text(
        "\n".join(repr(float(v)) for v in RIG.cam2proj.t) + "\n"
    )
    _assert_same_rig(load_calibration(folder, units="m", **SIZES))
    with pytest.raises(AssertionError):  # read as mm, the baseline would be 1000x too short
        _assert_same_rig(load_calibration(folder, **SIZES))


def test_txt_folder_with_the_camera_pose_in_a_board_frame(tmp_path: Path) -> None:
    """Some labs' folders give both devices' poses in a board frame: cam2proj is composed."""
    board2cam = Pose.from_euler("xyz", (20.0, -10.0, 3.0), t=(0.05, -0.02, 0.9))
    board2proj = RIG.cam2proj @ board2cam
    folder = _write_txt(tmp_path / "cal", "row", PAPER_TXT_FILES)
    tables = {
        "ProjRotationMatrix.txt": board2proj.R,
        "ProjTranslationVector.txt": board2proj.t[:, None] * 1000.0,
        "CamRotationMatrix.txt": board2cam.R,
        "CamTranslationVector.txt": board2cam.t[:, None] * 1000.0,
    }
    for name, table in tables.items():
        (folder / name).write_text("\n".join("\t".join(repr(float(v)) for v in r) for r in table))
    _assert_same_rig(load_calibration(folder, **SIZES), exact_r=False)


def test_save_paper_txt_is_what_the_paper_code_reads(tmp_path: Path) -> None:
    folder = save_paper_txt(RIG, tmp_path / "paper_txt")
    # The paper code's readers (realworld2digitaltwin.py): np.loadtxt with tabs, usecols.
    K = np.loadtxt(folder / "CamIntrinsicMatrix.txt", delimiter="\t", usecols=(0, 1, 2))  # noqa: N806
    np.testing.assert_array_equal(K, RIG.camera.intrinsics.K)
    R = np.loadtxt(folder / "ProjRotationMatrix.txt", delimiter="\t", usecols=(0, 1, 2))  # noqa: N806
    np.testing.assert_array_equal(R, RIG.cam2proj.R)
    T = np.loadtxt(folder / "ProjTranslationVector.txt", delimiter="\t", usecols=(0,))  # noqa: N806
    np.testing.assert_allclose(T, RIG.cam2proj.t * 1000.0, rtol=1e-15)  # mm, one per line
    for name in ("ProjTranslationVector.txt", "CamDistortion.txt", "ProjDistortion.txt"):
        lines = (folder / name).read_text().splitlines()
        assert len(lines) in (3, 5) and all(len(line.split()) == 1 for line in lines)
    _assert_same_rig(load_calibration(folder, **SIZES))
    # load_paper_txt keeps the paper's sizes as defaults.
    paper = load_paper_txt(folder)
    assert paper.camera.intrinsics.size == (960, 960)
    assert paper.projector.intrinsics.size == (912, 1140)


def test_every_name_virtus_writes_is_in_the_table(tmp_path: Path) -> None:
    """The names virtus writes (YAML nodes, text files) are read through the one table."""
    for quantity, name in PAPER_TXT_FILES.items():
        assert name.removesuffix(".txt") in CALIBRATION_NAMES[quantity]
    storage = cv2.FileStorage(str(save_opencv_yaml(RIG, tmp_path / "c.yaml")), 0)
    keys = set(storage.root().keys()) - {"units"}
    storage.release()
    assert keys == {names[0] for names in CALIBRATION_NAMES.values() if names[0] in keys}
    assert len(keys) == 10


# -- units ----------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".yaml", ".xml", ".json"])
def test_a_file_without_units_is_refused(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"cal{suffix}"
    if suffix == ".json":
        data = RIG.to_dict()
        del data["units"]
        path.write_text(json.dumps(data))
    else:
        _write_storage(path, _stereo_nodes())
    with pytest.raises(InputError, match=r"states no units") as info:
        load_calibration(path, **SIZES)
    assert "states no units" in str(info.value) and "--units mm" in str(info.value)
    assert str(path) in str(info.value)


def test_units_contradicting_the_file_are_refused(tmp_path: Path) -> None:
    path = _write_storage(tmp_path / "cal.yaml", _stereo_nodes() | {"units": "mm"})
    _assert_same_rig(load_calibration(path, units="mm", **SIZES))
    with pytest.raises(InputError, match=r"units: expected the units given \(m\).*'mm'"):
        load_calibration(path, units="m", **SIZES)
    with pytest.raises(InputError, match=r"units: expected units 'm', 'cm' or 'mm'"):
        load_calibration(path, units="inch", **SIZES)
    json_path = RIG.save_json(tmp_path / "rig.json")
    with pytest.raises(InputError, match="units"):
        load_calibration(json_path, units="mm")


# -- bad files ------------------------------------------------------------------------------


def _pop(key: str) -> Callable[[dict], None]:
    return lambda nodes: nodes.pop(key)


def _set(key: str, value: object) -> Callable[[dict], None]:
    return lambda nodes: nodes.__setitem__(key, value)


def _edit_k(row: int, col: int, value: float) -> Callable[[dict], None]:
    def edit(nodes: dict) -> None:
        K = nodes["K1"].copy()  # noqa: N806
        K[row, col] = value
        nodes["K1"] = K

    return edit


def _different_proj2cam(nodes: dict) -> None:
    other = Pose.from_euler("xyz", (5.7, -7.0, 0.4), t=RIG.proj2cam.t)
    nodes["proj2cam_R"], nodes["proj2cam_t"] = other.R, other.t[:, None] * 1000.0


def _camera_pose_without_r_t(nodes: dict) -> None:
    """A camera pose in a board frame next to proj2cam, which is not relative to it."""
    nodes["proj2cam_R"], nodes["proj2cam_t"] = RIG.proj2cam.R, RIG.proj2cam.t * 1000.0
    nodes["CamRotationMatrix"], nodes["CamTranslationVector"] = np.eye(3), np.zeros(3)
    del nodes["R"], nodes["T"]


BAD_NODES = {
    "missing matrix": (_pop("K2"), r"expected a projector_matrix node \(one of .*K2"),
    "missing T": (_pop("T"), r"expected a T node"),
    "wrong shape": (_set("K1", np.eye(3)[:2]), r"K1: expected a 3 x 3 matrix.*shape \(2, 3\)"),
    "not a rotation": (_set("R", RIG.cam2proj.R * 1.01), r"R: expected an orthonormal rotation"),
    "reflection": (_set("R", np.diag([1.0, 1.0, -1.0])), r"R: expected .*det \+1"),
    "NaN entry": (_edit_k(0, 2, np.nan), r"K1: expected finite values"),
    "negative fx": (_edit_k(0, 0, -2280.5), r"K1 \(fx\): expected a positive number"),
    "K not upper triangular": (_edit_k(1, 0, 3.0), r"K1 \(K\): expected \[\[fx, 0, cx\]"),
    "3x3 for a vector": (_set("T", np.eye(3)), r"T: expected a vector of 3 numbers.*\(3, 3\)"),
    "3x3 distortion": (_set("D1", np.eye(3)), r"D1: expected a vector \(one row or one column"),
    "T of 4": (_set("T", np.ones((4, 1))), r"T: expected 3 numbers, got '4 numbers'"),
    "text for a matrix": (_set("K2", "identity"), r"K2: expected a numeric array"),
    "two names": (_set("cameraMatrix1", np.eye(3)), r"one of camera_matrix.*K1.*cameraMatrix1"),
    "extrinsics twice": (_different_proj2cam, r"proj2cam_R/t and R/T describing one pose"),
    "camera pose alone": (_camera_pose_without_r_t, r"R and T with the camera's pose"),
    "width only": (_set("image_width", 1280), r"both image_width and image_height"),
    "units not text": (_set("units", 1000.0), r"units: expected one units string"),
}


@pytest.mark.parametrize("edit, message", BAD_NODES.values(), ids=BAD_NODES.keys())
def test_bad_nodes_are_named(tmp_path: Path, edit: Callable, message: str) -> None:
    nodes = _stereo_nodes() | {"units": "mm"}
    edit(nodes)
    path = _write_storage(tmp_path / "cal.yaml", nodes)
    with pytest.raises(InputError, match=message) as info:
        load_calibration(path, **SIZES)
    assert str(path) in str(info.value)


def _truncated_yaml() -> str:
    storage = cv2.FileStorage("m.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    for key, value in (_stereo_nodes() | {"units": "mm"}).items():
        storage.write(key, value)
    text = storage.releaseAndGetString()
    return text[: text.index("data", text.index("T: ")) + 12]  # inside T's data list


BAD_FILES = {
    "garbage bytes": ("cal.yaml", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", r"binary file"),
    "not UTF-8": ("cal.yaml", b"units: mm\nK1: \xff\xfe\n", r"not UTF-8"),
    "empty": ("cal.yaml", b"", r"empty file"),
    "blank": ("cal.xml", b"  \n\n", r"empty file"),
    "truncated YAML": ("cal.yaml", _truncated_yaml().encode(), r"OpenCV cannot parse"),
    "YAML syntax": ("cal.yml", b"units: mm\nK1: [1, 2\n", r"OpenCV cannot parse"),
    "XML syntax": ("cal.xml", b'<?xml version="1.0"?>\n<opencv_storage>\n<K1>1 2', r"parse"),
    "list at top": ("cal.yaml", b"- 1\n- 2\n", r"named top-level nodes"),
    # node.mat() crashes the process on this (OpenCV 5.0): it must never be called.
    "negative cols": (
        "cal.yaml",
        b"%YAML:1.0\nunits: mm\nT: !!opencv-matrix\n  rows: 3\n  cols: -1\n  dt: d\n"
        b"  data: [1., 2., 3.]\n",
        r"T: expected an opencv-matrix whose data fills its rows x cols",
    ),
    "invalid JSON": ("cal.json", b'{"units": "m", "camera": ', r"valid JSON"),
    "JSON NaN": ("cal.json", json.dumps(RIG.to_dict()).replace("0.013", "NaN").encode(), "NaN"),
    "JSON list": ("cal.json", b"[1, 2]", r"a JSON object"),
    "unknown type": ("cal.ini", b"[camera]\nfx = 1\n", r"a rig \.json.*\.yaml/\.yml/\.xml"),
}


@pytest.mark.parametrize("name, data, message", BAD_FILES.values(), ids=BAD_FILES.keys())
def test_malformed_files_are_refused(tmp_path: Path, name: str, data: bytes, message: str) -> None:
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(InputError, match=message) as info:
        load_calibration(path, units="mm", **SIZES)
    assert str(path) in str(info.value)


def test_a_huge_file_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "huge.yaml"
    with path.open("wb") as stream:  # sparse: nothing is written but the size
        stream.truncate(MAX_CONFIG_BYTES + 1)
    with pytest.raises(InputError, match="at most"):
        load_calibration(path, units="mm", **SIZES)


BAD_TXT = {
    "rotation 2x2": ("ProjRotationMatrix.txt", "1\t0\n0\t1\n", r"9 numbers in 3 rows"),
    "T as 3x3": ("ProjTranslationVector.txt", "1 0 0\n0 1 0\n0 0 1\n", r"one row or one column"),
    "ragged": ("CamIntrinsicMatrix.txt", "1 0 3\n0 1\n0 0 1\n", r"rows of equal length"),
    "words": ("ProjIntrinsicMatrix.txt", "fx 0 cx\n", r"numbers separated by tabs.*line 1"),
    "NaN": ("ProjTranslationVector.txt", "nan\n2\n3\n", r"ProjTranslationVector.txt: .*finite"),
    "empty": ("CamIntrinsicMatrix.txt", "", r"CamIntrinsicMatrix.txt: expected .*empty file"),
    "two distortions": ("CamDistortionCoefficients.txt", "0\n0\n0\n0\n", r"CamDistortion.txt"),
}


@pytest.mark.parametrize("name, text, message", BAD_TXT.values(), ids=BAD_TXT.keys())
def test_bad_txt_files_are_named(tmp_path: Path, name: str, text: str, message: str) -> None:
    folder = _write_txt(tmp_path / "cal", "column", PAPER_TXT_FILES)
    (folder / name).write_text(text)
    with pytest.raises(InputError, match=message):
        load_calibration(folder, **SIZES)


def test_missing_files_and_sizes(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        load_calibration(tmp_path / "nothing.yaml")
    folder = _write_txt(tmp_path / "cal", "row", PAPER_TXT_FILES)
    with pytest.raises(InputError, match=r"camera image size \(width, height\)"):
        load_calibration(folder, projector_size=PROJ_SIZE)
    with pytest.raises(InputError, match=r"projector image size"):
        load_calibration(folder, camera_size=CAM_SIZE)
    with pytest.raises(InputError, match=r"camera_size width: expected an integer"):
        load_calibration(folder, camera_size=(12.5, 10), projector_size=PROJ_SIZE)
    (folder / "ProjRotationMatrix.txt").unlink()
    with pytest.raises(FileNotFoundError, match="ProjRotationMatrix.txt"):
        load_calibration(folder, **SIZES)
