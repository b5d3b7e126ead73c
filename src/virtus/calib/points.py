"""Saved calibration correspondences: per board pose, the board's points, their camera pixels
and their projector pixels, read from the layouts benches and tools write
(:func:`read_points`), and calibrated (:meth:`PointSet.calibrate`). The job behind
``virtus calibrate --from-points`` is :func:`virtus.pipeline.calibrate.calibrate_points`.

Layouts (``source``; pixels are (x, y) = (u, v) with the centre of the top-left pixel at
(0, 0), OpenCV's convention; object points in metres, board frame, z = 0 on the plane):

* **One file per pose per device** (a folder): ``cam/<pose>.txt`` and ``proj/<pose>.txt``
  (optionally ``obj/<pose>.txt``), or ``<pose>_cam.txt`` and ``<pose>_proj.txt``
  (optionally ``<pose>_obj.txt``). One point per line, ``x y`` (object: ``x y`` or
  ``x y z``), separated by spaces, tabs or commas; blank lines and ``#`` comments are
  skipped; line *i* of every file of a pose is the same point, ``nan nan`` a point that
  device did not see. Object points come from the pose's ``obj`` file, else from one
  ``object_points.txt`` in the folder, else from the board (line *i* = board point *i*).
* **One CSV file** (``*.csv``) with a header naming the columns ``pose,id,x_cam,y_cam,
  x_proj,y_proj`` (any order, case ignored; more columns are ignored), one row per point;
  ``id`` is the board point's index (:attr:`Board.object_points` order) unless the columns
  ``x_obj,y_obj[,z_obj]`` give the object point. Poses keep their first row's order.
* **NumPy pose files** (a folder of ``*.npz``, or a folder holding ``poses/*.npz``): virtus's
  own ``poses/<name>.npz`` (``cam_centroids`` (N, 2), ``homographies`` (N, 3, 3); see
  :mod:`virtus.pipeline.calibrate`) are solved exactly as ``virtus calibrate`` solves them
  (perspective-bias correction, local homographies), with the board and image sizes of the
  run's ``episode.json`` when there is one; files with ``cam_points`` and ``proj_points``
  (N, 2) (and optionally ``object_points`` (N, 3)) are correspondences like the text files.

Correspondences of the text layouts are taken as exact images of the object points (no
perspective-bias correction): :func:`~virtus.calib.solve.calibrate_correspondences`.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.calib.board import Board, board_from_dict, board_from_spec
from virtus.calib.conditioning import warn_conditioning
from virtus.calib.poses import BoardPose, check_pose_spread
from virtus.calib.result import CalibrationResult
from virtus.calib.solve import (
    DEFAULT_DISTORTION,
    PoseObservation,
    StereoCalibration,
    calibrate_correspondences,
    calibrate_observations,
    distortion_setting,
)
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.io.safeio import load_npz, read_json, read_text

__all__ = ["LAYOUTS", "PointSet", "parse_sizes", "read_points"]

#: Layout names, as :attr:`PointSet.layout` and ``episode.json`` give them.
LAYOUTS = ("txt", "csv", "npz")
#: The CSV layout's required columns.
CSV_COLUMNS = ("pose", "id", "x_cam", "y_cam", "x_proj", "y_proj")
#: Largest points file read (64 MiB: millions of points).
MAX_POINTS_BYTES = 64 * 2**20
_SIZE = r"\s*(\d{1,6})\s*[xX]\s*(\d{1,6})\s*"
#: Pose names, object points, camera points, projector points.
_Columns = tuple[list[str], list[np.ndarray], list[np.ndarray], list[np.ndarray]]


@dataclass
class PointSet:
    """Correspondences read by :func:`read_points`.

    Attributes
    ----------
    layout : one of :data:`LAYOUTS`.
    names : the poses.
    camera_size, projector_size : (width, height) px.
    board : the board (None when every object point was given).
    object_points, cam_points, proj_points : per pose, (N_k, 3) metres and (N_k, 2) px
        (None for virtus's own pose files, which are ``observations``).
    observations : virtus pose files' observations (None otherwise).
    inputs : name -> file read (their checksums go into ``run.json``).
    source : what was read.
    """

    layout: str
    names: list[str]
    camera_size: tuple[int, int]
    projector_size: tuple[int, int]
    board: Board | None = None
    object_points: list[np.ndarray] | None = None
    cam_points: list[np.ndarray] | None = None
    proj_points: list[np.ndarray] | None = None
    observations: list[PoseObservation] | None = None
    inputs: dict[str, Path] = field(default_factory=dict)
    source: str = ""

    def describe(self) -> dict[str, Any]:
        """JSON-ready description (the ``episode.json`` of a run)."""
        return {
            "source": "points",
            "points": self.source,
            "layout": self.layout,
            "names": list(self.names),
            "board": None if self.board is None else self.board.to_dict(),
            "camera_size": list(self.camera_size),
            "projector_size": list(self.projector_size),
        }

    def check_output(self, out_dir: str | Path) -> None:
        """Refuse an output folder that is the source or holds it (a run there would own,
        and ``overwrite`` remove, what was read)."""
        source = Path(self.source).resolve()
        if Path(out_dir).resolve() in (source, *source.parents):
            raise InputError("out_dir", f"a folder that does not hold {self.source}", out_dir)

    def solve(
        self, *, fix_intrinsics: bool = False, distortion: str = DEFAULT_DISTORTION
    ) -> StereoCalibration:
        """The solver's result (:mod:`virtus.calib.solve`) for these points."""
        sizes = (self.camera_size, self.projector_size)
        options = {"fix_intrinsics": bool(fix_intrinsics), "distortion": distortion}
        if self.observations is not None:
            assert self.board is not None
            return calibrate_observations(self.board, self.observations, *sizes, **options)
        assert self.object_points is not None and self.cam_points is not None
        assert self.proj_points is not None
        return calibrate_correspondences(
            self.names, self.object_points, self.cam_points, self.proj_points, *sizes, **options
        )

    def calibrate(
        self,
        *,
        fix_intrinsics: bool = False,
        distortion: str = DEFAULT_DISTORTION,
    ) -> CalibrationResult:
        """Calibrate (:meth:`solve`), refuse a degenerate pose set
        (:func:`~virtus.calib.poses.check_pose_spread` on the solved poses, as for captures)
        and issue the conditioning warnings.

        Returns
        -------
        :class:`CalibrationResult` with ``poses`` the solved board poses, no truth comparison,
        ``settings`` what was read and how it was solved.
        """
        solved = self.solve(fix_intrinsics=fix_intrinsics, distortion=distortion)
        poses = [
            BoardPose(p["name"], pose)
            for p, pose in zip(solved.per_pose, solved.board2cam, strict=True)
        ]
        check_pose_spread(poses)
        warn_conditioning(solved.conditioning)
        return CalibrationResult(
            rig=solved.rig,
            rms_px=solved.rms_px,
            per_pose=solved.per_pose,
            truth_error=None,
            board=self.board,
            poses=poses,
            dropped_poses=solved.dropped_poses,
            settings={
                **{k: v for k, v in self.describe().items() if k in ("source", "points", "layout")},
                "n_poses": len(self.names),
                "fix_intrinsics": bool(fix_intrinsics),
                **distortion_setting(distortion),
            },
            uncertainty=solved.uncertainty,
            conditioning=solved.conditioning,
        )


def parse_sizes(sizes: Any) -> tuple[tuple[int, int], tuple[int, int]]:
    """``((camera w, h), (projector w, h))`` from ``"960x960,912x1140"`` or nested pairs."""
    if isinstance(sizes, str):
        match = re.fullmatch(f"{_SIZE},{_SIZE}", sizes)
        if match:
            w1, h1, w2, h2 = (int(g) for g in match.groups())
            sizes = ((w1, h1), (w2, h2))
    try:
        pairs = tuple(tuple(int(v) for v in pair) for pair in sizes)
        ok = len(pairs) == 2 and all(len(p) == 2 and min(p) > 0 for p in pairs)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(
            "sizes", "camera and projector image sizes, e.g. '960x960,912x1140'", sizes
        )
    return pairs  # type: ignore[return-value]


def _numbers(path: Path, columns: tuple[int, ...]) -> np.ndarray:
    """The points of a text file: one per line, ``columns`` numbers each (module docstring)."""
    rows = []
    text = read_text(path, "points file", max_bytes=MAX_POINTS_BYTES)
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = re.split(r"[\s,;]+", line)
        try:
            values = [float(v) for v in parts]
        except ValueError:
            values = []
        if len(values) not in columns:
            wanted = " or ".join(f"{n} numbers" for n in columns)
            raise InputError(f"points file {path} line {number}", wanted, line)
        rows.append(values + [0.0] * (max(columns) - len(values)))
    if not rows:
        raise InputError(f"points file {path}", "at least one point", "no points")
    return np.array(rows, dtype=np.float64)


def _board_points(board: Board | None, what: str, count: int) -> np.ndarray:
    """The board's first ``count`` object points (the text files give none)."""
    if board is None:
        raise InputError("board", f"a board (the object points of {what})", None)
    if count > board.n_points:
        raise InputError(what, f"at most the board's {board.n_points} points", f"{count} points")
    return board.object_points[:count]


def _read_txt(folder: Path, board: Board | None) -> _Columns:
    """Per-pose text files (module docstring)."""
    if (folder / "cam").is_dir() and (folder / "proj").is_dir():
        files = {p.stem: (p, folder / "proj" / p.name, folder / "obj" / p.name)
                 for p in sorted((folder / "cam").glob("*.txt"))}  # fmt: skip
    else:
        files = {
            p.name[: -len("_cam.txt")]: (
                p,
                p.with_name(p.name.replace("_cam.txt", "_proj.txt")),
                p.with_name(p.name.replace("_cam.txt", "_obj.txt")),
            )
            for p in sorted(folder.glob("*_cam.txt"))
        }
    shared = folder / "object_points.txt"
    common = _numbers(shared, (2, 3)) if shared.is_file() else None
    names, objs, cams, projs = [], [], [], []
    for name, (cam_file, proj_file, obj_file) in files.items():
        if not proj_file.is_file():
            raise InputError(f"pose {name!r}", f"a projector file {proj_file}", "none")
        cam, proj = _numbers(cam_file, (2,)), _numbers(proj_file, (2,))
        if obj_file.is_file():
            obj = _numbers(obj_file, (2, 3))
        else:
            obj = common if common is not None else _board_points(board, str(cam_file), len(cam))
        if not len(cam) == len(proj) == len(obj):
            raise InputError(
                f"pose {name!r}",
                "as many camera, projector and object points",
                f"{len(cam)}, {len(proj)} and {len(obj)}",
            )
        names.append(name)
        objs.append(obj)
        cams.append(cam)
        projs.append(proj)
    return names, objs, cams, projs


def _read_csv(path: Path, board: Board | None) -> _Columns:
    """One CSV file of every pose's points (module docstring)."""
    text = read_text(path, "points file", max_bytes=MAX_POINTS_BYTES)
    reader = csv.reader(io.StringIO(text))
    header = [h.strip().lower() for h in next(reader, [])]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise InputError(f"points file {path}", f"columns {', '.join(CSV_COLUMNS)}", header)
    col = {name: header.index(name) for name in header}
    given = "x_obj" in col and "y_obj" in col
    poses: dict[str, list[list[float]]] = {}
    for number, row in enumerate(reader, start=2):
        if not row or not "".join(row).strip():
            continue
        try:
            obj = [float(row[col[c]]) for c in ("x_obj", "y_obj")] if given else []
            obj += [float(row[col["z_obj"]]) if given and "z_obj" in col else 0.0]
            index = int(row[col["id"]])
            pixels = [float(row[col[c]] or "nan") for c in CSV_COLUMNS[2:]]
        except (ValueError, IndexError):
            raise InputError(f"points file {path} line {number}", "numbers", row) from None
        if not given:
            points = _board_points(board, str(path), board.n_points if board else 0)
            if not 0 <= index < len(points):
                raise InputError(f"points file {path} line {number}", "a board point id", index)
            obj = list(points[index])
        poses.setdefault(row[col["pose"]].strip(), []).append([*obj, *pixels])
    if not poses:
        raise InputError(f"points file {path}", "at least one point", "no rows")
    tables = [np.array(rows, dtype=np.float64) for rows in poses.values()]
    return (list(poses), [t[:, :3] for t in tables], [t[:, 3:5] for t in tables],
            [t[:, 5:7] for t in tables])  # fmt: skip


def _array(arrays: dict[str, np.ndarray], name: str, shape: tuple, path: Path) -> Any:
    """``arrays[name]`` as float64 of shape (N, *shape) (None if absent), else InputError."""
    array = arrays.get(name)
    if array is None:
        return None
    if array.ndim != 1 + len(shape) or array.shape[1:] != shape or array.dtype.kind not in "fi":
        wanted = f"(N, {', '.join(map(str, shape))}) numbers"
        raise InputError(f"pose file {path}: {name}", wanted, f"{array.dtype} {array.shape}")
    return array.astype(np.float64)


def _episode_of(folder: Path) -> dict[str, Any] | None:
    """The ``episode.json`` beside or above a folder of pose files (None if there is none)."""
    for candidate in (folder / "episode.json", folder.parent / "episode.json"):
        if candidate.is_file():
            return read_json(candidate, "calibration episode", expect=dict)
    return None


def _read_npz(folder: Path, board: Board | None, sizes: Any) -> tuple[PointSet, dict[str, Path]]:
    """NumPy pose files (module docstring)."""
    poses_dir = folder / "poses" if (folder / "poses").is_dir() else folder
    files = {p.stem: p for p in sorted(poses_dir.glob("*.npz"))}
    episode = _episode_of(poses_dir) or {}
    poses = episode.get("poses") if isinstance(episode.get("poses"), list) else []
    listed = episode.get("names") or [p.get("name") for p in poses if isinstance(p, dict)]
    recorded = [n for n in listed if isinstance(n, str) and n in files]
    order = recorded + [n for n in files if n not in recorded]
    if "board" in episode:
        run_board = board_from_dict(episode["board"])
        if board is not None and board.to_dict() != run_board.to_dict():
            raise InputError("board", "the board of the run's episode.json (or none)", board)
        board = run_board
    if sizes is None and "true_rig" in episode:
        rig = Rig.from_dict(episode["true_rig"])
        sizes = (rig.camera.intrinsics.size, rig.projector.intrinsics.size)
    elif sizes is None and "camera_size" in episode:
        sizes = (episode["camera_size"], episode["projector_size"])
    if sizes is None:
        raise InputError("sizes", "the camera and projector image sizes (no episode.json)", None)
    camera_size, projector_size = parse_sizes(sizes)
    shapes = {"cam_points": (2,), "proj_points": (2,), "object_points": (3,),
              "cam_centroids": (2,), "homographies": (3, 3)}  # fmt: skip
    arrays = {}
    for name in order:
        loaded = load_npz(files[name], "pose file")
        arrays[name] = {k: _array(loaded, k, shape, files[name]) for k, shape in shapes.items()}
    point_set = PointSet("npz", order, camera_size, projector_size, board)
    if order and all(a["cam_points"] is not None for a in arrays.values()):
        point_set.cam_points = [a["cam_points"] for a in arrays.values()]
        point_set.proj_points = [a["proj_points"] for a in arrays.values()]
        point_set.object_points = [
            _board_points(board, str(files[n]), len(a["cam_points"]))
            if a["object_points"] is None
            else a["object_points"]
            for n, a in arrays.items()
        ]
        for (n, a), obj in zip(arrays.items(), point_set.object_points, strict=True):
            lengths = [len(x) for x in (a["cam_points"], a["proj_points"], obj) if x is not None]
            if len(lengths) < 3 or len(set(lengths)) > 1:
                what = "cam_points, proj_points (and object_points) of one length"
                raise InputError(f"pose file {files[n]}", what, lengths)
    else:
        if board is None:
            raise InputError("board", f"a board (no episode.json beside {poses_dir})", None)
        point_set.observations = [
            PoseObservation(n, a["cam_centroids"], a["homographies"]) for n, a in arrays.items()
        ]
    return point_set, {f"pose {n}": files[n] for n in order}


def read_points(
    source: str | Path, *, board: str | Board | None = None, sizes: Any = None
) -> PointSet:
    """Read saved correspondences in any layout of the module docstring.

    Parameters
    ----------
    source : a ``.csv`` file, or a folder of per-pose text files or of ``.npz`` pose files
        (or a run directory holding ``poses/``).
    board : a board or a spec (:func:`~virtus.calib.board.board_from_spec`), for layouts
        whose object points are board indices; a run's ``episode.json`` gives its own.
    sizes : ``((camera w, h), (projector w, h))`` px or ``"960x960,912x1140"``; required
        unless a run's ``episode.json`` gives them.

    Raises
    ------
    InputError : a source in no known layout, a file that is not numbers, mismatched point
        counts, missing board or sizes (each naming the file or argument).
    """
    path = Path(source)
    the_board = None if board is None else board_from_spec(board)
    if path.is_dir() and (any(path.glob("*.npz")) or any(path.glob("poses/*.npz"))):
        point_set, inputs = _read_npz(path, the_board, sizes)
        point_set.inputs, point_set.source = inputs, str(path)
        return point_set
    if path.is_file() and path.suffix.lower() == ".csv":
        layout, (names, objs, cams, projs) = "csv", _read_csv(path, the_board)
        inputs = {"points": path}
    elif path.is_dir():
        layout, (names, objs, cams, projs) = "txt", _read_txt(path, the_board)
        inputs = {f"points {p.relative_to(path)}": p for p in sorted(path.rglob("*.txt"))}
    else:
        names = []
    if not names:
        raise InputError(
            "points",
            "a .csv file or a folder of per-pose files (cam/ and proj/, *_cam.txt and "
            "*_proj.txt, or .npz pose files)",
            str(path),
        )
    if sizes is None:
        raise InputError("sizes", "the camera and projector image sizes", None)
    camera_size, projector_size = parse_sizes(sizes)
    return PointSet(
        layout, names, camera_size, projector_size, the_board, objs, cams, projs, None,
        inputs, str(path),
    )  # fmt: skip
