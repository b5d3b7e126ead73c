"""The photometric twin on a real capture: how close the twin's frames come to a real
LightCrafter 4500 bench's before and after ``twin --fit``.

The capture: github.com/kimthyung/3D_Reconstruction_with_Fringe_pattern (no licence file:
read here, never copied into virtus), commit 561120b, ``3D_reconstruction/data00/p00/``
(52 BMPs, 1936 x 1464, 8 bit, a 7 x 21 white-on-black circle board at ~320 mm; the frames
``examples/sequences/lightcrafter_lab.yaml`` describes) and the lab's calibration
``3D_reconstruction/CalibrationDataDistortion/`` (OpenCV text files, mm). ``SOURCE`` is a
clone or a bare git directory of that repository (e.g. a ``git clone --bare``).

What it does, printing and writing (``--json``) every number:

1. stages the calibration folder as the lab names it (its one camera ``...Right`` beside
   ``Proj...`` files: :mod:`virtus.calib.names` reads those as the camera; the circle-point
   files are named as ignored);
2. imports the BMPs (:func:`virtus.pipeline.capture.import_images`) and decodes them with
   fringe-order repair: valid and flagged pixels on the board;
3. the geometric twin (ideal projector, ideal 8-bit camera): the board posed from both
   devices (:func:`virtus.pipeline.twin.stereo_board_pose`), rendered, compared
   (:func:`virtus.pipeline.twin.validate_twin`): normalised white/black/fringe/code frame RMS,
   projector-coordinate RMS, cloud MAE/RMSE, point noise real / twin;
   The twin board's background level (albedo over the circles') is measured on the white
   frame (the spec's white-on-black default, 0.25, is not this board's);
4. fits the light to the capture (:func:`virtus.twin.photometric.fit_photometry` on the
   board's white circles, eroded off their edges: one albedo; the same, only, pose: a fit
   *and* a check on one board, not a held-out test) and validates again.

    PYTHONPATH=src python benchmarks/bench_twin_real.py SOURCE [--spp 1] [--json out.json]

Runs on CPU in a few minutes (two 1936 x 1464 renders of 52 frames); a CUDA Mitsuba variant
is used where present. Not a test: the capture is not shipped (no licence).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

#: The commit of the public repository that holds the board capture.
COMMIT = "561120bda012c02f35e0e2a3c3517daf41a888d7"
CAPTURE_DIR = "3D_reconstruction/data00/p00"
CALIBRATION_DIR = "3D_reconstruction/CalibrationDataDistortion"
#: The lab's calibration folder, copied unchanged (names as the lab wrote them).
CALIBRATION_FILES = (
    *("CamIntrinsicMatrixRight.txt", "CamDistortionCoefficientsRight.txt"),
    *("CamRotationMatrixRight.txt", "CamTranslationVectorRight.txt"),
    *("ProjIntrinsicMatrix.txt", "ProjDistortionCoefficients.txt"),
    *("ProjRotationMatrix.txt", "ProjTranslationVector.txt"),
    *("cameraCirclePointsRight.txt", "projectorCirclePoints.txt"),
)
#: The board: 7 circles per column, 21 columns, 20 mm between neighbours of a column (the
#: board's own label, "10 mm", is OpenCV's asymmetric-grid unit, half that); the circles'
#: diameter measured on the white frame (area of the thresholded blobs: 48.6 px at 6.66 px/mm).
BOARD = "circles:7x21,spacing_mm=20,diameter_mm=7.3,white_on_black"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SEQUENCE = EXAMPLES / "sequences" / "lightcrafter_lab.yaml"
#: The rows of the validation table printed.
KEYS = (
    *("white_rms", "black_rms", "fringe_rms", "code_rms", "proj_uv_rms_px", "cloud_mae_mm"),
    *("cloud_rmse_mm", "point_noise_real_mm", "point_noise_twin_mm", "point_noise_ratio"),
)


def stage(source: Path, work: Path) -> tuple[Path, Path]:
    """The capture's BMPs and the lab's calibration folder under ``work``."""
    images, calibration = work / "images", work / "calibration"
    images.mkdir(parents=True)
    calibration.mkdir()
    bare = (source / "objects").is_dir() and (source / "HEAD").is_file()

    def copy(path: str, target: Path) -> None:
        if bare:
            blob = subprocess.run(
                ["git", f"--git-dir={source}", "show", f"{COMMIT}:{path}"],
                check=True, capture_output=True,
            ).stdout  # fmt: skip
            target.write_bytes(blob)
        else:
            shutil.copyfile(source / path, target)

    for index in range(52):
        copy(f"{CAPTURE_DIR}/{index:02d}.Bmp", images / f"{index:02d}.bmp")
    for name in CALIBRATION_FILES:
        copy(f"{CALIBRATION_DIR}/{name}", calibration / name)
    return images, calibration


def ndimage_circles(capture) -> np.ndarray:
    """The board's circles as the white frame shows them (not eroded)."""
    from scipy import ndimage

    inner, _ = circles_and_levels(capture)
    return ndimage.binary_dilation(inner, iterations=5)


def white_circles(capture, factor: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The board's white circles in a capture binned by ``factor`` (blobs of the white -
    black frame above mid-level, of the median area; edges not eroded) and that white -
    black frame (float64). Also ``bench_sim2real``'s fitting region."""
    from scipy import ndimage

    kinds = [frame.kind for frame in capture.sequence.frames]
    signal = capture.frames[kinds.index("white")].astype(np.float64)
    signal -= capture.frames[kinds.index("black")]
    threshold = 0.5 * (np.percentile(signal, 10) + np.percentile(signal, 99.5))
    labels, count = ndimage.label(signal > threshold)
    areas = ndimage.sum_labels(np.ones_like(signal), labels, np.arange(1, count + 1))
    median = np.median(areas[areas > 100 / factor**2])
    keep = np.flatnonzero((areas > 0.5 * median) & (areas < 2.0 * median)) + 1
    return np.isin(labels, keep), signal


def circles_and_levels(capture) -> tuple[np.ndarray, float]:
    """The board's white circles (:func:`white_circles`, eroded 5 px off their blurred edges:
    one albedo, for the fit) and the board's background over its circles (the twin board's
    printed contrast, measured: the spec's white-on-black default is 0.25)."""
    from scipy import ndimage

    circles, signal = white_circles(capture)
    inner = ndimage.binary_erosion(circles, iterations=5)
    rows, cols = np.nonzero(circles)
    box = np.zeros_like(circles)
    box[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1] = True
    background = box & ~ndimage.binary_dilation(circles, iterations=12)
    return inner, float(np.median(signal[background]) / np.median(signal[inner]))


def edge_split(real, virtual, circles: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Normalised frame RMS (white, phase, code frames; each capture over its mean white on
    ``mask``) within 6 px of a circle's edge and away from the edges: where misregistration
    of the board's print counts, and where the light alone does."""
    from scipy import ndimage

    edge = ndimage.binary_dilation(circles, iterations=6) & ~ndimage.binary_erosion(
        circles, iterations=6
    )
    kinds = [frame.kind for frame in real.sequence.frames]
    white = kinds.index("white")
    used = [i for i, kind in enumerate(kinds) if kind in ("white", "phase", "gray")]
    a = real.frames[used][:, mask].astype(np.float64) / real.frames[white][mask].mean()
    b = virtual.frames[used][:, mask].astype(np.float64) / virtual.frames[white][mask].mean()
    near = edge[mask]
    square = (a - b) ** 2
    return {
        "edge_rms": float(np.sqrt(square[:, near].mean())),
        "flat_rms": float(np.sqrt(square[:, ~near].mean())),
        "edge_share_of_pixels": float(near.mean()),
    }


def decode_stats(capture, rig, board) -> dict[str, float]:
    """Valid and flagged pixels inside the board (posed from both devices), repaired too."""
    from virtus.calib.observe import observe_pose
    from virtus.pipeline.twin import _on_board, stereo_board_pose

    obs = observe_pose(capture, board, "p00")
    pose, errors = stereo_board_pose(rig, board, obs.cam_centroids, obs.homographies)
    inside = _on_board(rig, board, pose)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain, repaired = capture.decode(), capture.decode(repair=True)
    valid = plain.mask & inside
    return {
        "board_pixels": int(inside.sum()),
        "valid_fraction": float(valid.sum() / inside.sum()),
        "flagged_fraction": float((plain.flagged & valid).sum() / valid.sum()),
        "flagged_after_repair": float(
            (repaired.flagged & repaired.mask & inside).sum()
            / max((repaired.mask & inside).sum(), 1)
        ),  # fmt: skip
        "pose_fit_mm": errors["fit_mm"],
        "pose_reprojection_camera_px": errors["camera"],
        "pose_reprojection_projector_px": errors["projector"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="clone or bare git dir of the capture's repo")
    parser.add_argument("--spp", type=int, default=1, help="supersamples of the twin renders")
    parser.add_argument("--albedo", type=float, default=1.0, help="albedo of the lit circles")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()

    import dataclasses

    import virtus.pipeline.twin as twin_job
    from virtus.calib.board import board_from_spec
    from virtus.pipeline.capture import import_images
    from virtus.pipeline.twin import validate_twin
    from virtus.sensor.camera import Sensor
    from virtus.twin.photometric import fit_photometry

    board = board_from_spec(BOARD)
    results: dict = {"source": f"kimthyung/3D_Reconstruction_with_Fringe_pattern@{COMMIT[:7]}"}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        images, calibration = stage(args.source, work)
        imported = import_images(images, SEQUENCE, calibration, work / "capture", units="mm")
        capture, rig = imported.capture, imported.rig
        region, level = circles_and_levels(capture)
        board = dataclasses.replace(board, background_level=level)
        results["board"] = {"spec": BOARD, "background_level": level,
                            "region_px": int(region.sum())}  # fmt: skip
        results["decode"] = decode_stats(capture, rig, board)
        renders: list = []  # the twin's captures, kept for the edge split
        compare = twin_job.compare_captures

        def keep(rig_, board_, pose, real, virtual, name):  # noqa: ANN001, ANN202
            renders.append((virtual, twin_job._on_board(rig_, board_, pose)))
            return compare(rig_, board_, pose, real, virtual, name)

        twin_job.compare_captures = keep
        start = time.perf_counter()
        before = validate_twin(rig, [capture], board=board, spp=args.spp)
        results["render_s"] = time.perf_counter() - start
        fit = fit_photometry(
            [capture], rig, prior_sensor=Sensor(bit_depth=8), albedo=args.albedo,
            regions=[region],
        )  # fmt: skip
        after = validate_twin(rig, [capture], board=board, spp=args.spp, twin=fit)
        circles = ndimage_circles(capture)
        for label, (virtual, inside) in zip(("before", "after"), renders, strict=True):
            mask = inside & capture.decode().mask & virtual.decode().mask
            results[f"split_{label}"] = edge_split(capture, virtual, circles, mask)
    results["before"] = {key: before.per_pose[0][key] for key in KEYS}
    results["after"] = {key: after.per_pose[0][key] for key in KEYS}
    results["fit"] = {
        "sensor": fit.sensor.to_dict(),
        "projector": fit.projector.to_dict(),
        "ambient": fit.ambient,
        "shading": {k: v for k, v in fit.report["shading"].items() if not isinstance(v, list)},
        "notes": fit.report["notes"],
    }
    print(json.dumps({**results["board"], **results["decode"]}, indent=1))
    print("edge/flat split, before:", results["split_before"], "after:", results["split_after"])
    print(f"{'':24s}{'geometric twin':>16s}{'fitted twin':>14s}")
    for key in KEYS:
        print(f"{key:24s}{results['before'][key]:16.4f}{results['after'][key]:14.4f}")
    shading = results["fit"]["shading"]
    print(
        f"fitted: gamma {fit.projector.gamma:.3f}, blur {fit.projector.psf_sigma_px:.3f} px, "
        f"vignetting cos^{shading['camera_exponent']:.2f}, fall-off "
        f"cos^{shading['projector_exponent']:.2f} (separable: {shading['separable']}), "
        f"gain {fit.sensor.system_gain_dn_per_e} DN/e-, dark noise {fit.sensor.dark_noise_e} e-, "
        f"ambient {fit.ambient:.4g}"
    )
    for note in results["fit"]["notes"]:
        print("note:", note)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
