"""Digital twins: write a calibrated rig's twin, and measure its fidelity against the real
captures it was calibrated from.

:func:`write_twin` is ``virtus twin CALIB --out DIR``: ``DIR/rig.json`` (the rig schema),
``DIR/isaac.json`` (:func:`virtus.twin.parameters.twin_parameters`: USD lens and film values in
tenths
of a scene unit, ``metersPerUnit``, Omniverse lens-distortion attributes, the projector's
RectLight size and both poses in Isaac's world) and, with usd-core, ``DIR/twin.usda``.

:func:`validate_twin` is ``virtus twin CALIB --validate CAPTURES...``: every captured board
pose is rendered again with the twin -- a :class:`~virtus.scanner.Scanner` built from the
twin rig and the captures' sequence, resolution and bit depth, the board placed by the
calibration's own extrinsics (``per_pose[*].board2cam`` of ``calibration.json``, matched by
pose name; a pose the file lacks -- a lab's calibration in text files, say -- is placed from
**both devices**, :func:`stereo_board_pose`: its circle centres in the camera and their
decoded projector points triangulated, and the board fitted to them; camera-only PnP leaves
the board's depth to the camera's focal length, and a 1 % focal error moves the board ~1 %
of its distance off the surface the rig reconstructs) -- and both captures are decoded
(with fringe-order repair) and compared (``posed_by``: ``calibration`` or ``stereo``, with
the stereo pose's errors ``pose_errors``: 3-D fit RMS in mm, reprojection RMS per device
in px):

* ``centre_diff_px``: board point (circle centre / corner) positions, real minus virtual,
  mean and max of the distances, px;
* ``proj_uv_rms_px`` (and ``proj_uv_median_px``): RMS (median) of the distance between the
  decoded projector coordinates of the two captures on the board (pixels valid in both,
  inside the board plane less :data:`BOARD_EDGE_FRACTION`), px;
* ``cloud_mae_mm``, ``cloud_rmse_mm``: distance from every real point (triangulated with the
  twin rig) to the nearest virtual point, on the board, mm (the paper's 0.436 mm);
* ``white_rms``, ``black_rms``, ``fringe_rms``, ``code_rms``: RMS difference of the
  normalised frames (each divided by its capture's mean white frame on the compared pixels),
  real minus virtual, per kind of frame (:func:`virtus.twin.photometric.frame_differences`);
* ``point_noise_real_mm``, ``point_noise_twin_mm``, ``point_noise_ratio``: RMS distance of
  each cloud to its own fitted plane (the board is flat: the point noise), and real / twin.

With ``out``, the per-pose **difference maps** go beside the table:
``validation_maps/pose_NNN.npy``, ``(4, h, w)`` float32, the layers of :data:`MAP_LAYERS`
(normalised white, first fringe and first code frame, real minus virtual, each frame
divided by its capture's mean white frame on the compared pixels; the distance between the
two decoded projector coordinates, projector px), NaN off the compared pixels, averaged
over ``bin x bin`` camera pixels so the longer side is at most :data:`MAP_MAX_SIDE`;
``validation.json`` lists each file with its SHA-256 under ``maps``.

:func:`run_twin` is the whole ``virtus twin`` job in an owned run directory
(:func:`virtus.io.runs.claim_run`, command ``twin``): ``run.json`` says ``running`` until the
twin (and its validation) are written, so a half-finished twin is known as such.

:func:`write_photometry` is ``virtus twin CALIB --fit CAPTURES...``: the twin's light,
fitted to real captures (phase shifts with white and black frames, e.g. of a matte plane at
several distances) by :func:`virtus.twin.photometric.fit_photometry`: ``DIR/sensor.yaml``
and ``DIR/projector.yaml`` (files ``--sensor`` and ``--projector`` read: gamma, blur,
fall-off, vignetting, exposure, gain, dark noise) and ``DIR/photometric.json`` (the ambient
level and every fitted number). :func:`validate_twin` given the twin directory renders with
them (and the ambient level).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.calib.board import Board, board_from_dict, board_from_spec
from virtus.calib.io import load_calibration
from virtus.calib.observe import observe_pose
from virtus.calib.poses import BoardPose
from virtus.calib.scene import (
    board_scene,
    board_texture,
)
from virtus.capture.capture import Capture
from virtus.capture.scandir import capture_dirs
from virtus.checks import positive
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.jsonio import write_json
from virtus.io.runs import atomic_write, claim_run, file_digest
from virtus.io.safeio import read_json
from virtus.metrology.plane import fit_plane
from virtus.reconstruct import points_from_decoded
from virtus.scanner import Scanner
from virtus.sensor.camera import Sensor, load_sensor
from virtus.sensor.projector import ProjectorModel, load_projector
from virtus.twin.parameters import DEFAULT_PIXEL_SIZE_M, twin_parameters
from virtus.twin.photometric import PhotometricFit, fit_photometry, frame_differences

__all__ = [
    "ISAAC_FILE",
    "PAPER_CLOUD_MAE_MM",
    "PHOTOMETRY_FILE",
    "PROJECTOR_FILE",
    "RIG_FILE",
    "SENSOR_FILE",
    "USD_FILE",
    "VALIDATION_FILE",
    "TwinValidation",
    "compare_captures",
    "MAP_LAYERS",
    "MAPS_DIR",
    "TWIN_COMMAND",
    "run_twin",
    "load_photometry",
    "check_validation",
    "stereo_board_pose",
    "validate_twin",
    "write_photometry",
    "write_twin",
]

#: Border of the board plane (fraction of its size per side) left out of the comparisons:
#: pixels straddling the board's edge mix board and background and belong to neither.
BOARD_EDGE_FRACTION = 0.05
#: The paper's real-to-virtual point-cloud MAE, mm (DESIGN.md section 4).
PAPER_CLOUD_MAE_MM = 0.436
#: Files written by :func:`write_twin` and :func:`validate_twin`.
RIG_FILE, ISAAC_FILE, USD_FILE, VALIDATION_FILE = (
    "rig.json",
    "isaac.json",
    "twin.usda",
    "validation.json",
)
#: Files written by :func:`write_photometry` (``virtus twin --fit``).
SENSOR_FILE, PROJECTOR_FILE, PHOTOMETRY_FILE = "sensor.yaml", "projector.yaml", "photometric.json"
#: Folder of the per-pose difference maps (beside ``validation.json``) and their layers.
MAPS_DIR = "validation_maps"
MAP_LAYERS = ("white", "fringe", "code", "proj_uv")
#: Longest side (px) of a stored difference map: larger captures are binned to it
#: (a 1920 x 1200 capture gives 480 x 300 maps, 2.3 MB a pose).
MAP_MAX_SIDE = 480
#: The run record's command and the files a twin run owns (:func:`run_twin`).
TWIN_COMMAND = "twin"
TWIN_LAYOUT = (RIG_FILE, ISAAC_FILE, USD_FILE, "twin_projector.png", VALIDATION_FILE,
               SENSOR_FILE, PROJECTOR_FILE, PHOTOMETRY_FILE, f"{MAPS_DIR}/*.npy")  # fmt: skip
#: (the USD stage's projector texture, written by :func:`virtus.twin.usd.export_usd` beside
#: ``twin.usda``)


def write_twin(
    calibration: str | Path,
    out_dir: str | Path,
    *,
    meters_per_unit: float = 1.0,
    pixel_size_m: float = DEFAULT_PIXEL_SIZE_M,
    units: str | None = None,
    camera_size: tuple[int, int] | None = None,
    projector_size: tuple[int, int] | None = None,
    fit: list[str | Path | Capture] | None = None,
    albedo: float = 1.0,
    sensor: str | Path | Sensor | None = None,
    projector: str | Path | ProjectorModel | None = None,
) -> dict[str, Path]:
    """Write the twin of a calibration (module docstring); returns name -> path written.

    ``calibration``: any file :func:`virtus.calib.io.load_calibration` reads (``units`` for
    files that state none; ``camera_size``/``projector_size``, ``(width, height)`` px, for
    files that state no image sizes, e.g. the paper code's text folders). ``pixel_size_m``:
    the real camera's pixel pitch, which sets the USD lens and film values (default: the
    paper's Isaac camera). With ``fit`` (captures), the twin's light too
    (:func:`write_photometry` with ``albedo``, ``sensor`` and ``projector``).
    """
    positive("pixel_size_m", pixel_size_m)  # before anything is written
    rig = load_calibration(
        calibration, units=units, camera_size=camera_size, projector_size=projector_size
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {"rig": rig.save_json(out / RIG_FILE)}
    params = twin_parameters(rig, pixel_size_m=pixel_size_m, meters_per_unit=meters_per_unit)
    params["source"] = str(calibration)
    written["isaac"] = write_json(out / ISAAC_FILE, params)
    try:
        from virtus.twin.usd import export_usd

        written["usd"] = export_usd(
            out / USD_FILE, rig=rig, meters_per_unit=meters_per_unit, pixel_size_m=pixel_size_m
        )
    except VirtusError as error:  # usd-core missing: the JSON files are the twin
        if "usd-core" not in str(error):
            raise
    if fit:
        written.update(
            write_photometry(rig, fit, out, albedo=albedo, sensor=sensor, projector=projector)
        )
    return written


def _yaml(path: Path, data: dict[str, Any], what: str) -> Path:
    import yaml

    text = f"# {what}, fitted by virtus twin --fit (report: {PHOTOMETRY_FILE})\n"
    text += yaml.safe_dump(data, sort_keys=False)
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def write_photometry(
    rig: Rig,
    captures: list[str | Path | Capture],
    out_dir: str | Path,
    *,
    albedo: float = 1.0,
    sensor: str | Path | Sensor | None = None,
    projector: str | Path | ProjectorModel | None = None,
) -> dict[str, Path]:
    """Fit the twin's camera and projector to real captures and write ``sensor.yaml``,
    ``projector.yaml`` and ``photometric.json`` (module docstring).

    Parameters
    ----------
    rig : the twin's (calibrated) rig.
    captures : capture directories, folders of them, or captures.
    out_dir : the twin directory.
    albedo : diffuse albedo of the captured surface (sets the exposure).
    sensor, projector : what is known and not fitted (a preset, a file or a model):
        the camera's black level, PRNU, DSNU; the projector's contrast ratio and fill factor.
    """
    items: list[Any] = list(captures)
    if items and all(isinstance(item, str | Path) for item in items):
        items = capture_dirs(items)
    loaded = [item if isinstance(item, Capture) else Capture.load(item) for item in items]
    prior_sensor = load_sensor(sensor) if isinstance(sensor, str | Path) else sensor
    prior_projector = load_projector(projector) if isinstance(projector, str | Path) else projector
    fit = fit_photometry(
        loaded, rig, prior_sensor=prior_sensor, prior_projector=prior_projector, albedo=albedo
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = fit.to_dict()
    report["captures"] = [str(c.path) if c.path is not None else None for c in loaded]
    return {
        "sensor": _yaml(out / SENSOR_FILE, fit.sensor.to_dict(), "camera"),
        "projector": _yaml(out / PROJECTOR_FILE, fit.projector.to_dict(), "projector"),
        "photometry": write_json(out / PHOTOMETRY_FILE, report),
    }


def load_photometry(twin: str | Path) -> PhotometricFit | None:
    """The fitted light of a twin directory (:func:`write_photometry`), or None if it has
    none: its sensor and projector files and the ambient level of its report."""
    directory = Path(twin)
    if not (directory / SENSOR_FILE).is_file() or not (directory / PROJECTOR_FILE).is_file():
        return None
    report = {}
    if (directory / PHOTOMETRY_FILE).is_file():
        report = read_json(directory / PHOTOMETRY_FILE, "twin photometry", expect=dict)
    ambient = report.get("ambient", 0.0)
    if isinstance(ambient, bool) or not isinstance(ambient, int | float) or ambient < 0:
        raise InputError(f"{directory / PHOTOMETRY_FILE}: ambient", "a number >= 0", ambient)
    return PhotometricFit(
        load_sensor(directory / SENSOR_FILE),
        load_projector(directory / PROJECTOR_FILE),
        float(ambient),
    )


@dataclass
class TwinValidation:
    """Per-pose and overall differences between real captures and their twin renders."""

    per_pose: list[dict[str, Any]]
    overall: dict[str, float]
    dropped: dict[str, str] = field(default_factory=dict)
    maps: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: units, per pose, overall, dropped poses (and the difference maps'
        files, when they were saved)."""
        data = {
            "units": {"centre": "px", "proj_uv": "projector px", "cloud": "mm"},
            "per_pose": self.per_pose,
            "overall": self.overall,
            "dropped": self.dropped,
        }
        if self.maps:
            data["maps"] = self.maps
        return data


def _board_poses(calibration: str | Path) -> tuple[dict[str, Pose], dict[str, Any] | None]:
    """The calibrated board poses by name and the board of a ``calibration.json`` (else {})."""
    path = Path(calibration)
    if path.suffix.lower() != ".json":
        return {}, None
    data = read_json(path, "calibration", expect=dict)
    poses = {
        str(item["name"]): Pose.from_dict(item["board2cam"], "board2cam")
        for item in data.get("per_pose", [])
        if isinstance(item, dict) and "board2cam" in item and "name" in item
    }
    return poses, data.get("board")


def _pnp(rig: Rig, board: Board, points: np.ndarray) -> Pose:
    import cv2

    K, dist = rig.camera.intrinsics.to_opencv()  # noqa: N806
    ok, rvec, tvec = cv2.solvePnP(board.object_points, points, K, dist)
    if not ok:
        raise VirtusError("twin validation: could not place the board (solvePnP failed)")
    return Pose.from_rotvec(rvec.ravel(), tvec.ravel())


def stereo_board_pose(
    rig: Rig, board: Board, cam_points: np.ndarray, homographies: np.ndarray
) -> tuple[Pose, dict[str, float]]:
    """The board pose seen by both devices: each board point triangulated from its camera
    position (``cam_points``, (N, 2) px, circle centres corrected for the centroid bias of
    their images as calibration does) and its projector position (``homographies``, (N, 3,
    3) local camera -> projector maps evaluated there), and the board's points fitted to
    them by the rigid motion of least squares (Kabsch / Horn's closed form). The board then
    lies on the surface the rig reconstructs, whatever error its calibration has (camera-only
    PnP places it by the camera's focal length alone). Returns ``board2cam`` and the fit's
    errors: ``fit_mm`` (RMS 3-D residual), ``camera`` and ``projector`` (RMS reprojection
    error, px)."""
    from virtus.calib.board import CircleBoard
    from virtus.calib.projector import apply_homographies
    from virtus.calib.solve import centroid_bias
    from virtus.reconstruct import triangulate

    obj = board.object_points
    cam = np.asarray(cam_points, dtype=np.float64)
    if isinstance(board, CircleBoard):
        cam = cam - centroid_bias(rig.camera.intrinsics, board, _pnp(rig, board, cam))
    proj = apply_homographies(homographies, cam)
    points = triangulate(rig, cam, proj)
    seen = np.isfinite(points).all(axis=1)
    if seen.sum() < 3:
        raise VirtusError("twin validation: fewer than 3 board points seen by both devices")
    a, b = obj[seen], points[seen]
    centre_a, centre_b = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - centre_a).T @ (b - centre_b))
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    rotation = vt.T @ flip @ u.T
    pose = Pose(rotation, centre_b - rotation @ centre_a)
    in_cam = pose.apply(obj)
    r_cam = rig.camera.intrinsics.project(in_cam) - cam
    r_proj = rig.projector.intrinsics.project(rig.cam2proj.apply(in_cam[seen])) - proj[seen]
    errors = {
        "fit_mm": float(1e3 * np.sqrt(np.mean(np.sum((pose.apply(a) - b) ** 2, axis=1)))),
        "camera": float(np.sqrt(np.mean(np.sum(r_cam**2, axis=1)))),
        "projector": float(np.sqrt(np.mean(np.sum(r_proj**2, axis=1)))),
    }
    return pose, errors


def _on_board(rig: Rig, board: Board, board2cam: Pose) -> np.ndarray:
    """(H, W) bool: camera pixels whose ray meets the board plane inside the plane."""
    intr = rig.camera.intrinsics
    rays = intr.unproject(intr.pixel_grid().reshape(-1, 2))
    normal = board2cam.R[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (board2cam.t @ normal) / (rays @ normal)
    local = (rays * s[:, None] - board2cam.t) @ board2cam.R
    half = 0.5 * np.asarray(board.plane_size_m) * (1.0 - BOARD_EDGE_FRACTION)
    inside = (s > 0) & (np.abs(local[:, 0]) < half[0]) & (np.abs(local[:, 1]) < half[1])
    return inside.reshape(intr.height, intr.width)


def _board_words(board: Board) -> str:
    """``"7x13 circle grid"`` or ``"6x9 checkerboard"`` (inner corners), for messages."""
    kind = "checkerboard" if board.TYPE == "checkerboard" else "circle grid"
    return f"{board.rows}x{board.cols} {kind}"  # type: ignore[union-attr]


def _check_board(board: Board, recorded: Any, spec: Any, items: list[Any]) -> None:
    """Refuse a board the captures do not show (naming ``--board`` when it was given): one
    of other geometry than the calibration file's board, or one found in none of the
    captures (its grid is searched in the white frame, else the phase background, until
    one capture shows it)."""
    from virtus.calib.detect import find_grid

    name = "--board" if spec is not None else "board (of the calibration file)"
    if spec is not None and recorded is not None:
        calibrated = board_from_dict(recorded)
        same = (
            calibrated.TYPE == board.TYPE
            and calibrated.object_points.shape == board.object_points.shape
            and np.allclose(calibrated.object_points, board.object_points, rtol=0, atol=1e-9)
        )
        if not same:
            raise InputError(
                name,
                f"the board the calibration used ({_board_words(calibrated)}, "
                f"{calibrated.center_distance_m * 1e3:g} mm apart)",
                f"{spec} ({_board_words(board)}, {board.center_distance_m * 1e3:g} mm apart)",
            )

    def shows(item: Any) -> bool:  # loaded here, not kept: the frames of one pose at a time
        real = item if isinstance(item, Capture) else Capture.load(item)
        kinds = [frame.kind for frame in real.sequence.frames]
        if "white" in kinds:
            image = real.frames[kinds.index("white")]
        else:
            image = real.decode().background
        return find_grid(image, board) is not None

    if items and not any(shows(item) for item in items):
        raise InputError(
            name,
            "the board the captures show",
            f"{spec or _board_words(board)}: no {_board_words(board)} found in any of the "
            f"{len(items)} captures",
        )


def _binned(values: np.ndarray, factor: int) -> np.ndarray:
    """``(L, H, W)`` averaged over ``factor x factor`` blocks (NaN ignored; a block of NaN
    only stays NaN), float32."""
    if factor == 1:
        return values.astype(np.float32)
    layers, height, width = values.shape
    h, w = -(-height // factor), -(-width // factor)
    padded = np.full((layers, h * factor, w * factor), np.nan)
    padded[:, :height, :width] = values
    blocks = padded.reshape(layers, h, factor, w, factor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks stay NaN, silently
        return np.nanmean(blocks, axis=(2, 4)).astype(np.float32)


def difference_maps(
    real: Capture, virtual: Capture, mask: np.ndarray, proj_distance: np.ndarray
) -> tuple[np.ndarray, int]:
    """The per-pose difference maps (module docstring): ``(4, h, w)`` float32 in the order
    of :data:`MAP_LAYERS`, and the binning factor. ``mask``: (H, W) bool, the compared
    pixels; ``proj_distance``: (H, W) projector px, the decoded-coordinate distance."""
    kinds = [frame.kind for frame in real.sequence.frames]
    height, width = mask.shape
    maps = np.full((len(MAP_LAYERS), height, width), np.nan)
    if "white" in kinds and np.any(mask):
        white = kinds.index("white")
        scale_real = float(real.frames[white][mask].mean())
        scale_twin = float(virtual.frames[white][mask].mean())
        codes = ("gray", "binary", "gray_complement", "binary_complement")
        firsts = (white, next((i for i, k in enumerate(kinds) if k == "phase"), None),
                  next((i for i, k in enumerate(kinds) if k in codes), None))  # fmt: skip
        for layer, index in enumerate(firsts):
            if index is None:
                continue
            a = real.frames[index].astype(np.float64) / scale_real
            b = virtual.frames[index].astype(np.float64) / scale_twin
            maps[layer][mask] = (a - b)[mask]
    maps[3][mask] = proj_distance[mask]
    factor = max(1, -(-max(height, width) // MAP_MAX_SIDE))
    return _binned(maps, factor), factor


def compare_captures(
    rig: Rig,
    board: Board,
    board2cam: Pose,
    real: Capture,
    virtual: Capture,
    name: str,
    maps: list[tuple[np.ndarray, int]] | None = None,
) -> dict[str, Any]:
    """Differences between a real capture and its twin render (module docstring); with
    ``maps`` (a list), the pose's :func:`difference_maps` are appended to it."""
    from scipy.spatial import cKDTree

    obs_real, obs_virtual = observe_pose(real, board, name), observe_pose(virtual, board, name)
    row: dict[str, Any] = {"name": name}
    if obs_real.cam_centroids is not None and obs_virtual.cam_centroids is not None:
        diff = np.linalg.norm(obs_real.cam_centroids - obs_virtual.cam_centroids, axis=1)
        row["centre_diff_mean_px"] = float(np.nanmean(diff))
        row["centre_diff_max_px"] = float(np.nanmax(diff))
    # Repaired fringe orders on both sides: a real frame's order errors are not the twin's.
    dec_real, dec_virtual = real.decode(repair=True), virtual.decode(repair=True)
    both = dec_real.mask & dec_virtual.mask & _on_board(rig, board, board2cam)
    delta = dec_real.proj_uv[both] - dec_virtual.proj_uv[both]
    distance_uv = np.sqrt(np.sum(delta**2, axis=1))
    row["proj_uv_rms_px"] = float(np.sqrt(np.mean(distance_uv**2)))
    row["proj_uv_median_px"] = float(np.median(distance_uv))
    row["pixels"] = int(both.sum())
    if maps is not None:
        distance_map = np.full(both.shape, np.nan)
        distance_map[both] = distance_uv
        maps.append(difference_maps(real, virtual, both, distance_map))
    cloud_real = points_from_decoded(rig, dec_real.proj_uv, both)[both]
    cloud_virtual = points_from_decoded(rig, dec_virtual.proj_uv, both)[both]
    cloud_real = cloud_real[np.isfinite(cloud_real).all(axis=1)]
    cloud_virtual = cloud_virtual[np.isfinite(cloud_virtual).all(axis=1)]
    distance, _ = cKDTree(cloud_virtual).query(cloud_real)
    row["cloud_mae_mm"] = float(1e3 * np.mean(distance))
    row["cloud_rmse_mm"] = float(1e3 * np.sqrt(np.mean(distance**2)))
    row["cloud_median_mm"] = float(1e3 * np.median(distance))
    row.update(frame_differences(real, virtual, both))
    row["point_noise_real_mm"] = float(1e3 * fit_plane(cloud_real).rms)
    row["point_noise_twin_mm"] = float(1e3 * fit_plane(cloud_virtual).rms)
    row["point_noise_ratio"] = row["point_noise_real_mm"] / row["point_noise_twin_mm"]
    return row


def check_validation(
    calibration: str | Path | Rig,
    captures: list[str | Path | Capture],
    *,
    board: str | Board | None = None,
    units: str | None = None,
) -> None:
    """The checks :func:`validate_twin` makes before it renders anything (the board known and
    shown by the captures, the captures readable), so a job can refuse bad validation inputs
    before it writes the twin. Raises what :func:`validate_twin` raises for them."""
    _validation_inputs(calibration, captures, board, units)


def _validation_inputs(
    calibration: str | Path | Rig,
    captures: list[str | Path | Capture],
    board: str | Board | None,
    units: str | None,
) -> tuple[Rig, dict[str, Pose], Board, list[Any]]:
    """The rig, the calibration's board poses by name, the board and the captures of a
    validation, checked before anything is rendered."""
    poses: dict[str, Pose] = {}
    board_data = None
    if isinstance(calibration, Rig):
        rig = calibration
    else:
        rig = load_calibration(calibration, units=units)
        poses, board_data = _board_poses(calibration)
    if board is None and board_data is None:
        raise InputError("board", "a board (the calibration file names none)", None)
    the_board = board_from_spec(board) if board is not None else board_from_dict(board_data)
    items: list[Any] = list(captures)
    if items and all(isinstance(item, str | Path) for item in items):
        items = capture_dirs(items)
    _check_board(the_board, board_data, board, items)
    return rig, poses, the_board, items


def validate_twin(
    calibration: str | Path | Rig,
    captures: list[str | Path | Capture],
    *,
    board: str | Board | None = None,
    spp: int = 1,
    out: str | Path | None = None,
    units: str | None = None,
    twin: str | Path | PhotometricFit | None = None,
) -> TwinValidation:
    """Render every captured pose with the twin and compare (module docstring).

    Parameters
    ----------
    calibration : the calibration (a file :func:`load_calibration` reads, or a rig); a
        ``calibration.json`` also gives the board poses and the board.
    captures : the real calibration captures (directories, folders of them, or captures).
    board : the board (default: the calibration file's).
    spp : supersamples of the twin renders.
    out : if given, the table is written there as JSON, and each pose's difference maps
        beside it (``<folder of out>/validation_maps/pose_NNN.npy``, module docstring).
    twin : the twin's fitted light (a twin directory, :func:`load_photometry`, or a fit):
        its camera, projector and ambient level render the poses; without it the captures'
        own sensor (or an ideal one) and an ideal projector do.

    Raises
    ------
    InputError : no board known, captures of another size than the calibration's camera or
        of another bit depth than the fitted camera's.
    """
    from virtus.render.settings import RenderSettings
    from virtus.scene.model import Scene

    light = load_photometry(twin) if isinstance(twin, str | Path) else twin

    rig, poses, the_board, items = _validation_inputs(calibration, captures, board, units)
    texture = board_texture(the_board)
    per_pose: list[dict[str, Any]] = []
    dropped: dict[str, str] = {}
    map_files: dict[str, Any] = {}
    for index, item in enumerate(items):
        real = item if isinstance(item, Capture) else Capture.load(item)
        name = real.path.name if real.path is not None else f"pose_{index + 1:03d}"
        cam = rig.camera.intrinsics
        if real.frames.shape[1:] != (cam.height, cam.width):
            raise InputError(
                f"capture {name!r}", f"{cam.width}x{cam.height} px frames", real.frames.shape
            )
        board2cam = poses.get(name)
        posed: dict[str, Any] = {"posed_by": "calibration"}
        if board2cam is None:
            obs = observe_pose(real, the_board, name)
            if obs.problem() is not None:
                dropped[name] = obs.problem()  # type: ignore[assignment]
                continue
            points, maps = obs.cam_centroids, obs.homographies
            board2cam, errors = stereo_board_pose(rig, the_board, points, maps)  # type: ignore[arg-type]
            posed = {"posed_by": "stereo", "pose_errors": errors}
        sensor = real.sensor or Sensor().with_(bit_depth=real.bit_depth)
        if light is not None and light.sensor.bit_depth != real.bit_depth:
            raise InputError(
                f"capture {name!r}", f"{light.sensor.bit_depth}-bit frames (the twin's camera)",
                real.bit_depth,
            )  # fmt: skip
        scanner = Scanner(
            rig=rig,
            sequence=real.sequence,
            sensor=sensor if light is None else light.sensor,
            projector=ProjectorModel() if light is None else light.projector,
            render=RenderSettings(spp=spp),
        )
        scene = board_scene(the_board, BoardPose(name, board2cam), texture)
        if light is not None and light.ambient > 0:
            scene = Scene(objects=scene.objects, ambient=light.ambient)
        virtual = scanner.capture(scene)
        pose_maps: list[tuple[np.ndarray, int]] | None = None if out is None else []
        row = compare_captures(rig, the_board, board2cam, real, virtual, name, pose_maps)
        per_pose.append({**row, **posed})
        if out is not None and pose_maps:
            _save_maps(Path(out).parent, f"pose_{index + 1:03d}.npy", name, pose_maps[0],
                       map_files)  # fmt: skip
    if not per_pose:
        raise VirtusError("twin validation: no pose could be compared" + f" ({dropped})")
    result = TwinValidation(per_pose, _overall(per_pose), dropped, map_files)
    if out is not None:
        write_json(Path(out), result.to_dict())
    return result


def _save_maps(
    folder: Path, file: str, name: str, pose_maps: tuple[np.ndarray, int], maps: dict[str, Any]
) -> None:
    """Write one pose's maps to ``folder/MAPS_DIR/file`` and list it in ``maps``."""
    values, factor = pose_maps
    target = folder / MAPS_DIR / file
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(target, lambda tmp: np.save(tmp, values))
    if not maps:
        maps.update(layers=list(MAP_LAYERS), bin=factor, files={},
                    units={"white": "share of the mean white level", "fringe": "same",
                           "code": "same", "proj_uv": "projector px"})  # fmt: skip
    maps["files"][name] = {"file": f"{MAPS_DIR}/{file}", "sha256": file_digest(target),
                           "shape": list(values.shape), "bin": factor}  # fmt: skip


def run_twin(
    calibration: str | Path,
    out_dir: str | Path,
    *,
    validate: list[str | Path] | None = None,
    board: str | None = None,
    spp: int = 1,
    **twin_options: Any,
) -> tuple[dict[str, Path], TwinValidation | None]:
    """``virtus twin``: :func:`write_twin` (``twin_options`` are its keywords) and, with
    ``validate`` (capture directories), :func:`validate_twin` into ``out_dir`` (with the
    fitted light when ``twin_options`` has ``fit``), in a run directory owned through
    :func:`virtus.io.runs.claim_run` (command ``twin``): ``run.json`` says ``running`` while
    the job runs, ``complete`` or ``failed`` after, and lists the files written. A new twin
    replaces an earlier twin's files in ``out_dir``; a directory that holds another
    command's run is refused. The calibration is read before anything is written.

    Raises
    ------
    InputError : a calibration that cannot be read, a bad ``pixel_size_m``.
    VirtusError : ``out_dir`` holds another command's run, or is locked by another run.
    """
    from virtus.errors import RunConflict
    from virtus.io.runs import RUN_FILE

    positive("pixel_size_m", twin_options.get("pixel_size_m", DEFAULT_PIXEL_SIZE_M))
    sizes = {k: twin_options.get(k) for k in ("units", "camera_size", "projector_size")}
    load_calibration(calibration, **sizes)  # refused before anything is written
    out = Path(out_dir)
    if (out / RUN_FILE).is_file():
        old = read_json(out / RUN_FILE, "run record", expect=dict)
        if old.get("command") != TWIN_COMMAND:
            raise RunConflict(f"{out} holds a `virtus {old.get('command')}` run; choose "
                              "another output directory for the twin")  # fmt: skip
    config = {
        "calibration": str(calibration),
        "validate": [str(p) for p in validate or []],
        "board": board,
        "spp": spp,
        **{k: _plain(v) for k, v in twin_options.items()},
    }
    inputs = {"calibration": calibration} if Path(calibration).is_file() else {}
    result = None
    with claim_run(out, TWIN_COMMAND, config, inputs=inputs, layout=TWIN_LAYOUT,
                   overwrite=True) as run:  # fmt: skip
        try:
            written = write_twin(calibration, out, **twin_options)
            if validate:
                result = validate_twin(
                    calibration, list(validate), board=board, spp=spp,
                    out=out / VALIDATION_FILE, units=twin_options.get("units"),
                    twin=out if twin_options.get("fit") else None,
                )  # fmt: skip
        finally:  # the files written so far, also of a failed run (an overwrite removes them)
            run.own(*(p.relative_to(out).as_posix() for pattern in TWIN_LAYOUT
                      for p in sorted(out.glob(pattern)) if p.is_file()))  # fmt: skip
    return written, result


def _plain(value: Any) -> Any:
    """A twin option as JSON data for the run record (paths and models as text)."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return str(value)


def _overall(per_pose: list[dict[str, Any]]) -> dict[str, float]:
    """The per-pose rows summed up (pixel-weighted where a row is an average over pixels)."""
    weights = np.array([row["pixels"] for row in per_pose], dtype=np.float64)
    centres = [r.get("centre_diff_mean_px", np.nan) for r in per_pose]

    def pooled_rms(key: str) -> float:
        return float(np.sqrt(np.average([r[key] ** 2 for r in per_pose], weights=weights)))

    overall = {
        "centre_diff_mean_px": float(np.mean(centres)),
        "centre_diff_max_px": float(
            np.max([r.get("centre_diff_max_px", np.nan) for r in per_pose])
        ),
        "proj_uv_rms_px": float(
            np.sqrt(np.average([r["proj_uv_rms_px"] ** 2 for r in per_pose], weights=weights))
        ),
        "cloud_mae_mm": float(np.average([r["cloud_mae_mm"] for r in per_pose], weights=weights)),
        "cloud_rmse_mm": float(
            np.sqrt(np.average([r["cloud_rmse_mm"] ** 2 for r in per_pose], weights=weights))
        ),
        "paper_cloud_mae_mm": PAPER_CLOUD_MAE_MM,
    }
    for key in ("white_rms", "black_rms", "fringe_rms", "code_rms"):
        overall[key] = pooled_rms(key)
    overall["point_noise_real_mm"] = pooled_rms("point_noise_real_mm")
    overall["point_noise_twin_mm"] = pooled_rms("point_noise_twin_mm")
    overall["point_noise_ratio"] = overall["point_noise_real_mm"] / overall["point_noise_twin_mm"]
    return overall
