"""The full virtual VDI/VDE 2634-2 acceptance test (10 spheres, 7 ball bars, 6 planes) of the
paper's scanner, in the settings the tests check in miniature, side by side:

* ``true-nearest``: ideal sensor, sharp DMD pixels, the true rig (the staircase alone);
* ``true-bilinear``: ideal sensor, projector pixels blurred over ~1 px, the true rig;
* ``calibrated``: ideal sensor, DMD pixels, the rig from a virtual calibration (the default);
* ``imx174``: the IMX174 sensor, DMD pixels, a virtual calibration;
* ``scale+1%``: ``true-bilinear`` reconstructed with a baseline 1 % long (SD ~ 1 % of the bar).

Reports each figure's largest magnitude (mm) and the wall time of each run. The renderer
takes CUDA where it works, else the CPU; ``--scale 0.25`` makes a quick CPU run (240 px
camera), ``--positions N`` a shortened one.

``--fit-bias`` instead measures, position by position (ideal sensor, DMD pixels, true rig),
the decoded coordinates' error against the true correspondences (mean and RMS, projector px)
and P_S and SD beside what the least-squares fit's own bias predicts from that RMS
(:func:`virtus.design.figures.expected_fit_bias`): why P_S and SD are not zero with sharp
DMD pixels (figures' module docstring).

    PYTHONPATH=src python benchmarks/bench_acceptance.py [--scale 1] [--positions N]
        [--only NAME ...] [--fit-bias] [--json out.json]

Not a test: numbers depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def scanners(scale: float) -> dict[str, tuple[object, object]]:
    """name -> (scanner, calibration) of each setting."""
    from virtus.geometry.devices import Camera, Rig, default_rig
    from virtus.geometry.transforms import Pose
    from virtus.scanner import Scanner
    from virtus.sensor import Lookup, load_projector, load_sensor

    rig = default_rig()
    rig = Rig(Camera(rig.camera.intrinsics.scaled(scale)), rig.projector, rig.proj2cam)
    dmd = Scanner(rig=rig)
    blurred = dmd.with_(projector=load_projector("ideal").with_(pixel=Lookup.bilinear))
    long = Rig(rig.camera, rig.projector, Pose(rig.proj2cam.R, 1.01 * np.asarray(rig.proj2cam.t)))
    return {
        "true-nearest": (dmd, "true"),
        "true-bilinear": (blurred, "true"),
        "calibrated": (dmd, "virtual"),
        "imx174": (dmd.with_(sensor=load_sensor("imx174")), "virtual"),
        "scale+1%": (blurred, long),
    }


def fit_bias_study(scale: float, positions: int | None) -> list[dict]:
    """P_S and SD of the sphere and ball-bar positions with DMD pixels and the true rig,
    measured and predicted from the staircase's RMS (module docstring)."""
    from virtus.design.acceptance import _position_seed, interior
    from virtus.design.artefacts import artefact_layout
    from virtus.design.figures import expected_fit_bias, measure_sphere, sphere_normals
    from virtus.design.volume import volume_from_rig
    from virtus.reconstruct import reconstruct

    scanner = scanners(scale)["true-nearest"][0]
    rig = scanner.rig
    sizes, layout = artefact_layout(volume_from_rig(rig), rig, positions)
    rows = []
    print(f"{'position':12s} {'mean du':>8s} {'mean dv':>8s} {'rms du':>7s} {'rms dv':>7s}"
          f" {'measured':>9s} {'predicted':>9s} (P_S or SD, mm)")  # fmt: skip
    for position in layout:
        if position.feature == "plane":
            continue
        capture = scanner.capture(position.scene(), rng=_position_seed(0, position.name))
        decoded = capture.decode()
        points = reconstruct(rig, decoded.proj_uv, interior(decoded.mask)).points
        fits, errors = [], []
        for centre in position.centres_m:
            fit = measure_sphere(points, centre, position.radius_m)
            cam_px = fit.pixels[:, ::-1].astype(float)
            _, _, true_uv = sphere_normals(rig, cam_px, centre, position.radius_m)
            error = decoded.proj_uv[fit.pixels[:, 0], fit.pixels[:, 1]] - true_uv
            fits.append((fit, cam_px, np.asarray(centre)))
            errors.append(error[np.isfinite(error).all(axis=1)])
        error = np.concatenate(errors)
        rms = np.sqrt((error**2).mean(axis=0))
        predicted = [expected_fit_bias(rig, cam, c, position.radius_m, rms) for _, cam, c in fits]
        if position.feature == "sphere":
            measured = 1e3 * (fits[0][0].diameter_m - sizes.sphere_diameter_m)
            expected = 1e3 * predicted[0][0]
        else:
            (a, _, ca), (b, _, cb) = fits
            measured = 1e3 * (np.linalg.norm(b.centre_m - a.centre_m) - sizes.bar_length_m)
            moved = (cb + predicted[1][1]) - (ca + predicted[0][1])
            expected = 1e3 * (np.linalg.norm(moved) - sizes.bar_length_m)
        mean = error.mean(axis=0)
        rows.append({"position": position.name, "mean_px": mean.tolist(), "rms_px": rms.tolist(),
                     "measured_mm": measured, "predicted_mm": expected})  # fmt: skip
        print(f"{position.name:12s} {mean[0]:+8.4f} {mean[1]:+8.4f} {rms[0]:7.3f} {rms[1]:7.3f}"
              f" {measured:+9.4f} {expected:+9.4f}", flush=True)  # fmt: skip
    for feature, figure in (("sphere", "P_S"), ("ball_bar", "SD")):
        mine = [r for r in rows if r["position"].startswith(feature)]
        if mine:
            measured = np.array([r["measured_mm"] for r in mine])
            expected = np.array([r["predicted_mm"] for r in mine])
            print(f"{figure}: mean measured {measured.mean():+.4f} mm, predicted "
                  f"{expected.mean():+.4f} mm; measured - predicted: sd "
                  f"{(measured - expected).std(ddof=1) if len(mine) > 1 else 0.0:.4f} mm "
                  f"over {len(mine)} positions")  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="camera resampling factor")
    parser.add_argument("--positions", type=int, default=None)
    parser.add_argument("--only", nargs="*", default=None, help="settings to run")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    parser.add_argument("--fit-bias", action="store_true",
                        help="P_S and SD of DMD pixels, measured vs the fit's bias")  # fmt: skip
    args = parser.parse_args()
    if args.fit_bias:
        rows = fit_bias_study(args.scale, args.positions)
        if args.json is not None:
            args.json.write_text(json.dumps({"camera_scale": args.scale, "fit_bias": rows},
                                            indent=1) + "\n")  # fmt: skip
        return

    from virtus.design import acceptance_test
    from virtus.render.backend import choose_variant

    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs"
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (scanner, calibration) in scanners(args.scale).items():
            if args.only and name not in args.only:
                continue
            start = time.perf_counter()
            result = acceptance_test(
                scanner,
                Path(tmp) / name.replace("%", "pct"),
                calibration=calibration,
                positions=args.positions,
            )
            seconds = time.perf_counter() - start
            maxima = {k: v["value_mm"] for k, v in result.summary["maxima"].items()}
            length = result.summary["artefacts"]["bar_length_mm"]
            rows[name] = {"seconds": seconds, "max_mm": maxima, "bar_length_mm": length}
            figures = "  ".join(f"{k} {v:+.4f}" for k, v in maxima.items())
            print(f"{name:14s} {seconds:7.1f} s  {figures}", flush=True)
    report = {
        "machine": machine,
        "variant": choose_variant(None),
        "camera_scale": args.scale,
        "positions": args.positions,
        "runs": rows,
    }
    print(json.dumps(report, indent=1))
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
