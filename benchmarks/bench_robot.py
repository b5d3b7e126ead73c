"""The sensor on a robot, measured: kinematics, IK, coverage planning, merged scans, hand-eye.

Usage::

    python benchmarks/bench_robot.py --tiny          # CPU, minutes: a 240 px camera, 1 spp
    python benchmarks/bench_robot.py                 # full rig (960 px, 4 spp); use a GPU

Sections (each prints a line and lands in OUT/bench_robot.json):

1. FK of the built-in Panda vs yourdfpy on examples/robots/panda.urdf (1,000 random
   configurations): largest difference (m), and microseconds per FK of all links.
2. IK on 200 random reachable targets (FK of collision-free random q): success share at
   1e-6 m / 1e-6 rad, median and 95th-percentile time.
3. View planning of the built-in free-form object (robot-scan's ``freeform`` world, the
   example robot file): coverage of the camera-and-projector-measurable surface after each
   of at most 8 views.
4. robot-scan of that plan with joint noise sigma in JOINT_NOISE (rad): merged C2M MAE (mm)
   with kinematics alone and after per-view ICP; coverage of the measurable surface.
5. Hand-eye from rendered board captures at 10 poses (camera on the hand looking at a board
   on the floor from ~0.9 m, +-25 deg; the paper's 4x7 board and a 54 x 60 mm one):
   errors against the mounted truth with the ideal sensor and with the IMX174 preset
   (always the full 960 px camera; --tiny: 1 spp).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "robots" / "panda_wrist.yaml"
JOINT_NOISE = (0.0, 2e-5, 5e-5, 1e-4)


def kinematics() -> dict:
    import yourdfpy

    from virtus.robot.model import builtin_robot

    robot = builtin_robot("panda")
    tree = robot.tree
    model = yourdfpy.URDF.load(str(ROOT / "examples/robots/panda.urdf"), load_meshes=False)
    q = tree.random_q(np.random.default_rng(0), 1000)
    ours = tree.fk(q)
    worst = 0.0
    for k in range(len(q)):
        model.update_cfg(q[k])
        for link in tree.link_names[1:]:
            worst = max(worst, float(np.abs(ours[link][k] - model.get_transform(link)).max()))
    start = time.perf_counter()
    for k in range(200):
        tree.fk(q[k])
    fk_us = (time.perf_counter() - start) / 200 * 1e6
    return {"fk_max_difference_m": worst, "fk_us_per_call": fk_us}


def inverse_kinematics() -> dict:
    from virtus.robot.ik import Unreachable, solve_ik
    from virtus.robot.model import builtin_robot

    robot = builtin_robot("panda")
    q = robot.tree.random_q(np.random.default_rng(1), 400)
    q = q[~robot.in_collision(q)][:200]
    targets = robot.tree.fk(q)["panda_hand"]
    times, ok = [], 0
    for k, target in enumerate(targets):
        start = time.perf_counter()
        try:
            solve_ik(robot, "panda_hand", target, rng=k)
            ok += 1
        except Unreachable:
            pass
        times.append(time.perf_counter() - start)
    return {
        "ik_success": ok / len(targets),
        "ik_targets": len(targets),
        "ik_median_ms": 1e3 * float(np.median(times)),
        "ik_p95_ms": 1e3 * float(np.percentile(times, 95)),
    }


def scanner_for(tiny: bool, sensor: str = "ideal"):  # noqa: ANN201
    from virtus.cli.options import build_scanner
    from virtus.sensor.projector import Lookup

    if not tiny:
        return build_scanner(spp=4, sensor=sensor, lookup=Lookup.bilinear)
    from tests.support import small_rig

    scanner = build_scanner(spp=1, sensor=sensor, lookup=Lookup.bilinear)
    return scanner.with_(rig=small_rig(1 / 4))


def scans(out: Path, tiny: bool) -> dict:
    from virtus.robot.config import load_robot_file
    from virtus.robot.scan import robot_scan

    setup = load_robot_file(EXAMPLE)
    scanner = scanner_for(tiny)
    radius = 0.003 if tiny else 0.001  # about two point spacings on the object
    start = time.perf_counter()
    first = robot_scan(
        setup,
        "freeform",
        out / "scan_plan",
        scanner=scanner,
        plan=8,
        candidates=48,
        icp=True,
        coverage_radius_m=radius,
        overwrite=True,
    )
    result = {
        "plan": first.record["plan"],
        "plan_and_scan_s": time.perf_counter() - start,
        "coverage_radius_mm": radius * 1e3,
        "noise": [],
    }
    trajectory = out / "scan_plan" / "trajectory.json"
    for sigma in JOINT_NOISE:
        start = time.perf_counter()
        run = robot_scan(
            setup,
            "freeform",
            out / f"scan_noise_{sigma:g}",
            scanner=scanner,
            trajectory=trajectory,
            joint_noise_rad=sigma,
            icp=True,
            seed=1,
            coverage_radius_m=radius,
            overwrite=True,
        )
        r = run.record
        result["noise"].append(
            {
                "joint_noise_rad": sigma,
                "views": len(r["views"]),
                "points": int(len(run.merged)),
                "mae_kinematics_mm": r["c2m_kinematics"][0]["mae_mm"],
                "mae_icp_mm": r["c2m_icp"][0]["mae_mm"],
                "rmse_kinematics_mm": r["c2m_kinematics"][0]["rmse_mm"],
                "coverage_of_measurable": r["coverage_kinematics"]["share_of_measurable"],
                "seconds": time.perf_counter() - start,
            }
        )
        print(json.dumps(result["noise"][-1]), flush=True)
    return result


def _board_views(setup, board2world, count: int, rng: np.random.Generator):  # noqa: ANN001, ANN202
    """IK-reachable camera poses looking at the board centre from 0.8-1.0 m, +-25 deg."""
    from virtus.geometry.transforms import Pose
    from virtus.robot.ik import Unreachable

    centre = board2world.t
    qs = []
    while len(qs) < count:
        polar, azimuth = np.radians(rng.uniform(0, 25)), rng.uniform(0, 2 * np.pi)
        d = np.array(
            [np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)]
        )
        eye = centre + rng.uniform(0.85, 0.95) * d
        view = Pose.look_at(eye, centre, image_down=(1.0, 0.0, 0.0))
        view = view @ Pose.from_euler("z", [rng.uniform(-25, 25)])
        try:
            qs.append(setup.solve_view(view, rng=len(qs), starts=16).q)
        except Unreachable:
            continue
    return qs


#: Boards of the hand-eye section: the paper's 4x7 (0.2 m plane) and a 54 x 60 mm one.
BOARDS = ("4x7", "circles:4x7,spacing_mm=12,diameter_mm=6,border_mm=6")


def handeye(out: Path, tiny: bool) -> dict:
    from virtus.calib import board_from_spec, board_texture
    from virtus.cli.options import build_scanner
    from virtus.geometry.transforms import Pose
    from virtus.robot.capture import capture_at
    from virtus.robot.config import load_robot_file
    from virtus.robot.handeye_job import handeye_from_captures
    from virtus.scene.model import PlaneObject, Scene, TexturedPlaneObject
    from virtus.sensor.projector import Lookup

    setup = load_robot_file(EXAMPLE)
    board2world = Pose.from_euler("xyz", [180.0, 0.0, 90.0], t=[0.5, 0.0, 0.001])
    qs = _board_views(setup, board2world, 10, np.random.default_rng(5))
    poses = {
        "hand2base": [
            Pose.from_matrix(setup.robot.tree.link_pose(q, setup.link)).to_dict() for q in qs
        ]
    }
    result = {}
    for b, spec in enumerate(BOARDS):
        board = board_from_spec(spec)
        plane = TexturedPlaneObject(
            size_m=board.plane_size_m, texture=board_texture(board), pose=board2world
        )
        scene = Scene(objects=[plane], background=PlaneObject((3.0, 3.0), Pose.identity()))
        for sensor in ("ideal", "imx174"):
            # the board's circles need the full camera: --tiny only lowers the samples
            scanner = build_scanner(spp=1 if tiny else 4, sensor=sensor, lookup=Lookup.bilinear)
            folder = out / f"handeye_{b}_{sensor}"
            for k, q in enumerate(qs):
                capture = capture_at(scanner, scene, setup, q, folder / f"{k:02d}", seed=k)
                capture.save(folder / f"{k:02d}", overwrite=True)
            (folder / "poses.json").write_text(json.dumps(poses))
            key = f"{spec} {sensor}"
            try:
                _, record = handeye_from_captures(
                    [folder / f"{k:02d}" for k in range(len(qs))],
                    folder / "poses.json",
                    spec,
                    folder / "result",
                    overwrite=True,
                )
                result[key] = {
                    k: record[k]
                    for k in (
                        "expected_rotation_error_deg",
                        "expected_translation_error_mm",
                        "residual_rms",
                        "truth",
                    )
                }
            except Exception as error:  # noqa: BLE001 - a benchmark reports, it does not stop
                result[key] = {"error": str(error)}
            print(key, json.dumps(result[key]), flush=True)
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="CPU-sized run (240 px, 1 spp)")
    parser.add_argument("--out", type=Path, default=Path("bench_robot_out"))
    parser.add_argument("--only", nargs="*", default=["fk", "ik", "scan", "handeye"])
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict = {"tiny": args.tiny}
    for name, job in (("fk", kinematics), ("ik", inverse_kinematics)):
        if name in args.only:
            results[name] = job()
            print(name, json.dumps(results[name]), flush=True)
    if "scan" in args.only:
        results["scan"] = scans(args.out, args.tiny)
    if "handeye" in args.only:
        results["handeye"] = handeye(args.out, args.tiny)
    (args.out / "bench_robot.json").write_text(json.dumps(results, indent=2, default=str))
    print(f"wrote {args.out / 'bench_robot.json'}")


if __name__ == "__main__":
    main()
