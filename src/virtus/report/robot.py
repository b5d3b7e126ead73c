"""Report section of a robot scan (``virtus robot-scan``, :mod:`virtus.robot.scan`): the views
(joint values rendered and reported, points), the merged cloud's cloud-to-mesh distance with
kinematics alone and after the per-view ICP, coverage, the first view's frames and decode,
and the merged cloud in 3D (world frame)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from virtus.report import scan
from virtus.report.html import Page

__all__ = ["RESULT_JSON", "add_robot_scan", "view_dirs"]

#: The robot scan's summary (views, C2M, coverage), as :mod:`virtus.robot.scan` names it.
RESULT_JSON = "robot_scan.json"


def view_dirs(path: Path, data: dict[str, Any]) -> list[Path]:
    """The view directories ``robot_scan.json`` lists (each a capture directory)."""
    return [path / str(v.get("view")) for v in data["views"] if isinstance(v, dict)]


def add_robot_scan(page: Page, path: Path) -> dict[str, Any]:
    """The robot scan's sections (module docstring)."""
    from virtus.io.ply import read_ply
    from virtus.paper import C2M_MAE_MM
    from virtus.report.runs import read_run_json

    data = read_run_json(path, RESULT_JSON, "robot scan summary",
                         ("views", "c2m_kinematics", "coverage_kinematics"))  # fmt: skip
    section = page.section("Robot scan", "robot")
    section.note(f"{len(data['views'])} views; joint noise {data.get('joint_noise_rad')} rad "
                 f"(the reported joint values are the rendered ones plus this noise); "
                 f"units: {data.get('units')}.")  # fmt: skip
    views = [v for v in data["views"] if isinstance(v, dict)]
    section.grid("views", ["view", "points", "q (rad)", "q reported (rad)"],
                 [[v.get("view"), v.get("points"), v.get("q"), v.get("q_reported")]
                  for v in views])  # fmt: skip
    coverage = data["coverage_kinematics"]
    if isinstance(coverage, dict):
        section.table("coverage (merged cloud, kinematics alone)", coverage)
    if isinstance(data.get("plan"), dict):
        section.table("plan", data["plan"])
    entries = [e for e in data["c2m_kinematics"] if isinstance(e, dict)]
    scan.add_c2m(page, entries, "Cloud-to-mesh distance, kinematics alone", C2M_MAE_MM,
                 registration="merged by the arm's kinematics alone (no registration)")  # fmt: skip
    icp = [e for e in data.get("c2m_icp", []) if isinstance(e, dict)]
    if icp:
        how = {
            "views": "views registered onto each other (ICP, no mesh)",
            "mesh": "each view registered onto the scene's mesh (ICP, evaluation aid)",
        }
        label = how.get(str(data.get("icp")), f"after ICP ({data.get('icp')})")
        scan.add_c2m(page, icp, "Cloud-to-mesh distance, after ICP", C2M_MAE_MM,
                     registration=label)  # fmt: skip
    first = view_dirs(path, data)[:1]
    for view in first:
        scan.add_capture(page, view, f"First view ({view.name}): frames")
        scan.add_decode(page, view, f"First view ({view.name}): decode")
    merged = read_ply(path / "merged.ply")
    scan.add_cloud(page, merged.points, None, "depth", "3D view",
                   "merged.ply, world frame (kinematics alone); colour: z")  # fmt: skip
    return data
