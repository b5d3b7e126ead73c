"""The fuzz functions: one per reader, each feeding bytes to the real reader.

Every target takes an *input* -- ``bytes`` for a one-file reader, ``{relative name: bytes}``
for a reader of a folder (a capture, a text calibration folder, a dataset store) -- plus
the name the file gets (its suffix chooses the format) and a scratch folder, writes the
input there and calls the reader as a user's file would reach it. The reader may accept the
input or refuse it with one of the target's **allowed** exception types (virtus's own
errors, :class:`virtus.errors.VirtusError` and subclasses, plus ``FileNotFoundError`` only
where the reader's contract names it); any other exception escapes :func:`run_case` and is
a bug.

The same functions serve the CI replay (``test_corpus.py``), the Hypothesis properties
(``test_properties.py``) and the coverage-guided run (``atheris_main.py``).
"""

from __future__ import annotations

import contextlib
import functools
import shutil
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import VirtusError

HERE = Path(__file__).resolve().parent
CORPUS = HERE / "corpus"
#: Files the scene and dataset-config seeds name (a mesh, textures, a rig), copied beside
#: every scene or configuration the fuzzer writes.
ASSETS = HERE / "assets"

#: One input: a file's bytes, or a folder's files by relative POSIX name.
Data = bytes | Mapping[str, bytes]


@dataclass(frozen=True)
class Target:
    """A reader under fuzz.

    name : the corpus folder (``corpus/<name>``) and the test id.
    call : ``call(data, name, workdir)`` writes ``data`` as ``workdir/name`` (a file or a
        folder) and reads it with the real reader.
    allowed : the exception types a refusal may have (anything else is a failure).
    folder : the input is a folder (``{name: bytes}``), not one file.
    weight : relative cost of a case (the CI budget gives slow readers fewer cases).
    suffixes : the file suffixes the reader takes (atheris picks one).
    """

    name: str
    call: Callable[[Data, str, Path], Any]
    allowed: tuple[type[BaseException], ...] = (VirtusError,)
    folder: bool = False
    weight: float = 1.0
    suffixes: tuple[str, ...] = ()


class FuzzFailure(AssertionError):
    """A reader raised an exception outside its allow-list (the input is described)."""


def write_input(data: Data, name: str, workdir: Path) -> Path:
    """``data`` written as ``workdir/name``: a file, or a folder of files."""
    path = workdir / name
    if isinstance(data, bytes | bytearray):
        path.write_bytes(data)
        return path
    path.mkdir(parents=True, exist_ok=True)
    for relative, content in data.items():
        file = path / relative
        file.parent.mkdir(parents=True, exist_ok=True)
        if content is None:  # a folder where a file was
            file.mkdir(exist_ok=True)
        else:
            file.write_bytes(content)
    return path


def read_folder(path: Path) -> dict[str, bytes]:
    """Every file under ``path`` by relative POSIX name (the inverse of :func:`write_input`)."""
    return {
        p.relative_to(path).as_posix(): p.read_bytes()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def _with_assets(workdir: Path) -> None:
    for asset in ASSETS.iterdir():
        target = workdir / asset.name
        if not target.exists():
            shutil.copy(asset, target)


# -- the fuzz functions ---------------------------------------------------------------------


def fuzz_sequence(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.patterns.load_sequence_file` (YAML or JSON by suffix)."""
    from virtus.patterns import load_sequence_file

    sequence, files = load_sequence_file(write_input(data, name, workdir))
    # a sequence that loads must describe itself and load back the same (round trip)
    from virtus.patterns import PatternSequence

    again = PatternSequence.from_dict(sequence.to_dict())
    if again != sequence:
        raise FuzzFailure("sequence.to_dict() does not load back as the same sequence")
    return files


def fuzz_calibration(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.calib.io.load_calibration` of a JSON, OpenCV YAML/XML or NumPy ``.npz``
    file, or a mapping ``.yaml`` (contract: FileNotFoundError only for a missing path --
    or a mapping naming a missing file, as a mutated one may)."""
    from virtus.calib.io import load_calibration

    _with_assets(workdir)  # the .npz a mapping file names
    path = write_input(data, name, workdir)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # files and keys left unused are named in warnings
        try:
            return load_calibration(path)
        except VirtusError:  # again with the sizes and units a caller may give
            sizes = {"camera_size": (16, 12), "projector_size": (32, 24)}
            return load_calibration(path, units="mm", **sizes)


def fuzz_calibration_txt(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.calib.io.load_calibration` of the paper code's text folder
    (FileNotFoundError is its contract for a folder lacking a required file)."""
    from virtus.calib.io import load_calibration

    path = write_input(data, name, workdir)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # files left unused are named in warnings
        try:
            return load_calibration(path)
        except VirtusError:
            sizes = {"camera_size": (16, 12), "projector_size": (32, 24)}
            return load_calibration(path, units="mm", **sizes)


def fuzz_pose_npz(data: Data, name: str, workdir: Path) -> Any:
    """A calibration run's pose file (``poses/<name>.npz``) through its reader,
    :func:`virtus.calib.posefile.load_pose_observation` (:func:`virtus.io.safeio.load_npz`
    underneath, called alone first)."""
    from virtus.calib.posefile import load_pose_observation
    from virtus.calib.poses import BoardPose
    from virtus.geometry.transforms import Pose
    from virtus.io.safeio import load_npz

    path = write_input(data, name, workdir)
    load_npz(path, "pose file")
    pose = BoardPose("pose", Pose(np.eye(3), np.zeros(3)))
    return load_pose_observation(path, pose, 7, "e1")


def fuzz_scene(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.scene.model.load_scene` (assets the seeds name are beside it)."""
    from virtus.scene.model import load_scene

    _with_assets(workdir)
    scene = load_scene(write_input(data, name, workdir))
    scene.to_dict()
    return scene


def fuzz_dataset_config(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.data.load_config` (a tiny rig and assets beside it)."""
    from virtus.data import load_config

    _with_assets(workdir)
    config = load_config(write_input(data, name, workdir))
    config.to_dict()
    return config


def fuzz_usd(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.twin.usd.read_usd` of a ``.usda`` stage (needs usd-core)."""
    from virtus.twin.usd import read_usd

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # skipped prims are reported as warnings
        return read_usd(write_input(data, name, workdir))


def fuzz_sensor(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.sensor.load_sensor` of a YAML/JSON file."""
    from virtus.sensor import load_sensor

    sensor = load_sensor(write_input(data, name, workdir))
    type(sensor).from_dict(sensor.to_dict())
    return sensor


def fuzz_projector(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.sensor.load_projector` of a YAML/JSON file."""
    from virtus.sensor import load_projector

    model = load_projector(write_input(data, name, workdir))
    type(model).from_dict(model.to_dict())
    return model


def fuzz_capture(data: Data, name: str, workdir: Path) -> Any:
    """:meth:`virtus.capture.Capture.load` of a capture folder, then its frames and ground
    truth (read on first access)."""
    from virtus.capture import Capture

    capture = Capture.load(write_input(data, name, workdir))
    capture.frames  # noqa: B018 (read on access)
    if capture.has_ground_truth:
        capture.ground_truth  # noqa: B018
    return capture


def fuzz_ply(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.io.ply.read_ply` (point clouds)."""
    from virtus.io.ply import read_ply

    return read_ply(write_input(data, name, workdir))


def fuzz_mesh(data: Data, name: str, workdir: Path) -> Any:
    """A scene's mesh object (:class:`virtus.scene.model.MeshObject`: the header check of
    :mod:`virtus.scene.meshfiles`, then trimesh) of an STL, OBJ or PLY file."""
    from virtus.scene.model import MeshObject

    path = write_input(data, name, workdir)
    return MeshObject(path, 0.001, np.eye(4)).load()


def fuzz_npy(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.io.safeio.load_npy`, free and with a dtype and shape required."""
    from virtus.io.safeio import load_npy

    path = write_input(data, name, workdir)
    array = load_npy(path, "array")
    with contextlib.suppress(VirtusError):
        load_npy(path, "array", dtype=(np.float64, np.float32), shape=(None, None))
    return array


def fuzz_image(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.io.images.read_image` (PNG, TIFF, BMP; header checked first)."""
    from virtus.io.images import read_image

    return read_image(write_input(data, name, workdir))


def fuzz_texture(data: Data, name: str, workdir: Path) -> Any:
    """:func:`virtus.scene.model.load_texture` (a textured plane's image or ``.npy``)."""
    from virtus.scene.model import load_texture

    return load_texture(write_input(data, name, workdir))


def fuzz_store(data: Data, name: str, workdir: Path) -> Any:
    """:meth:`virtus.data.DatasetStore.open` then ``verify()`` and a sample read, on a copy
    of a tiny store (``data``: every file of it, some mutated)."""
    from virtus.data import DatasetStore

    store = DatasetStore.open(write_input(data, name, workdir))
    report = store.verify()
    samples = store.samples()
    if samples:
        with contextlib.suppress(VirtusError):  # a damaged sample is named, not returned
            store.read_sample(min(samples))
    return report


TARGETS: dict[str, Target] = {
    target.name: target
    for target in (
        Target("sequence", fuzz_sequence, suffixes=(".yaml", ".json")),
        Target(
            "calibration",
            fuzz_calibration,
            (VirtusError, FileNotFoundError),
            suffixes=(".json", ".yaml", ".xml", ".npz"),
        ),
        Target(
            "calibration_txt", fuzz_calibration_txt, (VirtusError, FileNotFoundError), folder=True
        ),
        Target("pose_npz", fuzz_pose_npz, suffixes=(".npz",)),
        Target("scene", fuzz_scene, weight=2.0, suffixes=(".yaml",)),
        Target("dataset_config", fuzz_dataset_config, suffixes=(".yaml",)),
        # read_usd: FileNotFoundError for a missing stage (its contract; never here)
        Target("usd", fuzz_usd, (VirtusError, FileNotFoundError), weight=4.0, suffixes=(".usda",)),
        Target("sensor", fuzz_sensor, suffixes=(".yaml", ".json")),
        Target("projector", fuzz_projector, suffixes=(".yaml", ".json")),
        Target("capture", fuzz_capture, folder=True, weight=2.0),
        Target("ply", fuzz_ply, suffixes=(".ply",)),
        Target("mesh", fuzz_mesh, weight=2.0, suffixes=(".stl", ".obj", ".ply")),
        Target("npy", fuzz_npy, suffixes=(".npy",)),
        Target("image", fuzz_image, suffixes=(".png", ".tif", ".bmp")),
        Target("texture", fuzz_texture, suffixes=(".png", ".npy", ".tif")),
        Target("store", fuzz_store, folder=True, weight=20.0),
    )
}


@functools.cache
def usd_available() -> bool:
    try:
        import pxr  # noqa: F401
    except ImportError:
        return False
    return True


def run_case(target: Target, data: Data, name: str, workdir: Path) -> str:
    """Run one input; ``"accepted"`` or ``"refused"`` (an allowed error), else the
    exception propagates (a :class:`FuzzFailure` or the reader's own)."""
    workdir.mkdir(parents=True, exist_ok=True)
    try:
        target.call(data, name, workdir)
    except target.allowed:
        return "refused"
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return "accepted"
