"""The exact, differentiable phase -> depth layer: :mod:`virtus.reconstruct`'s triangulation
in torch operations, built from a sample's stored calibration.

A network that predicts the (absolute) phase of vertical fringes gives the projector column
``u_p = Phi T / (2 pi)`` of every camera pixel (``T``: the finest period in projector px).
Each camera pixel has a fixed ray (the camera's distortion removed exactly, once, by
:meth:`virtus.geometry.optics.Intrinsics.unproject`), so depth is a function of ``u_p``
alone: the intersection of the pixel's ray with the projector's surface of constant ``u_p``
-- :func:`virtus.reconstruct.triangulate` with ``use="u"`` (``"v"`` for horizontal fringes).

* Without projector distortion that surface is a plane through the projector centre:
  ``s = n.o / n.a`` in closed form (``a`` the unit camera ray, ``o`` the projector centre in
  the camera frame, ``n`` the plane normal), differentiable as written.
* With distortion it is a curved ruled surface. The ray parameter ``s*`` that projects to
  ``u_p`` is found by Newton's method outside the autograd graph (to ``1e-9`` px in float64,
  as the reference), and one Newton step ``s = s* + (u_p - g(s*)) / g'(s*)`` is taken inside
  it: its value is ``s*`` and its derivative ``1 / g'(s*)``, the exact implicit derivative
  ``ds/du_p`` (``g(s)`` = the projected coordinate of the point ``s a``).

The geometry runs in float64 whatever the input dtype (a float32 ray parameter at 2 m has
~0.1 um ulp, but the plane solve loses digits at grazing angles); results come back in the
input's dtype. Points that the reference returns as NaN (undecoded input, rays parallel to
the surface, behind either device, Newton not converged) are NaN here too, with zero
gradient. Conventions as :mod:`virtus.reconstruct`: metres, OpenCV camera frame, pixel
centres at integer ``(u, v)``, ``rig.proj2cam`` maps projector into camera coordinates.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.errors import InputError
from virtus.learn._torch import require_torch

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig

__all__ = ["DepthLayer", "phase_to_coordinate"]

torch = require_torch()

#: As :mod:`virtus.reconstruct`: rays closer to parallel than this sine are not intersected.
_MIN_SINE = 1e-9
#: Newton on the projected coordinate of a distorted projector (float64), as the reference.
_NEWTON_TOL_PX = 1e-9
_NEWTON_MAX_ITER = 30
#: Largest Newton step (normalised coordinates) at which the undistortion has converged.
_START_TOL = 1e-15


def phase_to_coordinate(phase: Any, period_px: float) -> Any:
    """Projector coordinate ``u_p = Phi T / (2 pi)`` (px) of absolute phase ``Phi`` (rad).

    ``period_px`` is the finest fringe period in projector pixels (the sequence's period in
    pattern units divided by its axis scale, :meth:`DepthLayer.from_record` reads it).
    """
    if not (isinstance(period_px, int | float) and np.isfinite(period_px) and period_px > 0):
        raise InputError("period_px", "a positive number of projector px", period_px)
    return phase * (float(period_px) / (2.0 * np.pi))


def _distort(x: Any, y: Any, k: tuple[float, ...]) -> tuple[Any, Any]:
    """OpenCV's distortion (k1, k2, p1, p2, k3, k4, k5, k6) of normalised coordinates."""
    k1, k2, p1, p2, k3, k4, k5, k6 = k
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


class DepthLayer(torch.nn.Module):
    """Projector coordinate per camera pixel -> camera-frame points, for one rig.

    Parameters
    ----------
    rig : the camera-projector rig (true or calibrated; both devices' distortion is used).
    direction : ``"v"`` (vertical fringes: the input is ``u_p``) or ``"h"`` (``v_p``).

    Calling the layer with ``coord`` of shape ``(..., H, W)`` (projector px, any float dtype,
    NaN where undecoded; ``H x W`` the camera's image size) returns ``(..., H, W, 3)`` points
    in metres in the camera frame (:meth:`forward`); :meth:`depth` returns only ``z``.
    Buffers move with ``.to(device)``.
    """

    def __init__(self, rig: Rig, direction: str = "v") -> None:
        super().__init__()
        if direction not in ("v", "h"):
            raise InputError("direction", "'v' (u_p) or 'h' (v_p)", direction)
        self.axis = 0 if direction == "v" else 1
        intr = rig.camera.intrinsics
        self.size = (intr.height, intr.width)
        rays = intr.unproject(intr.pixel_grid().reshape(-1, 2)).reshape(intr.height, intr.width, 3)
        pose = rig.proj2cam
        R = np.asarray(pose.R, dtype=np.float64)
        t = np.asarray(pose.t, dtype=np.float64)
        proj = rig.projector.intrinsics
        self.focal = float(proj.fx if self.axis == 0 else proj.fy)
        self.centre = float(proj.cx if self.axis == 0 else proj.cy)
        self.proj_k = tuple(
            float(c) for c in np.pad(proj.dist_array, (0, 8 - proj.dist_array.size))
        )
        self.proj_fc = (proj.fx, proj.fy, proj.cx, proj.cy)
        self.distorted = bool(proj.has_distortion)
        self.register_buffer("rays", torch.from_numpy(np.ascontiguousarray(rays)))
        self.register_buffer("R", torch.from_numpy(R.copy()))
        self.register_buffer("t", torch.from_numpy(t.copy()))
        # The camera ray in projector axes (b = R^T a) and the camera centre there (c = -R^T t):
        # a point s a of the camera frame is s b + c in the projector frame.
        self.register_buffer("rays_proj", torch.from_numpy(rays @ R))
        self.register_buffer("centre_proj", torch.from_numpy(-(R.T @ t)))

    @classmethod
    def from_record(cls, record: dict[str, Any], direction: str = "v") -> tuple[DepthLayer, float]:
        """The layer of a stored sample (its ``rig``) and the finest period of ``direction``
        in projector px (its ``sequence``), for :func:`phase_to_coordinate`."""
        from virtus.geometry.devices import Rig
        from virtus.patterns import PatternSequence

        sequence = PatternSequence.from_dict(record["sequence"])
        periods = sequence.periods(direction)
        if not periods:
            raise InputError("sequence", f"a phase set of direction {direction!r}", "none")
        return cls(Rig.from_dict(record["rig"]), direction), periods[0] / sequence.axis_scale(
            direction
        )

    def _check(self, coord: Any) -> None:
        if not torch.is_tensor(coord) or not coord.is_floating_point():
            raise InputError("coord", "a floating-point tensor", type(coord).__name__)
        if tuple(coord.shape[-2:]) != self.size:
            raise InputError(
                "coord", f"shape (..., {self.size[0]}, {self.size[1]})", tuple(coord.shape)
            )

    def _projected(self, s: Any) -> Any:
        """Projector coordinate along ``axis`` of the points ``s * rays`` (float64)."""
        p = s[..., None] * self.rays_proj + self.centre_proj
        z = p[..., 2]
        safe = torch.where(z > 0, z, torch.ones_like(z))
        x, y = p[..., 0] / safe, p[..., 1] / safe
        xd, yd = _distort(x, y, self.proj_k)
        fx, fy, cx, cy = self.proj_fc
        return fx * xd + cx if self.axis == 0 else fy * yd + cy

    def _plane_parameter(self, coord: Any) -> tuple[Any, Any]:
        """Ray parameter on the pinhole plane of ``coord`` (closed form) and its validity."""
        a = self.rays.expand(coord.shape + (3,))
        normal_proj = torch.zeros(coord.shape + (3,), dtype=coord.dtype, device=coord.device)
        normal_proj[..., self.axis] = 1.0
        normal_proj[..., 2] = -(coord - self.centre) / self.focal
        if self.distorted:
            # As the reference: undistort at the coordinate and the principal point's other
            # coordinate, a start from which Newton reaches the reference's root.
            with torch.no_grad():
                normal_proj[..., 2] = -self._undistorted_start(coord.detach())
        normal = normal_proj @ self.R.T
        na = (normal * a).sum(-1)
        no = normal @ self.t
        sine = na.abs() / normal.norm(dim=-1)
        ok = sine >= _MIN_SINE
        s = no / torch.where(ok, na, torch.ones_like(na))
        return s, ok & (s > 0)

    def _undistorted_start(self, coord: Any) -> Any:
        """Ideal normalised coordinate along ``axis`` of the distorted pixel ``coord`` on the
        principal line (Newton on OpenCV's model, as ``Intrinsics.undistort_normalized``)."""
        fx, fy, cx, cy = self.proj_fc
        xd = (coord - cx) / fx if self.axis == 0 else torch.zeros_like(coord)
        yd = (coord - cy) / fy if self.axis == 1 else torch.zeros_like(coord)
        x, y = xd.clone(), yd.clone()
        for _ in range(_NEWTON_MAX_ITER):
            with torch.enable_grad():
                lx, ly = x.requires_grad_(True), y.requires_grad_(True)
                fx_, fy_ = _distort(lx, ly, self.proj_k)
                a, b = torch.autograd.grad(fx_.sum(), (lx, ly), retain_graph=True)
                c, d = torch.autograd.grad(fy_.sum(), (lx, ly))
            rx, ry = fx_.detach() - xd, fy_.detach() - yd
            det = a * d - b * c
            det = torch.where(det.abs() > 0, det, torch.ones_like(det))
            dx, dy = (d * rx - b * ry) / det, (a * ry - c * rx) / det
            x, y = (x.detach() - dx).detach(), (y.detach() - dy).detach()
            # Converged everywhere (steps below 1e-15 normalised, ~1e-12 px): the remaining
            # iterations would not move it (a NaN step keeps iterating, as before).
            if float(torch.maximum(dx.abs().max(), dy.abs().max())) < _START_TOL:
                break
        return x if self.axis == 0 else y

    def _newton(self, coord: Any, s: Any, ok: Any) -> tuple[Any, Any]:
        """Refine ``s`` (no graph) until the projected coordinate matches ``coord``."""
        s = torch.where(ok, s, torch.ones_like(s))
        active = ok.clone()
        for _ in range(_NEWTON_MAX_ITER):
            if not bool(active.any()):
                break
            g, dg = self._value_and_slope(s)
            f = g - coord
            good = dg.abs() > 0
            step = f / torch.where(good, dg, torch.ones_like(dg))
            new = s - step
            diverged = active & (~torch.isfinite(new) | (new <= 0) | ~good)
            converged = f.abs() < _NEWTON_TOL_PX
            s = torch.where(active & ~diverged & ~converged, new, s)
            ok = ok & ~diverged
            active = active & ~diverged & ~converged
        return s, ok & ~active

    def _value_and_slope(self, s: Any) -> tuple[Any, Any]:
        """``g(s)`` and ``g'(s)`` per pixel (pixels are independent: grad of the sum)."""
        with torch.enable_grad():
            leaf = s.detach().requires_grad_(True)
            g = self._projected(leaf)
            (dg,) = torch.autograd.grad(g.sum(), leaf)
        return g.detach(), dg.detach()

    def parameter(self, coord: Any) -> tuple[Any, Any]:
        """Ray parameter ``s`` (metres along the unit camera ray) and validity, float64."""
        s, ok = self._plane_parameter(coord)
        if self.distorted:
            with torch.no_grad():
                s_star, ok = self._newton(coord.detach(), s.detach(), ok & torch.isfinite(coord))
            g, dg = self._value_and_slope(s_star)
            dg = torch.where(ok, dg, torch.ones_like(dg))
            s = s_star + (coord - g) / dg
        s_safe = torch.where(ok, s, torch.ones_like(s))
        point = s_safe[..., None] * self.rays
        z_proj = point @ self.R[:, 2] - self.t @ self.R[:, 2]
        ok = ok & (point[..., 2] > 0) & (z_proj > 0)
        return s_safe, ok

    def forward(self, coord: Any) -> Any:
        """``(..., H, W, 3)`` points (m, camera frame) of ``coord`` ``(..., H, W)`` (px)."""
        self._check(coord)
        dtype = coord.dtype
        c64 = coord.to(torch.float64)
        finite = torch.isfinite(c64)
        c64 = torch.where(finite, c64, torch.full_like(c64, self.centre))
        s, ok = self.parameter(c64)
        points = s[..., None] * self.rays
        points = torch.where(
            (ok & finite)[..., None], points, torch.full_like(points, float("nan"))
        )
        return points.to(dtype)

    def depth(self, coord: Any) -> Any:
        """``(..., H, W)`` camera-frame depth ``z`` (m) of ``coord`` (px); NaN where invalid."""
        return self.forward(coord)[..., 2]
