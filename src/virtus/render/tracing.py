"""One ray-tracing pass per pose: camera rays -> surface -> projector coordinates and weights.

For every camera pixel this records, per supersample, the projector coordinates
``(u_p, v_p)`` of the surface point and the radiance that a full-on (white) projector sends
back to the camera through that sample. Light transport is linear in the pattern, so every
frame of a sequence is synthesised from this one pass (:mod:`virtus.render.synthesis`).

Model
-----
* Camera rays come from ``rig.camera.intrinsics.unproject`` (any principal point, lens
  distortion) at ``spp = s * s`` stratified positions per pixel: an s x s grid at offsets
  ``(i + 0.5) / s - 0.5`` px, whose centroid is the pixel centre (2 x 2: +-0.25 px).
* Surface points go to the projector frame through ``rig.cam2proj`` and to projector pixels
  through ``rig.projector.intrinsics.project`` (its principal point and distortion).
* The projector is a point source at its optical centre whose irradiance on its virtual
  image plane z = 1 is uniform over the projector pixels (so each pixel emits the same
  power; this is also Mitsuba's ``projector`` emitter): radiant intensity
  ``I = pi / cos^3(theta_p)`` for a white pixel, theta_p the angle to the projector axis.
  Lens distortion's change of pixel solid angle is neglected.
* Radiance toward the camera: ``L = f(wi, wo) cos(theta_o) I / d^2`` with the hit's Mitsuba
  BSDF ``f`` (``bsdf.eval`` includes the cosine), ``d`` the distance to the projector centre,
  zero where a shadow ray to the projector centre is blocked or the point falls outside the
  projector image. A Lambertian surface of albedo rho facing the projector at 1 m on its
  axis therefore has ``L = rho``.
* Ambient light: ``L_amb = scene.ambient * rho_d`` with ``rho_d`` Mitsuba's diffuse
  reflectance of the hit (no occlusion).
* Ground truth uses one extra ray through each pixel centre.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from virtus.checks import positive_int
from virtus.devices import Rig
from virtus.errors import InputError
from virtus.groundtruth import GroundTruth
from virtus.optics import Intrinsics
from virtus.render.backend import mitsuba
from virtus.render.mitsuba_scene import check_in_front, scene_dict
from virtus.scene import Scene
from virtus.transforms import Pose

#: Rays traced per Mitsuba call: bounds memory (~100 B per ray inside Dr.Jit).
_RAYS_PER_CHUNK = 1 << 23


@dataclass(frozen=True, eq=False)
class Trace:
    """Result of one tracing pass.

    Attributes
    ----------
    height, width : camera image size in pixels.
    projector_width, projector_height : projector image size in pixels.
    spp : supersamples per pixel.
    weight : (P, spp) float32, P = H * W pixels in row-major order: radiance each sample
        adds to its pixel under a white projector, already divided by ``spp``; 0 where the
        sample is unlit (no hit, shadowed, outside the projector image).
    u_p, v_p : (P, spp) float32 projector pixel coordinates of each sample's surface point;
        0 where ``weight`` is 0.
    ambient : (P,) float32 ambient radiance of each pixel (mean over its samples).
    gt : ground truth through the pixel centres.
    variant : the Mitsuba variant that traced it.
    """

    height: int
    width: int
    spp: int
    projector_width: int
    projector_height: int
    weight: np.ndarray
    u_p: np.ndarray
    v_p: np.ndarray
    ambient: np.ndarray
    gt: GroundTruth
    variant: str

    @functools.cached_property
    def direct(self) -> np.ndarray:
        """(P,) float32 radiance from a full-on projector, without ambient light."""
        # A matrix-vector product: numpy's sum over a short last axis is several times slower.
        return self.weight @ np.ones(self.spp, dtype=np.float32)

    @property
    def white(self) -> np.ndarray:
        """(H, W) float32 radiance under a full-on projector, ambient included."""
        return (self.direct + self.ambient).reshape(self.height, self.width)


def sample_offsets(spp: int) -> np.ndarray:
    """(spp, 2) float64 stratified sub-pixel offsets ``(du, dv)`` whose centroid is 0.

    ``spp`` must be a perfect square s * s: an s x s grid at ``(i + 0.5) / s - 0.5`` px.
    """
    spp = positive_int("spp", spp)
    side = math.isqrt(spp)
    if side * side != spp:
        raise InputError("spp", "a perfect square (1, 4, 9, 16, ...)", spp)
    grid = (np.arange(side) + 0.5) / side - 0.5
    dv, du = np.meshgrid(grid, grid, indexing="ij")
    return np.stack([du.ravel(), dv.ravel()], axis=1)


@functools.lru_cache(maxsize=2)
def _camera_rays(intrinsics: Intrinsics, spp: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit ray directions in the camera frame, cached (datasets render many poses with one
    camera): centre rays (P, 3) float64, and supersample rays (3, P * spp) float32 (rows x,
    y, z; pixel-major order)."""
    grid = intrinsics.pixel_grid().reshape(-1, 2)
    centre = intrinsics.unproject(grid)
    pixels = (grid[:, None, :] + sample_offsets(spp)[None, :, :]).reshape(-1, 2)
    samples = np.ascontiguousarray(intrinsics.unproject(pixels).T, dtype=np.float32)
    for array in (centre, samples):
        array.setflags(write=False)
    return centre, samples


def _inside(u: np.ndarray, v: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N,) bool: projector coordinates inside the projector image (NaN -> False)."""
    with np.errstate(invalid="ignore"):
        return (
            (u >= -0.5) & (u < intrinsics.width - 0.5) & (v >= -0.5) & (v < intrinsics.height - 0.5)
        )


class _Tracer:
    """Dr.Jit side of one pass: Mitsuba scene, camera and projector poses in its world."""

    def __init__(self, mi, dr, mscene, cam2world: Pose, proj2world: Pose) -> None:  # noqa: ANN001
        self.mi, self.dr, self.mscene = mi, dr, mscene
        self.cam2world = mi.Transform4f(cam2world.matrix.tolist())
        self.world2proj = mi.Transform4f(proj2world.inverse().matrix.tolist())
        self.world2cam_R = cam2world.R.T  # noqa: N815
        self.projector = mi.Point3f(*(float(x) for x in proj2world.t))

    def _rays(self, directions: np.ndarray):  # noqa: ANN202
        mi = self.mi
        d = mi.Vector3f(directions[0], directions[1], directions[2])
        ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), d)
        return self.cam2world @ ray

    def centre(self, directions: np.ndarray, cam2proj: Pose) -> dict[str, np.ndarray]:
        """Pixel-centre rays (3, N) float64, camera frame -> ground truth per ray: point
        (camera frame, float64, NaN where missed), normal toward the camera, hit, shadow,
        and the point's normalised projector coordinates ``(x/z, y/z)`` (float64, NaN where
        missed or behind the projector).

        Points are ``t * d`` in float64 with Mitsuba's (float32) distance ``t``."""
        mi, dr = self.mi, self.dr
        si = self.mscene.ray_intersect(self._rays(directions.astype(np.float32)))
        hit = si.is_valid()
        occluded = self.mscene.ray_test(si.spawn_ray_to(self.projector), hit)
        d = [mi.Float64(directions[i]) for i in range(3)]
        t = dr.select(hit, mi.Float64(si.t), dr.nan)
        point = [t * d[i] for i in range(3)]
        # Shading normal, world -> camera frame, turned toward the camera (two-sided).
        n = si.sh_frame.n
        R = self.world2cam_R  # noqa: N806
        normal = [float(R[i, 0]) * n.x + float(R[i, 1]) * n.y + float(R[i, 2]) * n.z
                  for i in range(3)]  # fmt: skip
        facing = normal[0] * d[0] + normal[1] * d[1] + normal[2] * d[2] > 0
        normal = [dr.select(hit, dr.select(facing, -c, c), dr.nan) for c in normal]
        Rp, tp = cam2proj.R, cam2proj.t  # noqa: N806
        x = [float(Rp[i, 0]) * point[0] + float(Rp[i, 1]) * point[1]
             + float(Rp[i, 2]) * point[2] + float(tp[i]) for i in range(3)]  # fmt: skip
        # A true division: dr.rcp may be an approximation on GPUs (rcp.approx.f64).
        in_front = x[2] > 0
        xn = dr.select(in_front, x[0] / x[2], dr.nan)
        yn = dr.select(in_front, x[1] / x[2], dr.nan)
        out = {
            "px": point[0], "py": point[1], "pz": point[2],
            "nx": normal[0], "ny": normal[1], "nz": normal[2],
            "xn": xn, "yn": yn,
            "hit": hit, "occluded": occluded & hit,
        }  # fmt: skip
        dr.eval(*out.values())
        return {key: value.numpy() for key, value in out.items()}

    def samples(
        self, directions: np.ndarray, projector: Intrinsics, spp: int, ambient: float
    ) -> dict[str, np.ndarray]:
        """Supersample rays (3, N) float32 -> per sample: white-projector radiance divided by
        ``spp`` (0 where unlit), projector coordinates (0 where unlit) and, with ambient
        light, the diffuse reflectance.

        Without projector distortion everything is computed here; with distortion the
        normalised coordinates ``(x/z, y/z)`` are returned (keys ``xn``, ``yn``) for the
        projector model to distort in numpy.
        """
        mi, dr = self.mi, self.dr
        ray = self._rays(directions)
        si = self.mscene.ray_intersect(ray)
        hit = si.is_valid()
        occluded = self.mscene.ray_test(si.spawn_ray_to(self.projector), hit)
        p_proj = self.world2proj @ si.p
        z = p_proj.z
        lit = hit & ~occluded & (z > 0)
        to_projector = dr.normalize(self.projector - si.p)
        bsdf = si.bsdf(ray)
        f_cos = bsdf.eval(mi.BSDFContext(), si, si.to_local(to_projector), lit)[0]
        # pi f cos(theta_o) / (d^2 cos^3(theta_p)) = pi f cos(theta_o) |X_p| / z_p^3
        radiance = dr.pi / spp * f_cos * dr.norm(p_proj) / (z * z * z)
        inv_z = dr.select(lit, dr.rcp(z), 0.0)
        xn, yn = p_proj.x * inv_z, p_proj.y * inv_z
        out = {}
        if projector.has_distortion:
            out.update(xn=xn, yn=yn, radiance=dr.select(lit, radiance, 0.0))
        else:
            u = float(projector.fx) * xn + float(projector.cx)
            v = float(projector.fy) * yn + float(projector.cy)
            lit &= (u >= -0.5) & (u < projector.width - 0.5)
            lit &= (v >= -0.5) & (v < projector.height - 0.5)
            out.update(
                weight=dr.select(lit, radiance, 0.0),
                u_p=dr.select(lit, u, 0.0),
                v_p=dr.select(lit, v, 0.0),
            )
        if ambient > 0:
            out["rho_d"] = dr.select(hit, bsdf.eval_diffuse_reflectance(si, hit)[0], 0.0)
        dr.eval(*out.values())
        return {key: value.numpy() for key, value in out.items()}


def trace(
    rig: Rig,
    scene: Scene,
    *,
    spp: int = 4,
    cam2world: Pose | None = None,
    variant: str | None = None,
) -> Trace:
    """Trace one pose of ``rig`` in ``scene`` (see the module docstring for the model).

    Parameters
    ----------
    rig : camera, projector and ``proj2cam``.
    scene : the scene; its world frame is the camera frame unless ``cam2world`` is given.
    spp : supersamples per pixel, a perfect square (default 4 = 2 x 2).
    cam2world : pose of the camera in the scene's world frame (default: identity).
    variant : Mitsuba variant (default: automatic, see :mod:`virtus.render.backend`).
    """
    if not isinstance(rig, Rig):
        raise InputError("rig", "a virtus.devices.Rig", type(rig).__name__)
    if not isinstance(scene, Scene):
        raise InputError("scene", "a virtus.scene.Scene", type(scene).__name__)
    cam2world = Pose.identity() if cam2world is None else cam2world
    offsets = sample_offsets(spp)
    spp = len(offsets)
    check_in_front(scene, cam2world.inverse())

    mi, dr, variant_name = mitsuba(variant)
    mscene = mi.load_dict(scene_dict(mi, dr, scene))

    camera = rig.camera.intrinsics
    projector = rig.projector.intrinsics
    height, width = camera.height, camera.width
    n_pixels = height * width
    centre_dirs, sample_dirs = _camera_rays(camera, spp)
    tracer = _Tracer(mi, dr, mscene, cam2world, cam2world @ rig.proj2cam)

    # ---- ground truth through the pixel centres (float64 directions) ----
    centre_t = np.ascontiguousarray(centre_dirs.T)
    parts = [
        tracer.centre(centre_t[:, i : i + _RAYS_PER_CHUNK], rig.cam2proj)
        for i in range(0, n_pixels, _RAYS_PER_CHUNK)
    ]
    c = {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}
    hit = c["hit"]
    points = np.stack([c["px"], c["py"], c["pz"]], axis=1)
    normals = np.stack([c["nx"], c["ny"], c["nz"]], axis=1).astype(np.float64)
    xy = np.stack([c["xn"], c["yn"]], axis=1)
    if projector.has_distortion:
        finite = np.isfinite(xy[:, 0])
        xy[finite] = projector.distort_normalized(xy[finite])
    # The projector model (as Intrinsics.project), on the points' normalised coordinates.
    proj_uv = np.stack(
        [projector.fx * xy[:, 0] + projector.cx, projector.fy * xy[:, 1] + projector.cy], axis=1
    )
    outside = hit & ~_inside(proj_uv[:, 0], proj_uv[:, 1], projector)
    gt = GroundTruth(
        depth=points[:, 2].reshape(height, width),
        points=points.reshape(height, width, 3),
        normals=normals.reshape(height, width, 3),
        proj_uv=proj_uv.reshape(height, width, 2),
        mask_hit=hit.reshape(height, width),
        mask_shadow=c["occluded"].reshape(height, width),
        mask_outside=outside.reshape(height, width),
    )

    # ---- supersamples: projector coordinates and white-projector radiance ----
    n_rays = n_pixels * spp
    step = max(spp, _RAYS_PER_CHUNK // spp * spp)
    parts = [
        tracer.samples(sample_dirs[:, i : i + step], projector, spp, scene.ambient)
        for i in range(0, n_rays, step)
    ]
    s = {
        key: np.concatenate([part[key] for part in parts]) if len(parts) > 1 else parts[0][key]
        for key in parts[0]
    }
    if projector.has_distortion:
        xy = projector.distort_normalized(np.stack([s["xn"], s["yn"]], axis=1))
        u_p = (projector.fx * xy[:, 0] + projector.cx).astype(np.float32)
        v_p = (projector.fy * xy[:, 1] + projector.cy).astype(np.float32)
        lit = (s["radiance"] > 0) & _inside(u_p, v_p, projector)
        weight = np.where(lit, s["radiance"], np.float32(0.0))
        u_p = np.where(lit, u_p, np.float32(0.0))
        v_p = np.where(lit, v_p, np.float32(0.0))
    else:
        weight, u_p, v_p = s["weight"], s["u_p"], s["v_p"]
    if "rho_d" in s:
        ambient = np.float32(scene.ambient) * s["rho_d"].reshape(n_pixels, spp).mean(axis=1)
    else:
        ambient = np.zeros(n_pixels, dtype=np.float32)
    return Trace(
        height=height,
        width=width,
        spp=spp,
        projector_width=projector.width,
        projector_height=projector.height,
        weight=weight.reshape(n_pixels, spp),
        u_p=u_p.reshape(n_pixels, spp),
        v_p=v_p.reshape(n_pixels, spp),
        ambient=ambient.astype(np.float32),
        gt=gt,
        variant=variant_name,
    )
