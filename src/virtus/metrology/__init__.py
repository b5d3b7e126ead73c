"""Metrology: robust sphere (of a cloud, or of a point map's region of interest) and plane
fits, ICP to a mesh, cloud-to-mesh distance.

Lengths are metres inside; each result's ``to_dict`` reports millimetres with ``_mm`` keys.
"""

from virtus.metrology.c2m import C2MResult, cloud_to_mesh
from virtus.metrology.icp import IcpResult, icp_to_mesh
from virtus.metrology.plane import PlaneFit, fit_plane
from virtus.metrology.proximity import ClosestPoints, MeshIndex, closest_points
from virtus.metrology.sphere import SphereFit, fit_sphere, sphere_from_4_points, sphere_roi_fit
from virtus.metrology.stats import ErrorStats, Histogram, error_stats, histogram

__all__ = [
    "C2MResult",
    "ClosestPoints",
    "ErrorStats",
    "Histogram",
    "IcpResult",
    "MeshIndex",
    "PlaneFit",
    "SphereFit",
    "closest_points",
    "cloud_to_mesh",
    "error_stats",
    "fit_plane",
    "fit_sphere",
    "histogram",
    "icp_to_mesh",
    "sphere_from_4_points",
    "sphere_roi_fit",
]
