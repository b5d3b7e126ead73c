"""The evaluation numbers of fringe-analysis networks, in one place (numpy only).

Per sample, :func:`sample_errors` compares a predicted depth map (and, for a phase model,
predicted wrapped phase and fringe order) with the truth; :class:`MetricSums` adds samples
up and :meth:`MetricSums.summary` gives the community's numbers:

* ``object_mae_mm``, ``object_rmse_mm`` -- over the objects' pixels (FPP-ML-Bench's "object
  MAE": their 14.54 mm, PhiCalNet's 4.46 mm),
* ``background_mae_mm``, ``background_rmse_mm`` -- over the other pixels with a surface
  (background planes, boards),
* ``phase_rmse_rad`` -- of the wrapped phase, the difference wrapped to ``[-pi, pi)``,
* ``order_error_rate`` -- share of valid pixels whose fringe order is wrong,
* ``wrap_mae_mm`` / ``nonwrap_mae_mm`` and ``wrap_share`` -- depth error on the pixels within
  :data:`WRAP_BAND_RAD` of the ``+-pi`` wrap and elsewhere (PhiCalNet: the residual sits on
  the ~0.1 % of pixels at the wrap),
* ``flat_rms_mm`` -- for planes-only samples (the flat-plane test): RMS distance of the
  predicted points to the least-squares plane through them, per sample, averaged (a network
  that measures fringes predicts a plane; one that paints object outlines does not),
* ``valid_share`` -- share of surface pixels with a finite prediction.

Depths in metres in, millimetres out (names say so); a metric with no pixel is None.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "PUBLISHED_OBJECT_MAE_MM",
    "WRAP_BAND_RAD",
    "MetricSums",
    "plane_rms",
    "sample_errors",
    "wrap_to_pi",
]

#: Published object MAE (mm) on FPP-ML-Bench's data (960 x 960, 1.5-2.1 m, held-out test
#: objects): the UNet baseline (arXiv 2601.08900 v2, their best) and PhiCalNet's wrapped
#: phase + fixed calibration layer (arXiv 2606.17093). Benchmarks print results beside them.
PUBLISHED_OBJECT_MAE_MM = {"unet": 14.54, "phase": 4.46}
#: Pixels whose true wrapped phase is within this of +-pi count as "at the wrap": a
#: network's phase error there picks the wrong fringe order. 0.1 rad is 1.6 % of a period.
WRAP_BAND_RAD = 0.1


def wrap_to_pi(phase: np.ndarray) -> np.ndarray:
    """``phase`` wrapped to ``[-pi, pi)``."""
    return (np.asarray(phase, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def plane_rms(points: np.ndarray) -> float | None:
    """RMS distance (same unit as ``points`` ``(N, 3)``) to their least-squares plane."""
    pts = points[np.isfinite(points).all(axis=1)]
    if len(pts) < 3:
        return None
    centred = pts - pts.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    return float(np.sqrt(np.mean((centred @ normal) ** 2)))


@dataclass
class MetricSums:
    """Sums of errors over samples (``add`` the output of :func:`sample_errors`)."""

    sums: dict[str, float] = field(default_factory=dict)
    flat: list[float] = field(default_factory=list)
    samples: int = 0

    def add(self, errors: dict[str, Any]) -> None:
        self.samples += 1
        for key, value in errors.items():
            if key == "flat_rms_mm":
                if value is not None:
                    self.flat.append(value)
            else:
                self.sums[key] = self.sums.get(key, 0.0) + float(value)

    def _ratio(self, num: str, den: str, root: bool = False) -> float | None:
        count = self.sums.get(den, 0.0)
        if count <= 0:
            return None
        value = self.sums.get(num, 0.0) / count
        return float(np.sqrt(value) if root else value)

    def summary(self) -> dict[str, Any]:
        """The numbers of the module docstring, plus ``samples``."""
        return {
            "samples": self.samples,
            "object_mae_mm": self._ratio("object_abs", "object_n"),
            "object_rmse_mm": self._ratio("object_sq", "object_n", root=True),
            "background_mae_mm": self._ratio("background_abs", "background_n"),
            "background_rmse_mm": self._ratio("background_sq", "background_n", root=True),
            "phase_rmse_rad": self._ratio("phase_sq", "phase_n", root=True),
            "order_error_rate": self._ratio("order_wrong", "phase_n"),
            "wrap_mae_mm": self._ratio("wrap_abs", "wrap_n"),
            "nonwrap_mae_mm": self._ratio("nonwrap_abs", "nonwrap_n"),
            "wrap_share": self._ratio("wrap_n", "phase_n"),
            "flat_rms_mm": float(np.mean(self.flat)) if self.flat else None,
            "valid_share": self._ratio("predicted_n", "surface_n"),
        }


def sample_errors(
    pred_depth: np.ndarray,
    depth: np.ndarray,
    surface: np.ndarray,
    objects: np.ndarray,
    *,
    rays: np.ndarray | None = None,
    pred_wrapped: np.ndarray | None = None,
    wrapped: np.ndarray | None = None,
    pred_order: np.ndarray | None = None,
    order: np.ndarray | None = None,
    valid: np.ndarray | None = None,
) -> dict[str, Any]:
    """Error sums of one sample (``(H, W)`` maps; depths in metres).

    Parameters
    ----------
    pred_depth : predicted depth, NaN where the model gives none (counted as missing, not as
        an error: ``valid_share`` says how much is missing).
    depth, surface, objects : true depth, where a surface is, where an object is.
    rays : (H, W, 3) camera rays (any length with z = 1 preferred); with them and no object
        in the sample, the flat-plane RMS of the predicted points is computed.
    pred_wrapped, wrapped, pred_order, order, valid : phase model only (rad; orders int).
    """
    err_mm = (pred_depth - depth) * 1000.0
    predicted = surface & np.isfinite(pred_depth)
    obj = predicted & objects
    bg = predicted & ~objects
    out: dict[str, Any] = {
        "object_abs": np.abs(err_mm[obj]).sum(),
        "object_sq": (err_mm[obj] ** 2).sum(),
        "object_n": obj.sum(),
        "background_abs": np.abs(err_mm[bg]).sum(),
        "background_sq": (err_mm[bg] ** 2).sum(),
        "background_n": bg.sum(),
        "predicted_n": predicted.sum(),
        "surface_n": surface.sum(),
    }
    if rays is not None and not objects.any():
        points = (rays / rays[..., 2:3]) * pred_depth[..., None] * 1000.0
        out["flat_rms_mm"] = plane_rms(points[predicted])
    if pred_wrapped is not None and wrapped is not None and valid is not None:
        diff = wrap_to_pi(pred_wrapped - wrapped)
        ok = valid & np.isfinite(diff)
        at_wrap = ok & (np.abs(wrap_to_pi(wrapped)) > np.pi - WRAP_BAND_RAD)
        rest = ok & ~at_wrap
        out.update(
            phase_sq=(diff[ok] ** 2).sum(),
            phase_n=ok.sum(),
            order_wrong=(pred_order[ok] != order[ok]).sum() if pred_order is not None else 0,
            wrap_abs=np.nansum(np.abs(err_mm[at_wrap & predicted])),
            wrap_n=(at_wrap & predicted).sum(),
            nonwrap_abs=np.nansum(np.abs(err_mm[rest & predicted])),
            nonwrap_n=(rest & predicted).sum(),
        )
    return out
