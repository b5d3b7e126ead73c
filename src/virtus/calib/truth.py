"""Comparison of a calibrated rig with the true rig that rendered the images.

Only a virtual sensor can do this: every number is "estimated minus true".
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics


def _device_error(estimated: Intrinsics, true: Intrinsics) -> dict[str, Any]:
    n = max(len(estimated.dist_array), len(true.dist_array))
    est_dist = np.pad(estimated.dist_array, (0, n - len(estimated.dist_array)))
    true_dist = np.pad(true.dist_array, (0, n - len(true.dist_array)))
    return {
        "fx_rel_error": estimated.fx / true.fx - 1.0,
        "fy_rel_error": estimated.fy / true.fy - 1.0,
        "cx_error_px": estimated.cx - true.cx,
        "cy_error_px": estimated.cy - true.cy,
        "principal_point_error_px": float(np.hypot(estimated.cx - true.cx, estimated.cy - true.cy)),
        "dist_estimated": est_dist.tolist(),
        "dist_true": true_dist.tolist(),
        "dist_error": (est_dist - true_dist).tolist(),
    }


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """Angle (degrees) of a (3, 3) rotation matrix, accurate for tiny angles."""
    # atan2(|skew part|, trace part) is well conditioned near 0 (acos is not).
    skew = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    return float(
        np.degrees(np.arctan2(0.5 * np.linalg.norm(skew), 0.5 * (np.trace(rotation) - 1.0)))
    )


def truth_error(estimated: Rig, true: Rig) -> dict[str, Any]:
    """Errors of a calibrated rig against the truth.

    Returns
    -------
    dict with ``camera`` and ``projector`` (``fx_rel_error``, ``fy_rel_error`` (fractions),
    ``cx_error_px``, ``cy_error_px``, ``principal_point_error_px``, distortion estimated /
    true / error) and ``proj2cam``: ``baseline_error_m`` (difference of the baseline
    lengths), ``translation_error_m`` (norm of the difference of the projector centres),
    ``rotation_error_deg`` (angle of R_est R_true^T).
    """
    rel = estimated.proj2cam.R @ true.proj2cam.R.T
    return {
        "camera": _device_error(estimated.camera.intrinsics, true.camera.intrinsics),
        "projector": _device_error(estimated.projector.intrinsics, true.projector.intrinsics),
        "proj2cam": {
            "baseline_error_m": estimated.baseline_m - true.baseline_m,
            "translation_error_m": float(np.linalg.norm(estimated.proj2cam.t - true.proj2cam.t)),
            "rotation_error_deg": rotation_angle_deg(rel),
        },
    }
